# Two commands for a fresh machine (see README): `make demo` and `make test`.
# Each first installs lburst and what it needs into a local virtual environment.
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
PYTHON3 ?= python3

.PHONY: demo test test-slow test-pythons install lint

$(STAMP): pyproject.toml
	$(PYTHON3) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/lburst demo --out outputs/demo

test: $(STAMP)
	$(PY) -m pytest -q $(PYTEST_ARGS)

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow
	LBURST_HYPOTHESIS_EXAMPLES=2000 $(PY) -m pytest -q tests/test_properties.py tests/cli/test_numeric_options.py

# The fast suite on each Python that requires-python (>=3.10) declares and pyenv has, each in
# its own .venv-X.Y (made on first use, as .venv); not part of `make test` or CI.
# PYTEST_ARGS picks tests, e.g. `make test-pythons PYTEST_ARGS=tests/cli`.
PYTHONS ?= 3.10 3.11 3.12 3.13
PYENV_ROOT ?= $(HOME)/.pyenv

test-pythons:
	@for v in $(PYTHONS); do \
	  py=$$(ls -d $(PYENV_ROOT)/versions/$$v.* 2>/dev/null | sort -V | tail -1)/bin/python; \
	  if [ ! -x "$$py" ]; then echo "test-pythons: Python $$v not in pyenv, skipped"; continue; fi; \
	  echo "test-pythons: Python $$v ($$py)"; \
	  $(MAKE) --no-print-directory test VENV=.venv-$$v PYTHON3=$$py || exit 1; \
	done

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
