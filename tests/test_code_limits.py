"""Size limits of the code: no function or method in lburst/ is longer than 100 lines
(decorators and docstring included), argument tables too (they are built from tables of rows)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "lburst"
MAX_FUNCTION_LINES = 100


def long_functions(root: Path, limit: int) -> list[str]:
    """``path:line name (N lines)`` of every function under ``root`` longer than ``limit`` lines."""
    found = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                lines = node.end_lineno - first + 1
                if lines > limit:
                    found.append(f"{path.relative_to(root).as_posix()}:{node.lineno} {node.name} ({lines} lines)")
    return found


def test_no_function_in_lburst_is_over_100_lines():
    too_long = long_functions(ROOT, MAX_FUNCTION_LINES)
    assert not too_long, "functions over 100 lines:\n" + "\n".join(too_long)


def test_long_functions_counts_decorators_and_docstrings(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(98))
    (tmp_path / "m.py").write_text(f'@staticmethod\ndef f():\n    """doc"""\n{body}\n\n\ndef g():\n{body}\n')
    assert long_functions(tmp_path, 100) == ["m.py:2 f (101 lines)"]  # decorator, def, docstring, 98 lines
    assert long_functions(tmp_path, 101) == []  # g: 99 lines
