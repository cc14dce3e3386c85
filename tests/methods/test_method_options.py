"""Typed method options: one parser for every spec, errors that list the valid options,
wrappers and learned methods found through the registry (never by the name's prefix),
and `lburst methods`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pytest

from lburst.methods import Method, accepts, create, register, registry, weights_file
from lburst.methods.learned import LearnedOptions
from lburst.methods.options import parse_options


@dataclass(frozen=True)
class ToyOptions:
    count: int = 3
    scale: float = 1.5
    flag: bool = False
    mode: Literal["a", "b"] = "a"
    pair: tuple[float, float] | None = None


class Toy:
    def __init__(self, options: ToyOptions) -> None:
        self.options = options
        self.name = "toy"

    def __call__(self, burst: np.ndarray) -> dict:
        k = self.options.count
        return {
            "keypoints": np.zeros((k, 2), np.float32),
            "scales": np.ones(k, np.float32),
            "scores": np.ones(k, np.float32),
            "descriptors": np.ones((k, 4), np.float32),
        }


@pytest.fixture
def toy():
    @register("toy-test", ToyOptions)
    def factory(arg: None, options: ToyOptions) -> Toy:
        """A test method."""
        return Toy(options)

    yield "toy-test"
    registry._METHODS.pop("toy-test")


def test_spec_strings_become_typed_options(toy):
    extractor = create("toy-test,count=7,scale=2,flag=yes,mode=b,pair=1:-2")
    assert extractor.options == ToyOptions(count=7, scale=2.0, flag=True, mode="b", pair=(1.0, -2.0))
    assert extractor.name == "toy-test,count=7,scale=2,flag=yes,mode=b,pair=1:-2"
    assert create(toy, count=2).options.count == 2  # typed keyword options from code
    assert create(toy, pair="none").options.pair is None


@pytest.mark.parametrize(
    "spec, message",
    [
        (
            "toy-test,colour=red",
            r"unknown options for method 'toy-test': colour; valid: count: int = 3, "
            r"scale: float = 1.5, flag: bool = false, mode: a\|b = a, pair: float:float \| none = none",
        ),
        ("toy-test,count=2.5", r"option count of method 'toy-test': expected int, got '2.5'"),
        ("toy-test,flag=maybe", r"option flag of method 'toy-test': expected a boolean"),
        ("toy-test,mode=c", r"option mode of method 'toy-test': expected one of a, b, got 'c'"),
        ("toy-test,pair=1", r"option pair of method 'toy-test': expected 2 numbers"),
        ("toy-test:weights.pt", r"method 'toy-test' takes no argument, got 'weights.pt'"),
        ("toy-test,count", r"bad option 'count' in method spec 'toy-test,count': expected KEY=VALUE"),
        ("nope", r"unknown method 'nope' in 'nope'; available: .*sift"),
    ],
)
def test_bad_specs_say_what_is_valid(toy, spec, message):
    with pytest.raises(ValueError, match=message):
        create(spec)


def test_wrappers_are_registered_methods_with_their_own_options():
    spec = Method.parse("merge,reduce=median+orb,max_features=300")
    assert (spec.name, spec.given, spec.inner.name, spec.inner.given) == (
        "merge",
        {"reduce": "median"},
        "orb",
        {"max_features": "300"},
    )
    extractor = create("merge,reduce=median+orb,max_features=300")
    assert extractor.reduce == "median" and extractor.inner.name == "orb,max_features=300"
    with pytest.raises(ValueError, match=r"option reduce of method 'merge': expected one of mean, median"):
        create("merge,reduce=mode+sift")
    plain = Method.parse("lburst:/runs/a+b/last.pt,top_k=100")  # a '+' inside a path is not a wrapper
    assert (plain.name, plain.arg, plain.inner) == ("lburst", "/runs/a+b/last.pt", None)


def test_learned_methods_are_found_by_their_options_and_weights(tmp_path):
    assert accepts("lburst", "top_k") and accepts("merge+r2d2:x.pt", "top_k")
    assert not accepts("sift", "top_k") and not accepts("merge+sift", "top_k")
    assert weights_file("merge+lburst:/w/x.pt,frame_order=published") == Path("/w/x.pt")
    assert weights_file("sift") is None and weights_file("merge+orb") is None
    assert weights_file("lburst").name == "lburst-b5.pt" and weights_file("r2d2").name == "lburst-b1.pt"


def test_learned_options_default_to_the_papers_multiscale_settings():
    from lburst.model.extractor import MultiScaleConfig

    options = parse_options(LearnedOptions, {"top_k": "none", "precision": "bf16"}, "lburst")
    assert options.top_k is None and options.precision == "bf16"
    assert MultiScaleConfig(**options.multiscale(), top_k=None) == MultiScaleConfig(top_k=None, precision="bf16")
    with pytest.raises(ValueError, match="method 'lburst': precision must be fp32, bf16 or fp16"):
        parse_options(LearnedOptions, {"precision": "int8"}, "lburst")
    given = parse_options(LearnedOptions, {"min_size": "320", "subpixel": "true"}, "lburst").multiscale()
    assert MultiScaleConfig(**given) == MultiScaleConfig(min_size=320, subpixel=True)


def test_lburst_methods_lists_every_method_and_matcher_with_defaults(capsys):
    from lburst.cli import main

    assert main(["methods"]) == 0
    text = capsys.readouterr().out
    for name in registry.available():
        assert f"  {name}" in text
    assert "lburst[:CHECKPOINT][,KEY=VALUE...]" in text and "top_k=4000  (int | none)" in text
    assert "merge[,KEY=VALUE...]+SPEC" in text and "reduce=mean  (mean|median)" in text
    assert "max_features=5000  (int)" in text and "slope_range=none  (float:float | none)" in text
    assert "ratio=0.8  (float)" in text
    assert main(["methods", "sift"]) == 0
    only = capsys.readouterr().out
    assert "root=false  (bool)" in only and "buff" not in only
    assert main(["methods", "nope"]) == 2
    assert capsys.readouterr().err.startswith("lburst methods: error: unknown method or matcher 'nope'")


def test_a_checkpoint_path_with_commas_loads_and_keeps_its_options(tmp_path):
    import shutil

    from lburst.weights import weights_path

    folder = tmp_path / "run,2"
    folder.mkdir()
    shutil.copy(weights_path("lburst-b5-lite"), folder / "w,1.pt")
    spec = f"lburst-lite:{folder / 'w,1.pt'},top_k=7,runtime=torch"
    assert Method.parse(spec).arg == str(folder / "w,1.pt")
    burst = np.random.default_rng(0).integers(0, 255, (5, 64, 80, 3), dtype=np.uint8)
    assert len(create(spec)(burst)["keypoints"]) <= 7
    with pytest.raises(ValueError, match="bad option 'w.pt'"):
        Method.parse("lburst,w.pt")  # no checkpoint given: a bare word is still a bad option


def test_shipped_names_work_where_a_checkpoint_file_is_expected(tmp_path):
    from lburst.cli import main

    assert main(["export", "onnx", "lburst-b5-lite", "--out", str(tmp_path / "lite.onnx")]) == 0
    assert (tmp_path / "lite.onnx").stat().st_size > 100_000


def test_with_default_sets_an_option_the_spec_leaves_unset():
    """An input's default (``top_k`` of a scene) reaches the method that runs on the burst,
    inside a wrapper too, and never overrides what the spec says or a method without it."""

    def with_default(spec: str, option: str, value) -> str:
        return str(Method.parse(spec).with_default(option, value))

    assert with_default("lburst", "top_k", 8000) == "lburst,top_k=8000"
    assert create(Method.parse("lburst").with_default("top_k", 8000)).top_k == 8000
    assert create(Method.parse("merge+lburst").with_default("top_k", 8000)).inner.top_k == 8000
    assert with_default("lburst,top_k=2000", "top_k", 8000) == "lburst,top_k=2000"
    assert with_default("lburst", "top_k", None) == "lburst"
    assert with_default("sift", "top_k", 8000) == "sift"
