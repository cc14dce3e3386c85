"""CPU runtimes of the light network (lburst.model.runtimes): the ONNX export, OpenVINO and
int8 runners reproduce (or, for int8, follow) the torch maps; no timings here."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import torch

from lburst import calibration as cal
from lburst.extras import MissingExtra
from lburst.model import openvino as ov
from lburst.model import runtimes as rt
from lburst.model.extractor import LBurst
from lburst.model.lite import LiteConfig, LiteNet
from lburst.model.network import normalize_burst, save_checkpoint
from lburst.model.onnx import quantize_onnx
from lburst.model.runtimes import Runtime, inference_form

SMALL = LiteConfig(frames=3, dim=16, fine=8, coarse=16, dilations=(1, 2))
SIZES = [(96, 128), (75, 131)]  # an odd size too


@pytest.fixture(scope="module")
def net() -> LiteNet:
    torch.manual_seed(0)
    return LiteNet(SMALL).eval()


@pytest.fixture(scope="module")
def exported(net, tmp_path_factory):
    """The small light net's checkpoint (aligned input, whitening) exported by ``export_onnx``."""
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnxscript")
    from lburst.model.onnx import export_onnx

    folder = tmp_path_factory.mktemp("lite-onnx")
    meta = {"input": "aligned", "descriptor_mean": torch.zeros(SMALL.dim), "descriptor_whitening": torch.eye(SMALL.dim)}
    save_checkpoint(net, folder / "lite.pt", meta=meta)
    return export_onnx(folder / "lite.pt", folder / "lite.onnx")


def _reference(net: LiteNet, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
    with torch.inference_mode():
        return inference_form(net)(x)


def _assert_maps_close(got, ref, atol: float = 1e-4) -> None:
    assert len(got) == len(ref) == 3
    for a, b in zip(got, ref):
        assert a.shape == b.shape
        torch.testing.assert_close(a.float(), b.float(), atol=atol, rtol=0)


@pytest.mark.parametrize("size", SIZES)
def test_onnx_export_of_the_light_net_matches_torch(net, exported, size):
    from lburst.model.onnx import OnnxRunner

    x = torch.randn(1, SMALL.in_channels, *size)
    runner = OnnxRunner(exported)
    got, ref = runner(x), _reference(net, x)
    _assert_maps_close(got, ref)
    assert ref[2].shape[-2:] == ((size[0] + 3) // 4, (size[1] + 3) // 4)  # the quarter map, as 'half'
    assert runner.frames == SMALL.frames and runner.meta["input"] == "aligned"


def test_onnx_light_model_extracts_through_lburst(net, exported):
    burst = np.random.default_rng(0).integers(0, 256, (3, 70, 90, 3), dtype=np.uint8)
    model = LBurst.from_onnx(exported)
    assert model.align  # the checkpoint's meta travels with the graph
    assert model.pad == 0  # no meta['pad']: no reflected border
    model.align = False
    got, ref = model.dense(burst), LBurst(net).dense(burst)
    for key in ref:
        np.testing.assert_allclose(got[key], ref[key], atol=1e-4)


def _assert_same_features(got: dict, ref: dict) -> None:
    """The keypoints of ``got`` are those of ``ref`` (the same positions and scales, in any order: scores
    within float rounding of each other may rank either way), with their scores and descriptors."""

    def where(features: dict) -> dict:
        keys = np.column_stack([features["keypoints"], features["scales"]]).round(3)
        return {tuple(key): i for i, key in enumerate(keys.tolist())}

    a, b = where(got), where(ref)
    assert a.keys() == b.keys(), f"{len(a.keys() - b.keys())} keypoints more, {len(b.keys() - a.keys())} missing"
    common = sorted(a)
    i, j = [a[k] for k in common], [b[k] for k in common]
    np.testing.assert_allclose(got["scores"][i], ref["scores"][j], atol=1e-5)
    np.testing.assert_allclose(got["descriptors"][i], ref["descriptors"][j], atol=1e-4)


@pytest.mark.parametrize("runtime", ["onnx", "openvino"])
@pytest.mark.parametrize("top_k", [None, 300])
def test_the_runtimes_extract_the_keypoints_and_descriptors_of_torch(net, exported, runtime, top_k):
    """Every pyramid level (odd sizes included) through ONNX Runtime or OpenVINO: the keypoints,
    scales, scores and descriptors of the torch network."""
    if runtime == "onnx":
        model = LBurst.from_onnx(exported)
    else:
        pytest.importorskip("openvino")
        model = LBurst(None, runner=ov.OpenVinoRunner(exported, threads=1), frames=SMALL.frames)
    model.align = False
    burst = np.random.default_rng(1).integers(0, 256, (3, 70, 90, 3), dtype=np.uint8)
    options = dict(top_k=top_k, min_size=32, rel_thr=0.0, rep_thr=0.0)  # a random network: every local maximum
    got, ref = model.extract(burst, **options), LBurst(net).extract(burst, **options)
    assert len(set(ref["scales"].tolist())) >= 4 and len(ref["keypoints"]) >= 300
    _assert_same_features(got, ref)


@pytest.fixture(scope="module")
def converted(net):
    """The small light net converted from torch by ``openvino.convert_model`` (done once: slow)."""
    pytest.importorskip("openvino")
    return ov.openvino_model(net, {"input": "aligned"})


@pytest.mark.parametrize("source", ["onnx", "net"])
def test_openvino_fp32_matches_torch(net, exported, converted, source):
    runner = ov.OpenVinoRunner(exported if source == "onnx" else converted, threads=1)
    assert runner.frames == SMALL.frames and runner.meta["input"] == "aligned"
    for size in SIZES:
        x = torch.randn(1, SMALL.in_channels, *size)
        _assert_maps_close(runner(x), _reference(net, x))
    compiles = runner.compile_seconds
    runner(torch.randn(1, SMALL.in_channels, *SIZES[0]))  # a shape seen before: no new compile
    assert runner.compile_seconds == compiles and len(runner._requests) == len(SIZES)
    if source == "onnx":
        assert runner.meta["descriptor_mean"].shape == (SMALL.dim,)


def test_openvino_dynamic_shape_model_matches_torch(net, exported):
    pytest.importorskip("openvino")
    runner = ov.OpenVinoRunner(exported, threads=1, dynamic=True)
    for size in SIZES:
        x = torch.randn(1, SMALL.in_channels, *size)
        _assert_maps_close(runner(x), _reference(net, x))
    assert len(runner._requests) == 1


def test_openvino_runner_runs_lburst(net, exported):
    pytest.importorskip("openvino")
    burst = np.random.default_rng(1).integers(0, 256, (3, 70, 90, 3), dtype=np.uint8)
    model = LBurst(None, runner=ov.OpenVinoRunner(exported, threads=1), frames=SMALL.frames)
    got, ref = model.dense(burst), LBurst(net).dense(burst)
    for key in ref:
        np.testing.assert_allclose(got[key], ref[key], atol=1e-4)
    assert len(model.extract(burst, top_k=50)["scores"]) == len(LBurst(net).extract(burst, top_k=50)["scores"])


@pytest.fixture(scope="module")
def calibration():
    """Small deterministic calibration bursts from synthetic photos (no data folder needed)."""
    rng = np.random.default_rng(0)
    photos = []
    for _ in range(2):
        base = rng.integers(0, 256, (12, 16, 3)).astype(np.uint8)
        photos.append(np.repeat(np.repeat(base, 8, axis=0), 8, axis=1))  # blocks: edges and flat areas
    return cal.calibration_bursts(photos, count=4, frames=SMALL.frames, long_side=(64, 96), seed=0)


def test_calibration_bursts_are_seeded_and_normalised(calibration):
    photos = [np.full((48, 64, 3), 128, np.uint8), np.zeros((48, 64, 3), np.uint8)]
    a = cal.calibration_bursts(photos, count=2, frames=3, long_side=(40, 60), seed=3)
    b = cal.calibration_bursts(photos, count=2, frames=3, long_side=(40, 60), seed=3)
    for x, y in zip(a, b):
        torch.testing.assert_close(x, y, atol=0, rtol=0)
    assert all(x.shape[:2] == (1, 9) and 40 <= max(x.shape[-2:]) <= 60 for x in a)
    assert all(x.dtype == torch.float32 and x.ndim == 4 for x in calibration)


def test_training_photos_leave_out_the_validation_tenth(tmp_path):
    from lburst.train.data import is_validation_photo

    for i in range(40):
        (tmp_path / f"p{i}.jpg").write_bytes(b"")
    found = cal.training_photos(tmp_path)
    assert found and all(not is_validation_photo(p) for p in found)
    assert len(found) == sum(not is_validation_photo(tmp_path / f"p{i}.jpg") for i in range(40))


def _correlation(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(torch.corrcoef(torch.stack([a.flatten().double(), b.flatten().double()]))[0, 1])


def _check_int8(runner, net, calibration) -> None:
    x = calibration[0]
    ref = _reference(net, x)
    got = runner(x)
    for a, b in zip(got, ref):
        assert a.shape == b.shape and a.dtype == torch.float32
        assert _correlation(a, b) > 0.9


def test_openvino_int8_follows_fp32(net, exported, calibration):
    pytest.importorskip("openvino")
    pytest.importorskip("nncf")
    quantized = ov.quantize_openvino(exported, calibration)
    _check_int8(ov.OpenVinoRunner(quantized, threads=1), net, calibration)


def test_onnxruntime_int8_follows_fp32(net, exported, calibration, tmp_path):
    from lburst.model.onnx import OnnxRunner

    path = quantize_onnx(exported, tmp_path / "int8.onnx", calibration)
    runner = OnnxRunner(path, threads=1)
    assert runner.meta["input"] == "aligned"  # metadata kept
    _check_int8(runner, net, calibration)


def test_choose_runtime_follows_the_documented_rule():
    def choose(*args, **kwargs) -> str:
        return rt.choose_runtime(*args, **kwargs).name

    assert choose() in rt.RUNTIMES
    everything = set(rt.RUNTIMES)
    assert choose({"avx512_bf16"}, everything) == "openvino-bf16"
    assert choose({"amx_bf16"}, everything, exact=True) == "openvino"
    assert choose({"amx_bf16"}, everything, exact=True, threads=1) == "onnxruntime"
    assert choose({"avx2"}, everything) == "openvino"
    assert choose({"avx2"}, everything, threads=1) == "onnxruntime"
    assert choose({"avx512_bf16"}, {"torch", "onnxruntime"}) == "onnxruntime"
    assert choose({"avx2"}, {"torch", "openvino"}, threads=1) == "openvino"
    assert choose({"avx512_bf16"}, {"torch"}) == "torch-bf16"
    assert choose({"avx512_bf16"}, {"torch"}, exact=True) == "torch"
    assert choose(set(), ()) == "torch"


def test_make_runner_torch_runtimes_need_no_extras(net):
    x = torch.randn(1, SMALL.in_channels, *SIZES[1])
    _assert_maps_close(rt.make_runner("torch", net)(x), _reference(net, x), atol=0)
    with pytest.raises(ValueError, match="unknown runtime"):
        rt.make_runner("tensorrt", net)


def test_missing_openvino_names_the_extra(net, monkeypatch):
    monkeypatch.setitem(sys.modules, "openvino", None)
    with pytest.raises(MissingExtra, match=r"lburst\[openvino\]"):
        ov.OpenVinoRunner(net)


def test_a_checkpoint_on_a_runtime_keeps_its_meta(net, tmp_path):
    meta = {"input": "aligned", "descriptor_mean": torch.zeros(SMALL.dim)}
    save_checkpoint(net, tmp_path / "lite.pt", meta=meta)
    model = LBurst.from_checkpoint(tmp_path / "lite.pt", "cpu", runtime="torch-bf16")
    assert model.runtime == "torch-bf16" and model.frames == SMALL.frames and model.align
    assert model.descriptor_mean is not None
    burst = np.random.default_rng(2).integers(0, 256, (3, 40, 56, 3), dtype=np.uint8)
    assert model.dense(burst)["descriptors"].shape == (40, 56, SMALL.dim)


def test_a_runtime_name_is_parsed_once_into_an_engine_and_a_precision():
    assert [Runtime.parse(name).name for name in rt.RUNTIMES] == list(rt.RUNTIMES)
    assert Runtime.parse("openvino-int8") == Runtime("openvino", "int8")
    assert Runtime.parse("torch") == Runtime("torch", "fp32") and Runtime.parse(Runtime()) == Runtime()
    assert Runtime("openvino", "int8").modules == ("openvino", "nncf") and Runtime("torch").modules == ()
    assert Runtime("onnxruntime").cpu_only and not Runtime("torch", "bf16").cpu_only
    for bad in ("tensorrt", "torch-int8", "onnxruntime-bf16", "openvino-", "openvino-bf16-x", ""):
        with pytest.raises(ValueError, match="unknown runtime"):
            Runtime.parse(bad)
    with pytest.raises(ValueError, match="unknown runtime 'torch-fp16'"):
        Runtime("torch", "fp16")


def test_resolve_runtime_picks_one_for_the_network_and_the_device():
    cpu, cuda = torch.device("cpu"), torch.device("cuda")
    assert rt.resolve_runtime(None, False, cpu, 1) == Runtime("torch")  # the Fast-Quad-L2-Net: torch
    assert rt.resolve_runtime(None, True, cpu, 1) == rt.choose_runtime(threads=1)  # the light network: auto
    assert rt.resolve_runtime(None, True, cuda, 1) == Runtime("torch")
    assert rt.resolve_runtime("auto", False, cuda, None) == Runtime("torch")
    assert rt.resolve_runtime("torch-bf16", False, cuda, None) == Runtime("torch", "bf16")
    with pytest.raises(ValueError, match="runs on the CPU only"):
        rt.resolve_runtime("openvino", True, cuda, None)


def test_an_int8_runtime_is_calibrated_on_the_bursts_of_the_caller(net, tmp_path, monkeypatch):
    """lburst.model makes no calibration set: without one an int8 runtime is refused in one line;
    a function of the frame count is called with the network's, and bursts are normalised."""
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnxscript")
    save_checkpoint(net, tmp_path / "lite.pt", meta={"input": "aligned"})
    with pytest.raises(
        ValueError, match=r"'onnxruntime-int8' is calibrated on bursts the caller gives: pass calibration="
    ):
        LBurst.from_checkpoint(tmp_path / "lite.pt", "cpu", runtime="onnxruntime-int8")
    asked, seen = [], []

    def bursts(frames: int) -> list[np.ndarray]:
        asked.append(frames)
        return [np.random.default_rng(i).integers(0, 256, (frames, 48, 64, 3), dtype=np.uint8) for i in range(2)]

    monkeypatch.setattr(rt, "quantize_onnx", lambda path, out, calibration: seen.append(calibration) or path)
    model = LBurst.from_checkpoint(tmp_path / "lite.pt", "cpu", runtime="onnxruntime-int8", calibration=bursts)
    assert asked == [SMALL.frames] and model.runtime == "onnxruntime-int8"
    for got, burst in zip(seen[0], bursts(SMALL.frames), strict=True):
        torch.testing.assert_close(got, normalize_burst(burst), atol=0, rtol=0)
