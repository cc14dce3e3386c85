"""lburst.model is the network and what runs it: it imports no simulation code (int8 calibration
data comes from the caller), and LBurst composes a runtime backend and the detector."""

from __future__ import annotations

import ast
from pathlib import Path

import lburst.model

MODEL = Path(lburst.model.__file__).parent
SIMULATION = ("lburst.scenes", "lburst.simulate", "lburst.noise")


def imported_modules(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return found


def test_no_model_module_imports_the_simulator():
    found = {
        f"{path.name}: {name}"
        for path in sorted(MODEL.glob("*.py"))
        for name in imported_modules(path)
        if any(name == s or name.startswith(s + ".") for s in SIMULATION)
    }
    assert not found, f"lburst/model imports simulation code: {sorted(found)}"


def test_lburst_is_a_backend_under_a_detector_in_at_most_250_lines():
    tree = ast.parse((MODEL / "extractor.py").read_text(encoding="utf-8"))
    (cls,) = [node for node in tree.body if isinstance(node, ast.ClassDef) and node.name == "LBurst"]
    assert cls.end_lineno - cls.lineno + 1 <= 250
    longest = max(
        (node.end_lineno - node.lineno + 1, f"{path.name}:{node.name}")
        for path in MODEL.glob("*.py")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.FunctionDef)
    )
    assert longest[0] <= 100, longest
