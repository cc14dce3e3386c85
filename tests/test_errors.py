"""One error family: every exception class that lburst defines derives from
:class:`lburst.LBurstError` (and keeps its built-in base, so ``except ValueError`` still
works), and lburst raises no bare built-in exception on purpose."""

from __future__ import annotations

import ast
import builtins
import importlib
import inspect
import pkgutil
from pathlib import Path

import pytest

import lburst
from lburst.errors import LBurstError, LBurstValueError

PACKAGE = Path(lburst.__file__).parent

# (file, built-in) raised on purpose that stay built-in, and why
ALLOWED = {
    ("__init__.py", "AttributeError"): "a module's __getattr__ protocol",
    ("sfm/__init__.py", "AttributeError"): "a module's __getattr__ protocol",
    ("extras.py", "AttributeError"): "LazyModule.__getattr__ protocol",
    ("matching.py", "NotImplementedError"): "an abstract method",
    ("methods/options.py", "TypeError"): "a programming error: an options dataclass with an unsupported field type",
    ("sfm/reference.py", "TypeError"): "caught at once and raised again as LBurstValueError",
    ("sfm/reference.py", "KeyError"): "caught at once and raised again as LBurstValueError",
    # the module is being split (issue 28, item 4); its two checks become LBurstValueError there
}


def _modules() -> list:
    found = []
    for info in pkgutil.walk_packages(lburst.__path__, "lburst."):
        if info.name.rsplit(".", 1)[-1] == "__main__":  # runs the command on import
            continue
        try:
            found.append(importlib.import_module(info.name))
        except ImportError as exc:  # an optional extra that is not installed
            if not isinstance(exc, ModuleNotFoundError):
                raise
    return found


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


def test_lburst_raises_no_bare_builtin_exception():
    names = {n for n in dir(builtins) if isinstance(getattr(builtins, n), type)}
    names = {n for n in names if issubclass(getattr(builtins, n), Exception)}  # not KeyboardInterrupt, SystemExit
    bare = []
    for path in sorted(PACKAGE.rglob("*.py")):
        where = path.relative_to(PACKAGE).as_posix()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Raise) and node.exc is not None:
                call = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                if isinstance(call, ast.Name) and call.id in names and (where, call.id) not in ALLOWED:
                    bare.append(f"{where}:{node.lineno}: {call.id}")
    assert not bare, bare
