"""A feature method is a value (:class:`lburst.methods.Method`): parsed once, its spec given back by
``str``, equal and hashable by its spec, picklable (it ships to cluster workers), and it gives the
store's keys and the results' names that the spec string gave before it was a value."""

from __future__ import annotations

import ast
import pickle
import re
from pathlib import Path

import numpy as np
import pytest

import lburst
from lburst import store
from lburst.bench.homography import BenchMethod, InputMode
from lburst.cli import main
from lburst.cli.extract import chosen_method
from lburst.cluster.models import WorkerExtractor, extractor_request
from lburst.demo import method_labels
from lburst.methods import Method, method_slug

#: the content of ``w.pt`` in the tests' working folder: its SHA-1 starts 39d6220e2090
WEIGHTS = b"lburst test weights\n"

#: spec, its results key (the store's ``spec``), its benchmark folder (slug), the options the store
#: keys for precision=bf16, runtime=torch and top_k=4000 (those the method has), the spec with a
#: scene's 8,000 keypoints as default, and the demo's label: each computed with the string functions
#: that came before Method (lburst.methods.learned.results_key, method_slug, store.method_key,
#: with_default, lburst.demo._label), with ``w.pt`` holding :data:`WEIGHTS`
BEFORE = [
    ("sift", "sift", "sift-e7fa92", {"precision": "bf16"}, "sift", "sift"),
    (
        "sift,root=true",
        "sift,root=true",
        "sift_root=true-eb67cb",
        {"precision": "bf16"},
        "sift,root=true",
        "sift-root=true",
    ),
    (
        "orb,max_features=2000",
        "orb,max_features=2000",
        "orb_max_features=2000-6df342",
        {"precision": "bf16"},
        "orb,max_features=2000",
        "orb-max_features=2000",
    ),
    ("merge+sift", "merge+sift", "merge+sift-25949b", {"precision": "bf16"}, "merge+sift", "merge+sift"),
    (
        "merge,reduce=median+orb",
        "merge,reduce=median+orb",
        "merge_reduce=median+orb-ceb84a",
        {"precision": "bf16"},
        "merge,reduce=median+orb",
        "merge,reduce=median+orb",
    ),
    (
        "merge,reduce=median+orb,max_features=300",
        "merge,reduce=median+orb,max_features=300",
        "merge_reduce=median+orb_max_features=300-db4501",
        {"precision": "bf16"},
        "merge,reduce=median+orb,max_features=300",
        "merge,reduce=median+orb-max_features=300",
    ),
    (
        "lburst:w.pt",
        "lburst:w.pt@39d6220e2090",
        "lburst_w.pt_39d6220e2090-35e97b",
        {"precision": "bf16", "runtime": "torch"},
        "lburst:w.pt,top_k=8000",
        "lburst-w",
    ),
    (
        "lburst-lite:w.pt,top_k=2000",
        "lburst-lite:w.pt,top_k=2000@39d6220e2090",
        "lburst-lite_w.pt_top_k=2000_39d6220e2090-423c20",
        {"precision": "bf16", "runtime": "torch", "top_k": "4000"},
        "lburst-lite:w.pt,top_k=2000",
        "lburst-lite-w-top_k=2000",
    ),
    (
        "lburst:w.pt,frame_order=published",
        "lburst:w.pt,frame_order=published@39d6220e2090",
        "_w.pt_frame_order=published_39d6220e2090-feb99d",
        {"precision": "bf16", "runtime": "torch"},
        "lburst:w.pt,frame_order=published,top_k=8000",
        "lburst-w-frame_order=published",
    ),
    (
        "merge+lburst:w.pt",
        "merge+lburst:w.pt@39d6220e2090",
        "merge+lburst_w.pt_39d6220e2090-1c3b0e",
        {"precision": "bf16", "runtime": "torch"},
        "merge+lburst:w.pt,top_k=8000",
        "merge+lburst-w",
    ),
    (
        "lburst:w.pt,rotations=2",
        "lburst:w.pt,rotations=2@39d6220e2090",
        "lburst_w.pt_rotations=2_39d6220e2090-4494ab",
        {"precision": "bf16", "runtime": "torch"},
        "lburst:w.pt,rotations=2,top_k=8000",
        "lburst-w-rotations=2",
    ),
    (
        "r2d2:w.pt",
        "r2d2:w.pt@39d6220e2090",
        "r2d2_w.pt_39d6220e2090-254865",
        {"precision": "bf16", "runtime": "torch"},
        "r2d2:w.pt,top_k=8000",
        "r2d2-w",
    ),
    (
        "lburst:path/to.pt,frame_order=published",
        "lburst:path/to.pt,frame_order=published",
        "lburst_path_to.pt_frame_order=published-7a16bc",
        {"precision": "bf16", "runtime": "torch"},
        "lburst:path/to.pt,frame_order=published,top_k=8000",
        "lburst-to-frame_order=published",
    ),
    (
        "lburst:missing.pt",
        "lburst:missing.pt",
        "lburst_missing.pt-76d690",
        {"precision": "bf16", "runtime": "torch"},
        "lburst:missing.pt,top_k=8000",
        "lburst-missing",
    ),
    ("buff", "buff", "buff-c516fa", {"precision": "bf16"}, "buff", "buff"),
    (
        "merge+r2d2:w.pt,top_k=500",
        "merge+r2d2:w.pt,top_k=500@39d6220e2090",
        "merge+r2d2_w.pt_top_k=500_39d6220e2090-824030",
        {"precision": "bf16", "runtime": "torch", "top_k": "4000"},
        "merge+r2d2:w.pt,top_k=500",
        "merge+r2d2-w-top_k=500",
    ),
]


@pytest.fixture
def weights(tmp_path, monkeypatch):
    """A working folder holding ``w.pt`` (:data:`WEIGHTS`), so that the specs name it relatively."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("LBURST_WEIGHTS", raising=False)
    (tmp_path / "w.pt").write_bytes(WEIGHTS)
    return tmp_path / "w.pt"


@pytest.mark.parametrize("spec, key, slug, options, scene_spec, label", BEFORE)
def test_keys_and_names_are_those_the_spec_string_gave(weights, spec, key, slug, options, scene_spec, label):
    method = Method.parse(spec)
    assert method.results_key() == key
    assert method.slug() == slug == method_slug(key)
    assert store.method_key(method) == {"spec": key, "options": {}, "revision": store.REVISION}
    given = (
        {"precision": "bf16", "runtime": "torch", "top_k": 4000} if method.accepts("top_k") else {"precision": "bf16"}
    )
    assert store.method_key(method, **given) == {"spec": key, "options": options, "revision": store.REVISION}
    assert store.method_key(spec, **given) == store.method_key(method, **given)  # the API takes the spec too
    assert str(method.with_default("top_k", 8000)) == scene_spec
    assert method.label() == label
    assert method_labels([method]) == {method: label}


def test_a_checkpoint_path_with_a_comma_keeps_its_key_and_is_labelled_by_its_stem(weights):
    (weights.parent / "w,1.pt").write_bytes(b"other weights\n")
    method = Method.parse("lburst:w,1.pt,top_k=7")
    assert (method.arg, method.given) == ("w,1.pt", {"top_k": "7"})
    assert method.results_key() == "lburst:w,1.pt,top_k=7@79eebf9c0f3d"  # as before
    assert method.slug() == "lburst_w_1.pt_top_k=7_79eebf9c0f3d-77531d"
    assert method.label() == "lburst-w,1-top_k=7"  # the label split the path at its comma: lburst-w-1.pt-top_k=7


SPECS = [row[0] for row in BEFORE] + [
    "lburst",
    "lburst-lite,top_k=2000",
    "lburst,rotations=2",
    "lburst:/runs/a+b/last.pt,top_k=100",
    "lburst:/runs/w,1.pt,runtime=torch",
    "merge,reduce=median+merge+sift",
    "toy,flag=yes,pair=1:-2",
    "sift,root=",
]


@pytest.mark.parametrize("spec", SPECS)
def test_a_spec_parses_into_a_method_that_gives_it_back(spec):
    method = Method.parse(spec)
    assert str(method) == spec
    assert Method.parse(str(method)) == method and Method.of(method) is method and Method.of(spec) == method
    assert repr(method) == f"Method.parse({spec!r})"
    assert pickle.loads(pickle.dumps(method)) == method


def test_the_parts_of_a_method():
    method = Method.parse("merge,reduce=median+lburst:/w/x.pt,top_k=100,frame_order=published")
    assert (method.name, method.arg, method.given) == ("merge", None, {"reduce": "median"})
    inner = method.inner
    assert (inner.name, inner.arg, inner.options) == (
        "lburst",
        "/w/x.pt",
        (("top_k", "100"), ("frame_order", "published")),
    )
    assert method.innermost is inner and inner.innermost is inner
    assert method.accepts("top_k") and not Method.parse("merge+sift").accepts("top_k")
    assert method.weights_file() == Path("/w/x.pt") and Method.parse("merge+orb").weights_file() is None
    assert Method("lburst", "/w/x.pt", {"top_k": 100}) == Method.parse("lburst:/w/x.pt,top_k=100")  # options as text


def test_methods_are_equal_and_hash_alike_by_their_spec():
    a, b = Method.parse("lburst,top_k=2000"), Method.parse("lburst,top_k=2000")
    assert a == b and hash(a) == hash(b) and len({a, b, Method("lburst", options=(("top_k", "2000"),))}) == 1
    assert Method.parse("lburst, top_k = 2000") == a  # spaces around names are not part of the method
    assert a != Method.parse("lburst,top_k=2001") and a != Method.parse("lburst-lite,top_k=2000")
    assert Method.parse("lburst,top_k=1,rotations=2") != Method.parse("lburst,rotations=2,top_k=1")  # keys differ too
    assert Method.parse("merge+sift") != Method.parse("sift") and a != "lburst,top_k=2000"
    with pytest.raises(AttributeError):
        a.name = "sift"  # frozen


def test_new_methods_from_a_method_leave_it_as_it_was():
    lburst = Method.parse("merge+lburst")
    assert str(lburst.with_option("frame_order", "published")) == "merge+lburst,frame_order=published"
    assert str(lburst.with_weights("w.pt")) == "merge+lburst:w.pt"
    assert Method.parse("lburst:x.pt").with_weights("w.pt") == Method.parse("lburst:x.pt")  # its own checkpoint wins
    # the weights go to the method's checkpoint, not after its options (the spec read 'lburst,top_k=5:w.pt')
    assert str(Method.parse("lburst,top_k=5").with_weights("w.pt")) == "lburst:w.pt,top_k=5"
    assert str(lburst.with_given("top_k", 300, "--top-k")) == "merge+lburst,top_k=300"
    assert str(lburst) == "merge+lburst"
    with pytest.raises(ValueError, match=r"^--top-k 300 and top_k=7 in method spec 'lburst,top_k=7' disagree"):
        Method.parse("lburst,top_k=7").with_given("top_k", 300, "--top-k")
    assert Method.parse("lburst,top_k=7").with_given("top_k", 7, "--top-k") == Method.parse("lburst,top_k=7")
    with pytest.raises(ValueError, match=r"^option 'frame_order' given twice in method spec 'lburst,frame_order=a,"):
        Method.parse("lburst,frame_order=a").with_option("frame_order", "published")


@pytest.mark.parametrize(
    "spec, message",
    [
        ("lburst:", "method spec 'lburst:': nothing after 'lburst:' (a checkpoint file or a shipped name)"),
        ("merge+lburst: ,top_k=5", "method spec 'lburst: ,top_k=5': nothing after 'lburst:' (a checkpoint file"),
        ("lburst,w.pt", "bad option 'w.pt' in method spec 'lburst,w.pt': expected KEY=VALUE"),
        ("sift,root=1,root=0", "option 'root' given twice in method spec 'sift,root=1,root=0'"),
        ("merge:x.pt+sift", "method 'merge' takes no argument, got 'x.pt' in 'merge:x.pt+sift'"),
        (None, "a method spec is a string such as 'lburst' or 'merge+sift', got None"),
        (["sift"], "a method spec is a string such as 'lburst' or 'merge+sift', got ['sift']"),
    ],
)
def test_a_spec_that_breaks_the_grammar_is_one_line(spec, message):
    with pytest.raises(ValueError, match="^" + re.escape(message)) as caught:
        Method.parse(spec)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize(
    "spec, message",
    [
        ("nope", "unknown method 'nope' in 'nope'; available: "),
        ("merge+nope", "unknown method 'nope' in 'nope'; available: "),  # the level that names it
        ("sift:x.pt", "method 'sift' takes no argument, got 'x.pt'"),
        ("sift,colour=red", "unknown options for method 'sift': colour; valid: "),
        ("merge+lburst,top_k=0", "method 'lburst': top_k must be an integer >= 1"),
        ("merge,reduce=median", "method 'merge' wraps another method: write merge+SPEC, e.g. merge+sift"),
    ],
)
def test_names_and_values_are_checked_without_creating_anything(spec, message):
    method = Method.parse(spec)  # the grammar holds
    with pytest.raises(ValueError, match="^" + re.escape(message)):
        method.check()


def test_a_method_ships_to_a_worker_and_creates_its_extractor_there():
    request = extractor_request(Method.parse("sift,max_features=50"))
    shipped = pickle.loads(pickle.dumps(WorkerExtractor(request)))
    assert shipped.request.method == Method.parse("sift,max_features=50") and shipped.request.key == request.key
    burst = np.random.default_rng(0).integers(0, 255, (3, 96, 128, 3), dtype=np.uint8)
    features = shipped(burst)
    assert 0 < len(features["keypoints"]) <= 50
    assert Method.parse("merge,reduce=median+sift").create().inner.name == "sift"  # each level named by its spec


@pytest.mark.parametrize(
    "method, weights, frame_order, spec",
    [  # lburst extract's --method, --weights and --frame-order, as they made the spec before
        (None, None, None, "lburst"),
        (None, "w.pt", None, "lburst:w.pt"),
        ("lburst", "w.pt", "published", "lburst:w.pt,frame_order=published"),
        ("merge+lburst", "w.pt", None, "merge+lburst:w.pt"),
        ("lburst:x.pt", "w.pt", None, "lburst:x.pt"),
        ("sift", None, None, "sift"),
        ("lburst-lite,top_k=5", None, "temporal", "lburst-lite,top_k=5,frame_order=temporal"),
        ("merge+lburst", None, "published", "merge+lburst,frame_order=published"),
    ],
)
def test_extract_makes_the_method_it_made_as_a_spec(monkeypatch, method, weights, frame_order, spec):
    monkeypatch.delenv("LBURST_WEIGHTS", raising=False)
    given = None if method is None else Method.parse(method)
    assert str(chosen_method(given, weights, frame_order)) == spec


def test_extract_refuses_a_spec_that_breaks_the_grammar_in_one_line(tmp_path, capsys):
    assert main(["extract", str(tmp_path), "--out", str(tmp_path / "out"), "--method", "lburst,w.pt"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "lburst extract: error: argument --method: bad option 'w.pt' in method spec 'lburst,w.pt': expected KEY=VALUE\n"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "text, spec, mode, name, prefix",
    [  # the homography benchmark's methods, as the string functions read them before
        ("sift", "sift", InputMode.BURST, "sift", ""),
        ("gold+sift", "sift", InputMode.GOLD, "gold+sift", "gold+"),
        ("gold:w.pt", "r2d2:w.pt", InputMode.GOLD, "gold:w.pt", "gold:"),
        ("oracle-merge+merge+sift", "merge+sift", InputMode.ORACLE_MERGE, "oracle-merge+merge+sift", "oracle-merge+"),
        ("gold+r2d2:w.pt", "r2d2:w.pt", InputMode.GOLD, "gold:w.pt", "gold:"),
        ("oracle-merge+lburst:w.pt,top_k=9", "lburst:w.pt,top_k=9", InputMode.ORACLE_MERGE, None, "oracle-merge+"),
    ],
)
def test_the_homography_benchmark_reads_its_methods_as_before(text, spec, mode, name, prefix):
    method = BenchMethod.parse(text)
    assert (method.method, method.mode, method.name, method.key_prefix) == (
        Method.parse(spec),
        mode,
        name or text,
        prefix,
    )


def test_the_homography_benchmark_takes_a_method_or_its_text():
    method = Method.parse("merge+sift")
    assert BenchMethod.of(method) == BenchMethod.of("merge+sift") == BenchMethod(method, InputMode.BURST)
    assert BenchMethod.of("gold+sift") == BenchMethod(Method("sift"), InputMode.GOLD)


# --- the grammar is read only in lburst/methods/ ----------------------------------------------

ROOT = Path(lburst.__file__).parent

#: modules outside lburst/methods/ that split a spec of another grammar, with what it is
OTHER_GRAMMARS = {
    "matching.py": "a matcher spec, NAME[,KEY=VALUE...] (its options read by lburst.methods.options.parse_pairs)",
    "noise.py": "a noise spec (lburst.noise), e.g. sensor:imx686@6400,photons=20",
    "cluster/session.py": "a scheduler address of a cluster spec, tcp://HOST:PORT",
}

_NAMES = re.compile(r"method|spec|weights", re.IGNORECASE)
_GRAMMAR = (",", ":", "+")


def _mentions(node: ast.AST) -> bool:
    return bool(_NAMES.search(ast.unparse(node)))


def spec_handling(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, code) of what reads or writes a method spec by hand: ``split``/``partition`` (and their
    right-hand forms) at ``,``, ``:`` or ``+`` of something named method, spec or weights; an f-string
    that joins such a value to ``,``, ``:`` or ``+`` (``f"{method}:{weights}"``, ``f"lburst:{weights}"``);
    and ``spec += ",KEY=VALUE"``."""
    found = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr in ("split", "rsplit", "partition", "rpartition")
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and node.args[0].value in _GRAMMAR
            and _mentions(node.func.value)
        ):
            found.append((node.lineno, ast.unparse(node)))
        elif isinstance(node, ast.JoinedStr):
            parts = node.values
            for a, b in zip(parts, parts[1:]):
                value, text = (a, b) if isinstance(a, ast.FormattedValue) else (b, a)
                if not (isinstance(value, ast.FormattedValue) and isinstance(text, ast.Constant)):
                    continue
                glued = re.match(r"[,:+](?!\s)", text.value) if value is a else re.search(r"[,:+]$", text.value)
                if glued and _mentions(value.value):
                    found.append((node.lineno, ast.unparse(node)))
        elif isinstance(node, ast.AugAssign) and isinstance(node.op, ast.Add) and _mentions(node.target):
            added = node.value.values[0] if isinstance(node.value, ast.JoinedStr) and node.value.values else node.value
            if isinstance(added, ast.Constant) and isinstance(added.value, str) and added.value[:1] in _GRAMMAR:
                found.append((node.lineno, ast.unparse(node)))
    return found


def spec_handling_outside_methods(root: Path) -> dict[str, list[tuple[int, str]]]:
    """:func:`spec_handling` of every module under ``root`` but ``methods/``, by path under ``root``."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        name = path.relative_to(root).as_posix()
        if not name.startswith("methods/"):
            hits = spec_handling(ast.parse(path.read_text(encoding="utf-8")))
            if hits:
                found[name] = hits
    return found


def test_no_module_outside_methods_reads_or_writes_a_method_spec():
    found = spec_handling_outside_methods(ROOT)
    by_hand = {name: hits for name, hits in found.items() if name not in OTHER_GRAMMARS}
    assert not by_hand, f"a method spec read or written by hand (ask lburst.methods.Method instead): {by_hand}"
    assert set(OTHER_GRAMMARS) <= set(found), f"listed but gone: {sorted(set(OTHER_GRAMMARS) - set(found))}"


@pytest.mark.parametrize(
    "code",
    [
        "name, _, arg = spec.partition(':')",
        "*merges, last = args.method.split('+')",
        "if weights and ':' not in method.split(',')[0]: pass",
        "spec = f'{method}:{weights}'",
        "spec = f'lburst:{weights}'",
        "text = f'{spec},{option}={value}'",
        "spec += f',frame_order={frame_order}'",
    ],
)
def test_the_check_sees_a_spec_read_or_written_by_hand(code):
    assert spec_handling(ast.parse(code))


@pytest.mark.parametrize(
    "code",
    [
        "raise ValueError(f'{spec}: no such method')",
        "print(f'[2/3] reconstruct with {method} ({i + 1}/{n})')",
        "key = f'{name}:{port}'",
        "method = Method.parse(text).with_option('frame_order', order)",
        "parts = line.split(':')",
    ],
)
def test_the_check_leaves_other_code_alone(code):
    assert not spec_handling(ast.parse(code))
