"""The import structure: no cycles between lburst modules or packages, argument parsing only
in lburst/cli/, and the COLMAP child process (with the pose metrics) free of torch, OpenCV and tqdm."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import lburst

ROOT = Path(lburst.__file__).parent


def module_names() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _runtime_nodes(tree: ast.AST):
    """Every node except the bodies of ``if TYPE_CHECKING:`` blocks (imports that never run)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            stack.extend(node.orelse)
            continue
        stack.extend(ast.iter_child_nodes(node))


def import_call(node: ast.AST) -> str | None:
    """The module a call of ``importlib.import_module(NAME)`` (or ``import_module``, ``__import__``)
    imports: NAME where it is a string constant, ``''`` where it is computed at run time;
    ``None`` for any other node."""
    if not isinstance(node, ast.Call) or not node.args:
        return None
    func = node.func
    called = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else None
    if called not in ("import_module", "__import__"):
        return None
    first = node.args[0]
    return first.value if isinstance(first, ast.Constant) and isinstance(first.value, str) else ""


def imports_of(name: str, path: Path, modules: dict[str, Path], type_only: bool = True) -> set[str]:
    """lburst modules that ``name`` imports anywhere (module level or in functions, by an import
    statement or by ``importlib.import_module`` of a constant name), those of ``if TYPE_CHECKING:``
    blocks too unless ``type_only`` is false (only the imports that run)."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree) if type_only else _runtime_nodes(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                found.add(sub if sub in modules else base)
        elif import_call(node):
            found.add(import_call(node))
    return {m for m in found if m in modules and m != name}


def package_of(name: str) -> str:
    """``lburst.sfm.colmap`` -> ``lburst.sfm``; a top-level module is its own unit."""
    parts = name.split(".")
    if len(parts) >= 2 and (ROOT / parts[1]).is_dir():
        return ".".join(parts[:2])
    return name


def cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def import_graph(type_only: bool = True) -> dict[str, set[str]]:
    """Module -> the lburst modules it imports (``import lburst.x``, ``from lburst.x import y``,
    relative ones), at module level, in functions and, with ``type_only``, in ``if TYPE_CHECKING:``."""
    modules = module_names()
    return {name: imports_of(name, path, modules, type_only) for name, path in modules.items()}


def test_the_import_graph_is_read():
    graph = import_graph()
    assert "lburst.sfm.poses" in graph["lburst.sfm.metrics"]
    assert "lburst.features" in graph["lburst.methods.merge"]
    assert "lburst.sfm.retrieval" in graph["lburst.sfm.reconstruct"]  # imported inside a function
    assert "lburst.methods" in graph["lburst.sfm.feature_stage"]  # inside a nested function
    typed = [n for n, p in module_names().items() if "TYPE_CHECKING" in p.read_text(encoding="utf-8")]
    assert typed and all(graph[n] >= import_graph(type_only=False)[n] for n in typed)


def test_type_only_imports_are_in_the_graph(tmp_path):
    """An import under ``if TYPE_CHECKING:`` is an arrow too (``outputs`` <-> ``reconstruct`` was
    a cycle through one)."""
    module = tmp_path / "m.py"
    module.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from lburst.sfm.result import Status\n")
    modules = module_names()
    assert imports_of("lburst.m", module, modules) == {"lburst.sfm.result"}
    assert imports_of("lburst.m", module, modules, type_only=False) == set()


def test_no_two_modules_import_each_other():
    found = cycles(import_graph())
    assert not found, f"import cycles between modules: {[sorted(c) for c in found]}"


def test_no_cycle_through_the_imports_that_run():
    found = cycles(import_graph(type_only=False))
    assert not found, f"import cycles between modules: {[sorted(c) for c in found]}"


def test_the_reconstruct_pipeline_is_split_by_concept():
    """``sfm/reconstruct.py`` runs the named stages; the input and its features (``read``), pairs,
    matching, verification and mapping (``mapping``), options and result are their own modules."""
    lines = len((ROOT / "sfm" / "reconstruct.py").read_text(encoding="utf-8").splitlines())
    assert lines <= 300, f"lburst/sfm/reconstruct.py has {lines} lines"
    for module in ("options", "read", "result", "mapping", "pairs", "match"):
        assert f"lburst.sfm.{module}" in import_graph()["lburst.sfm.reconstruct"]


def imports_argparse(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "argparse" for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "argparse":
            return True
    return False


def test_only_the_command_line_parses_arguments():
    """Every parser lives in lburst/cli/; library modules take typed arguments."""
    found = sorted(
        name
        for name, path in module_names().items()
        if name != "lburst.cli" and not name.startswith("lburst.cli.") and imports_argparse(path)
    )
    assert not found, f"modules outside lburst/cli/ that import argparse: {found}"


def test_no_two_packages_import_each_other():
    packages: dict[str, set[str]] = {}
    for name, deps in import_graph().items():
        packages.setdefault(package_of(name), set()).update(
            package_of(d) for d in deps if package_of(d) != package_of(name)
        )
    found = cycles(packages)
    assert not found, f"import cycles between packages: {[sorted(c) for c in found]}"


def test_colmap_child_and_poses_import_no_torch_opencv_or_tqdm():
    code = (
        "import sys, lburst.cli.colmap_job, lburst.sfm.colmap, lburst.sfm.poses\n"
        "print(','.join(m for m in ('torch', 'cv2', 'tqdm', 'pycolmap', 'matplotlib') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"imported: {out.stdout.strip()}"


def test_import_lburst_and_its_methods_registry_is_light():
    code = (
        "import sys, lburst, lburst.methods, lburst.features, lburst.extras\n"
        "print(','.join(m for m in ('torch', 'pycolmap', 'matplotlib', 'skimage') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"imported: {out.stdout.strip()}"


#: The only imports of our own modules inside functions, each (importer, imported) with why it
#: waits for the call: every other one sits at the top of its module (issue 28).
INNER_IMPORTS = {
    ("lburst.demo", "lburst.model.extractor"): "torch, only when the demo runs",
    ("lburst.matching", "lburst.match"): "torch: the matcher registry stays light (import lburst.methods)",
    ("lburst.sfm.colmap", "lburst.burst.io"): "OpenCV: the COLMAP child imports no cv2",
}


def inner_imports() -> set[tuple[str, str]]:
    """(importer, imported) for every import of an lburst module inside a function body;
    ``lburst/__init__.py``'s public names load on first use by design, through importlib."""
    found = set()
    for name, path in module_names().items():
        for function in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(function, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in ast.walk(function):
                if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "lburst":
                    found.add((name, node.module))
                elif isinstance(node, ast.Import):
                    found |= {(name, a.name) for a in node.names if a.name.split(".")[0] == "lburst"}
                elif (import_call(node) or "").split(".")[0] == "lburst":
                    found.add((name, import_call(node)))
    return found


def test_our_own_modules_are_imported_at_the_top_unless_listed():
    found = inner_imports()
    unlisted = sorted(found - set(INNER_IMPORTS))
    assert not unlisted, f"move these imports to the top of the module, or list them with a reason: {unlisted}"
    assert set(INNER_IMPORTS) <= found, f"listed but gone (remove them): {sorted(set(INNER_IMPORTS) - found)}"


def test_the_inner_imports_test_sees_an_import_in_a_function(tmp_path, monkeypatch):
    module = tmp_path / "lburst" / "m.py"
    module.parent.mkdir()
    module.write_text("def f():\n    from lburst.noise import GaussianNoise\n    return GaussianNoise\n")
    monkeypatch.setattr(sys.modules[__name__], "module_names", lambda: {"lburst.m": module})
    assert inner_imports() == {("lburst.m", "lburst.noise")}


def test_the_import_graph_sees_importlib_imports(tmp_path, monkeypatch):
    """``importlib.import_module("lburst.x")`` is an arrow of the graph, and in a function an inner import."""
    module = tmp_path / "lburst" / "m.py"
    module.parent.mkdir()
    module.write_text(
        "import importlib\n"
        "from importlib import import_module\n"
        "RESULT = importlib.import_module('lburst.sfm.result')\n"
        "def f():\n"
        "    return import_module('lburst.noise'), __import__('lburst.tum')\n"
    )
    modules = module_names()
    assert imports_of("lburst.m", module, modules) == {"lburst.sfm.result", "lburst.noise", "lburst.tum"}
    monkeypatch.setattr(sys.modules[__name__], "module_names", lambda: {"lburst.m": module})
    assert inner_imports() == {("lburst.m", "lburst.noise"), ("lburst.m", "lburst.tum")}


#: Modules that import a module whose name they compute at run time (the graph cannot follow
#: those arrows), and why.
DYNAMIC_IMPORTS = {
    "lburst": "its public names load on first use (_EXPORTS)",
    "lburst.sfm": "its public names load on first use (_EXPORTS)",
    "lburst.methods.registry": "each method's module registers it when first asked for (_PROVIDERS)",
    "lburst.cli": "each subcommand's module (COMMANDS), imported when it runs",
    "lburst.extras": "optional dependencies, by the name a caller asks for",
}


def test_only_the_listed_modules_import_by_a_computed_name():
    found = {
        name
        for name, path in module_names().items()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if import_call(node) == ""
    }
    assert found == set(DYNAMIC_IMPORTS), (
        f"unlisted: {sorted(found - set(DYNAMIC_IMPORTS))}, gone: {sorted(set(DYNAMIC_IMPORTS) - found)}"
    )
