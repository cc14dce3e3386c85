"""Every Python that ``requires-python`` declares can import lburst: no module, script or test
uses syntax or a standard-library name newer than the lowest one (``enum.StrEnum`` is 3.11+).

A cheap guard, run on any Python; ``make test-pythons`` runs the fast suite on each declared
Python that pyenv has."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: standard-library names by the Python that added them: (module, name); module "" for builtins,
#: name "" for a whole module
ADDED = {
    (3, 11): {
        ("enum", "StrEnum"),
        ("enum", "ReprEnum"),
        ("enum", "EnumCheck"),
        ("enum", "FlagBoundary"),
        ("enum", "verify"),
        ("enum", "member"),
        ("enum", "nonmember"),
        ("enum", "global_enum"),
        ("typing", "Self"),
        ("typing", "LiteralString"),
        ("typing", "Never"),
        ("typing", "assert_never"),
        ("typing", "assert_type"),
        ("typing", "reveal_type"),
        ("typing", "Required"),
        ("typing", "NotRequired"),
        ("typing", "TypeVarTuple"),
        ("typing", "Unpack"),
        ("typing", "dataclass_transform"),
        ("tomllib", ""),
        ("wsgiref.types", ""),
        ("datetime", "UTC"),
        ("hashlib", "file_digest"),
        ("contextlib", "chdir"),
        ("operator", "call"),
        ("math", "cbrt"),
        ("math", "exp2"),
        ("asyncio", "TaskGroup"),
        ("asyncio", "timeout"),
        ("asyncio", "Runner"),
        ("logging", "getLevelNamesMapping"),
        ("sys", "exception"),
        ("", "ExceptionGroup"),
        ("", "BaseExceptionGroup"),
    },
    (3, 12): {
        ("typing", "override"),
        ("typing", "TypeAliasType"),
        ("itertools", "batched"),
        ("math", "sumprod"),
        ("sys", "monitoring"),
    },
    (3, 13): {
        ("warnings", "deprecated"),
        ("copy", "replace"),
        ("os", "process_cpu_count"),
        ("typing", "ReadOnly"),
        ("typing", "TypeIs"),
        ("math", "fma"),
        ("re", "PatternError"),
    },
}


def lowest_python() -> tuple[int, int]:
    """The lowest Python of ``requires-python`` in pyproject.toml (read without tomllib, 3.11+)."""
    text = (REPO / "pyproject.toml").read_text(encoding="utf-8")
    found = re.search(r'^requires-python\s*=\s*">=\s*(\d+)\.(\d+)', text, re.MULTILINE)
    assert found, "pyproject.toml declares no requires-python >= X.Y"
    return int(found.group(1)), int(found.group(2))


def newer_names(tree: ast.AST, lowest: tuple[int, int]) -> list[str]:
    """``module.name (3.X+)`` of every use in ``tree`` of a standard-library name that ``lowest`` lacks:
    ``from M import N``, ``import M``, ``M.N`` (``M`` imported under any alias) and builtins."""
    newer = {pair: version for version, pairs in ADDED.items() if version > lowest for pair in pairs}
    aliases: dict[str, str] = {}  # local name -> module
    found = []

    def refuse(module: str, name: str) -> None:
        version = newer.get((module, name))
        if version is not None:
            found.append(f"{'.'.join(p for p in (module, name) if p)} (Python {version[0]}.{version[1]}+)")

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                refuse(alias.name, "")
                aliases[alias.asname or alias.name.split(".")[0]] = (
                    alias.name if alias.asname else alias.name.split(".")[0]
                )
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            refuse(node.module, "")
            for alias in node.names:
                refuse(node.module, alias.name)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            refuse(aliases[node.value.id], node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
            refuse("", node.id)
    return found


def python_files() -> list[Path]:
    return sorted(p for folder in ("lburst", "scripts", "tests") for p in (REPO / folder).rglob("*.py"))


def test_every_file_parses_and_uses_only_names_of_the_lowest_declared_python():
    lowest = lowest_python()
    bad = []
    for path in python_files():
        source = path.read_text(encoding="utf-8")
        try:  # the grammar of the lowest Python: except*, a[*b], ...
            tree = ast.parse(source, str(path), feature_version=lowest)
        except SyntaxError as exc:
            bad.append(f"{path.relative_to(REPO)}:{exc.lineno}: {exc.msg}")
            continue
        bad += [f"{path.relative_to(REPO)}: {name}" for name in newer_names(tree, lowest)]
    assert not bad, f"not on Python {lowest[0]}.{lowest[1]}, which pyproject.toml declares: " + "; ".join(bad)


@pytest.mark.parametrize(
    "source",
    [
        "from enum import StrEnum",
        "import enum\nclass S(enum.StrEnum): pass",
        "import typing as t\nx: t.Self",
        "import tomllib",
        "raise ExceptionGroup('x', [])",
        "from itertools import batched",
    ],
)
def test_the_guard_sees_a_name_of_a_newer_python(source):
    assert newer_names(ast.parse(source), (3, 10))


def test_the_guard_sees_the_syntax_of_a_newer_python():
    with pytest.raises(SyntaxError):
        ast.parse("try:\n    pass\nexcept* ValueError:\n    pass\n", feature_version=(3, 10))


def test_lburst_str_enums_read_as_their_values():
    from lburst.sfm.result import Status

    assert str(Status.COMPLETE) == f"{Status.COMPLETE}" == "complete" == Status.COMPLETE
    assert Status("partial") is Status.PARTIAL and f"{Status.NO_MODEL:>9}" == " no_model"
