"""ONNX export and the ONNX Runtime backend agree with the torch network."""

import numpy as np
import pytest
import torch

pytest.importorskip("onnxruntime")

from lburst.model.extractor import LBurst  # noqa: E402
from lburst.model.fast import FastLBurstNet  # noqa: E402
from lburst.model.network import CheckpointError, LBurstNet, NetConfig, save_checkpoint  # noqa: E402
from lburst.model.onnx import OnnxRunner, export_onnx  # noqa: E402


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("onnx")
    torch.manual_seed(0)
    net = LBurstNet(NetConfig(frames=3)).eval()
    with torch.no_grad():  # heads of some contrast: maps whose local maxima are not ties of float rounding
        net.sal.weight.mul_(300)
        net.clf.weight.mul_(300)
    save_checkpoint(net, folder / "net.pt")
    return net, export_onnx(folder / "net.pt", folder / "net.onnx")


@pytest.mark.parametrize("size", [(96, 128), (75, 131)])
def test_onnx_runtime_matches_torch_at_any_size(exported, size):
    net, path = exported
    x = torch.randn(1, 9, *size)
    with torch.inference_mode():
        ref = FastLBurstNet(net)(x)
    got = OnnxRunner(path)(x)
    for a, b in zip(got, ref):
        assert a.shape == b.shape
        torch.testing.assert_close(a, b, atol=1e-5, rtol=0)


def test_onnx_model_extracts_through_lburst(exported):
    net, path = exported
    burst = np.random.default_rng(0).integers(0, 256, (3, 70, 90, 3), dtype=np.uint8)
    model = LBurst.from_onnx(path)
    assert model.frames == 3
    dense_onnx, dense_torch = model.dense(burst), LBurst(net).dense(burst)
    for key in dense_torch:
        np.testing.assert_allclose(dense_onnx[key], dense_torch[key], atol=1e-5)


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


@pytest.mark.parametrize("top_k", [None, 300])
def test_onnx_model_extracts_the_keypoints_and_descriptors_of_torch(exported, top_k):
    """Every pyramid level (odd sizes included) through ONNX Runtime: the same keypoints as torch."""
    net, path = exported
    burst = np.random.default_rng(0).integers(0, 256, (3, 70, 90, 3), dtype=np.uint8)
    options = dict(top_k=top_k, min_size=32, rel_thr=0.0, rep_thr=0.0)  # a random network: every local maximum
    got, ref = LBurst.from_onnx(path).extract(burst, **options), LBurst(net).extract(burst, **options)
    assert len(set(ref["scales"].tolist())) >= 4 and len(ref["keypoints"]) >= 300
    _assert_same_features(got, ref)


def test_onnx_model_keeps_the_aligned_input_and_the_descriptor_whitening(exported, tmp_path):
    net, _ = exported
    rng = np.random.default_rng(1)
    mean = rng.normal(size=128).astype(np.float32) * 0.05
    matrix = np.eye(128, dtype=np.float32) + rng.normal(size=(128, 128)).astype(np.float32) * 0.01
    meta = {
        "input": "aligned",
        "descriptor_mean": torch.from_numpy(mean),
        "descriptor_whitening": torch.from_numpy(matrix),
    }
    save_checkpoint(net, tmp_path / "w.pt", meta=meta)
    model = LBurst.from_onnx(export_onnx(tmp_path / "w.pt", tmp_path / "w.onnx"))
    reference = LBurst.from_checkpoint(tmp_path / "w.pt", device="cpu")
    assert model.align and reference.align
    np.testing.assert_array_equal(model.descriptor_whitening.numpy(), matrix)
    burst = rng.integers(0, 256, (3, 70, 90, 3), dtype=np.uint8)
    np.testing.assert_allclose(
        model.dense(burst, whiten=True)["descriptors"], reference.dense(burst, whiten=True)["descriptors"], atol=1e-4
    )
    assert not LBurst.from_onnx(exported[1]).align  # weights for unaligned bursts stay so


def test_bad_onnx_file_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"nope")
    with pytest.raises(CheckpointError, match="bad.onnx"):
        OnnxRunner(bad)


def test_another_network_with_the_same_input_channels_is_refused_by_name(tmp_path):
    import onnx
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("burst", TensorProto.FLOAT, [1, 15, "h", "w"])
    y = helper.make_tensor_value_info("logits", TensorProto.FLOAT, [1, 15, "h", "w"])
    graph = helper.make_graph([helper.make_node("Relu", ["burst"], ["logits"])], "other", [x], [y])
    path = tmp_path / "other.onnx"
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)]), path)
    with pytest.raises(CheckpointError, match=r"other.onnx: not an lburst export .*outputs \['logits'\]"):
        LBurst.from_onnx(path)
