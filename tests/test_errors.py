"""One error family: every exception class that lburst defines derives from
:class:`lburst.LBurstError` (and keeps its built-in base, so ``except ValueError`` still
works), and lburst raises no bare built-in exception on purpose."""

from __future__ import annotations

import ast
import builtins
import importlib
import inspect
import pkgutil
from collections import Counter
from pathlib import Path

import pytest

import lburst
from lburst.errors import LBurstError, LBurstValueError
from lburst.extras import EXTRAS, MissingExtra

PACKAGE = Path(lburst.__file__).parent

# (file, built-in) raised on purpose that stay built-in: how many times, and why
ALLOWED = {
    ("__init__.py", "AttributeError"): (1, "a module's __getattr__ protocol"),
    ("sfm/__init__.py", "AttributeError"): (1, "a module's __getattr__ protocol"),
    ("extras.py", "AttributeError"): (1, "LazyModule.__getattr__ protocol"),
    ("matching.py", "NotImplementedError"): (1, "an abstract method"),
    ("methods/options.py", "TypeError"): (
        1,
        "a programming error: an options dataclass with an unsupported field type",
    ),
    ("sfm/reference.py", "TypeError"): (1, "caught at once and raised again as LBurstValueError"),
    ("sfm/reference.py", "KeyError"): (1, "caught at once and raised again as LBurstValueError"),
}


def _modules() -> list:
    """Every module of lburst, imported; one that cannot be imported fails the test, unless what
    is missing is an optional extra that is not installed (lburst.extras.EXTRAS)."""
    found = []
    for info in pkgutil.walk_packages(lburst.__path__, "lburst.", onerror=_package_failed):
        if info.name.rsplit(".", 1)[-1] == "__main__":  # runs the command on import
            continue
        try:
            found.append(importlib.import_module(info.name))
        except ImportError as exc:
            if not _missing_extra(exc):
                raise
    return found


def _missing_extra(exc: ImportError) -> bool:
    missing = exc.__cause__ if isinstance(exc, MissingExtra) else exc
    name = getattr(missing, "name", None) or ""
    return isinstance(missing, ModuleNotFoundError) and name.split(".")[0] in EXTRAS


def _package_failed(name: str) -> None:
    """``walk_packages``' ``onerror``: a package that cannot be imported raises its error again,
    unless what is missing is an optional extra."""
    try:
        importlib.import_module(name)
    except ImportError as exc:
        if not _missing_extra(exc):
            raise


def test_every_exception_class_of_lburst_derives_from_lburst_error():
    classes = {
        cls
        for module in _modules()
        for _, cls in inspect.getmembers(module, inspect.isclass)
        if issubclass(cls, BaseException) and cls.__module__.startswith("lburst")
    }
    assert len(classes) >= 8  # LBurstError, BurstError, CheckpointError, SceneError, ...
    assert not [c.__qualname__ for c in classes if not issubclass(c, LBurstError)]


@pytest.mark.parametrize(
    "name, builtin",
    [
        ("lburst.burst.io.BurstError", ValueError),
        ("lburst.model.network.CheckpointError", ValueError),
        ("lburst.sfm.scene.SceneError", ValueError),
        ("lburst.sfm.result.ReconstructionError", RuntimeError),
        ("lburst.sfm.colmap.ColmapError", RuntimeError),
        ("lburst.extras.MissingExtra", ImportError),
        ("lburst.process.FolderInUse", OSError),
    ],
)
def test_each_error_keeps_its_builtin_base(name, builtin):
    module, _, attr = name.rpartition(".")
    cls = getattr(importlib.import_module(module), attr)
    assert issubclass(cls, LBurstError) and issubclass(cls, builtin)


def test_the_base_is_public():
    assert lburst.LBurstError is LBurstError and lburst.LBurstValueError is LBurstValueError
    with pytest.raises(LBurstError):
        lburst.methods.create("no-such-method")
    with pytest.raises(ValueError):
        lburst.matching.create("mnn,nope=1")


BUILTIN_EXCEPTIONS = {
    n for n in dir(builtins) if isinstance(getattr(builtins, n), type) and issubclass(getattr(builtins, n), Exception)
}  # not KeyboardInterrupt or SystemExit


def builtin_raises(files: dict[str, Path]) -> Counter:
    """How many times each file (by its name in ``files``) raises each built-in exception:
    ``raise ValueError(...)``, ``raise ValueError`` or ``raise builtins.ValueError(...)``."""
    found: Counter = Counter()
    for where, path in files.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.Raise) or node.exc is None:
                continue
            target = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if (
                isinstance(target, ast.Attribute)
                and isinstance(target.value, ast.Name)
                and target.value.id == "builtins"
            ):
                name = target.attr
            else:
                name = target.id if isinstance(target, ast.Name) else None
            if name in BUILTIN_EXCEPTIONS:
                found[(where, name)] += 1
    return found


def test_lburst_raises_no_bare_builtin_exception():
    files = {path.relative_to(PACKAGE).as_posix(): path for path in sorted(PACKAGE.rglob("*.py"))}
    found = builtin_raises(files)
    unlisted = sorted(f"{where}: {name} x{n}" for (where, name), n in found.items() if (where, name) not in ALLOWED)
    assert not unlisted, (
        f"raise an LBurstError instead (lburst.errors), or list them in ALLOWED with a reason: {unlisted}"
    )
    counts = {key: (found.get(key, 0), count) for key, (count, _) in ALLOWED.items()}
    assert all(n == count for n, count in counts.values()), f"(found, allowed) raises per allowed file: {counts}"


def test_the_raise_check_sees_builtins_by_any_name_and_counts_them(tmp_path):
    module = tmp_path / "m.py"
    module.write_text(
        "import builtins\n"
        "def f(x):\n"
        "    if x:\n"
        "        raise builtins.ValueError('x')\n"
        "    raise KeyError\n"
        "def g():\n"
        "    raise KeyError('y')\n"
        "    raise LBurstValueError('z')\n"
    )
    assert builtin_raises({"m.py": module}) == Counter({("m.py", "KeyError"): 2, ("m.py", "ValueError"): 1})


def test_a_module_that_fails_to_import_is_not_passed_over(monkeypatch):
    """Only a missing optional extra is; a missing module of lburst's own, or any other error, is an error."""
    broken = pkgutil.ModuleInfo(None, "lburst.no_such_module_for_this_test", False)
    monkeypatch.setattr(pkgutil, "walk_packages", lambda *args, **kwargs: [broken])
    with pytest.raises(ModuleNotFoundError, match="no_such_module_for_this_test"):
        _modules()
    assert not _missing_extra(ModuleNotFoundError("no", name="numpyy"))
    assert not _missing_extra(ImportError("cannot import name 'x' from 'lburst.noise'"))
    assert _missing_extra(ModuleNotFoundError("no", name="pycolmap"))
    extra = MissingExtra("needs av: pip install 'lburst[video]'")
    extra.__cause__ = ModuleNotFoundError("no", name="av")
    assert _missing_extra(extra)
    with pytest.raises(ModuleNotFoundError, match="no_such_package_for_this_test"):
        _package_failed("lburst.no_such_package_for_this_test")
    _package_failed("lburst.sfm")  # imports: nothing to say
