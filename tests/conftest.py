"""Shared test fixtures.  Data from ``../shared`` (or ``$LBURST_SHARED``) is optional:
tests that need it skip cleanly when it is absent."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

torch.set_num_threads(min(2, torch.get_num_threads()))
cv2.setNumThreads(1)  # as several test modules set it when collected: the same for one file as for the suite

try:  # a dev dependency: property tests skip without it
    from hypothesis import settings as hypothesis_settings
except ImportError:
    hypothesis_settings = None
if hypothesis_settings is not None:
    # Every run draws the same examples (a failure seen once is seen again), as many as
    # LBURST_HYPOTHESIS_EXAMPLES says where a test does not set its own count (`make test-slow`: 2000).
    hypothesis_settings.register_profile(
        "lburst",
        derandomize=True,
        max_examples=int(os.environ.get("LBURST_HYPOTHESIS_EXAMPLES", "40")),
        deadline=None,
    )
    hypothesis_settings.load_profile("lburst")

SHARED = Path(os.environ.get("LBURST_SHARED", Path(__file__).resolve().parents[1].parent / "shared"))


#: variables that pytest and libraries set for themselves (torch: on first use of its compile cache)
LIBRARY_VARIABLES = {"PYTEST_CURRENT_TEST", "TORCHINDUCTOR_CACHE_DIR"}


def _process_state() -> dict:
    return {
        "torch threads": torch.get_num_threads(),
        "OpenCV threads": cv2.getNumThreads(),
        "working directory": os.getcwd(),
        "environment": {k: v for k, v in os.environ.items() if k not in LIBRARY_VARIABLES},
    }


def _changes(before: dict, after: dict) -> list[str]:
    found = [f"{k} {before[k]} -> {after[k]}" for k in before if k != "environment" and before[k] != after[k]]
    env, now = before["environment"], after["environment"]
    return found + [
        f"${k} {env.get(k)!r} -> {now.get(k)!r}" for k in sorted(env.keys() | now.keys()) if env.get(k) != now.get(k)
    ]


def _restore(state: dict) -> None:
    torch.set_num_threads(state["torch threads"])
    cv2.setNumThreads(state["OpenCV threads"])
    os.chdir(state["working directory"])
    for key in set(os.environ) - set(state["environment"]) - LIBRARY_VARIABLES:
        del os.environ[key]
    os.environ.update(state["environment"])


def _unchanged_since(before: dict, what: str) -> None:
    leaks = _changes(before, _process_state())
    if leaks:
        _restore(before)
        pytest.fail(f"{what} changed process-wide state (restore it, e.g. with monkeypatch): {'; '.join(leaks)}")


@pytest.fixture(scope="module", autouse=True)
def module_leaves_process_state():
    """The fixtures of a test module (a cluster, a run with ``--threads 1`` that several tests
    share) leave the process as they found it once the module's tests are done."""
    before = _process_state()
    yield
    _unchanged_since(before, "a fixture of this module")


@pytest.fixture(autouse=True)
def process_state_unchanged():
    """Every test (and the function-scoped fixtures it uses) leaves the process as it found it:
    torch's and OpenCV's thread counts, the environment and the working directory; or it fails
    here naming what changed, and the state is put back for the next test.  The global random
    states of torch and NumPy are put back silently: a test may seed them for its own draws,
    never for the next test's."""
    before = _process_state()
    torch_rng, numpy_rng = torch.get_rng_state(), np.random.get_state()
    yield
    torch.set_rng_state(torch_rng)
    np.random.set_state(numpy_rng)
    _unchanged_since(before, "the test")


@pytest.fixture(scope="session")
def shared() -> Path:
    """The ``shared`` data folder; skips the test when it is not there."""
    if not (SHARED / "README.md").is_file():
        pytest.skip(f"shared data not found at {SHARED} (set LBURST_SHARED)")
    return SHARED


@pytest.fixture(scope="session")
def anchors(shared: Path) -> Path:
    path = shared / "anchors"
    if not (path / "reference_outputs.npz").is_file():
        pytest.skip(f"published checkpoints not found in {path}")
    return path


@pytest.fixture(scope="session")
def load_script():
    """A function that imports ``scripts/NAME.py`` of the repository as a module."""
    import importlib.util

    folder = Path(__file__).resolve().parents[1] / "scripts"

    def load(name: str):
        spec = importlib.util.spec_from_file_location(name, folder / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load
