"""A model whose weights hold NaN or inf is refused where it is loaded, whatever its format: a
checkpoint did so already; an ONNX export gave 0 keypoints silently, and so did OpenVINO."""

import numpy as np
import pytest
import torch

from lburst.model.extractor import LBurst
from lburst.model.lite import LiteConfig, LiteNet
from lburst.model.network import CheckpointError, save_checkpoint

NAN_WEIGHTS = r"1 weight tensors hold NaN or inf \(a diverged run\?\), first "


def _net(poison: float | None) -> LiteNet:
    torch.manual_seed(0)
    net = LiteNet(LiteConfig(frames=3, fine=8, coarse=16, dilations=(1, 2))).eval()
    if poison is not None:
        with torch.no_grad():
            net.desc.weight[3, 2] = poison
    return net


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    """A light network's ONNX export, and copies of it with one value of its descriptor weights
    made NaN or inf (one export: they take seconds each)."""
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnxscript")
    import onnx
    from onnx import numpy_helper

    from lburst.model.onnx import export_network_onnx

    folder = tmp_path_factory.mktemp("nan")
    good = export_network_onnx(_net(None), folder / "good.onnx")
    paths = {"good": good}
    for name, poison in (("nan", np.nan), ("inf", np.inf)):
        model = onnx.load(str(good))
        weights = next(t for t in model.graph.initializer if numpy_helper.to_array(t).shape[:2] == (128, 16))
        values = numpy_helper.to_array(weights).copy()
        values[3, 2] = poison
        weights.CopyFrom(numpy_helper.from_array(values, weights.name))
        onnx.save(model, str(folder / f"{name}.onnx"))
        paths[name] = folder / f"{name}.onnx"
    return paths


@pytest.mark.parametrize("name", ["nan", "inf"])
def test_an_onnx_export_with_nan_weights_is_refused_at_load(exports, name):
    from lburst.model.onnx import OnnxRunner

    with pytest.raises(CheckpointError, match=rf"{name}.onnx: {NAN_WEIGHTS}"):
        OnnxRunner(exports[name])
    with pytest.raises(CheckpointError, match=rf"{name}.onnx: {NAN_WEIGHTS}"):
        LBurst.from_onnx(exports[name])


def test_a_good_onnx_export_still_loads_and_gives_finite_maps(exports):
    burst = np.random.default_rng(0).integers(0, 256, (3, 64, 80, 3), dtype=np.uint8)
    dense = LBurst.from_onnx(exports["good"]).dense(burst)
    assert all(np.isfinite(value).all() for value in dense.values())


def test_openvino_refuses_nan_weights_from_a_file_or_a_network(exports):
    pytest.importorskip("openvino")
    from lburst.model.openvino import OpenVinoRunner

    with pytest.raises(CheckpointError, match=rf"nan.onnx: {NAN_WEIGHTS}"):
        OpenVinoRunner(exports["nan"])
    with pytest.raises(CheckpointError, match=rf"LiteNet: {NAN_WEIGHTS}'[^']*desc"):
        OpenVinoRunner(_net(float("nan")))
    assert OpenVinoRunner(exports["good"]).frames == 3


def test_a_checkpoint_with_nan_weights_says_the_same(tmp_path):
    save_checkpoint(_net(float("nan")), tmp_path / "nan.pt")
    with pytest.raises(CheckpointError, match=rf"nan.pt: {NAN_WEIGHTS}'desc.weight'"):
        LBurst.from_checkpoint(tmp_path / "nan.pt")
