"""The extractor speaks torch: ``LBurst.to(device)`` and ``.device``, bursts as tensors in torch's
layout (kornia and LightGlue's convention), batches of them, and ``image_size`` in every result."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lburst.model.extractor import LBurst, burst_from_tensor
from lburst.model.network import LBurstNet, NetConfig

OPTIONS = {"rel_thr": 0, "rep_thr": 0, "top_k": 300}  # a random network: keypoints anywhere


@pytest.fixture(scope="module")
def model() -> LBurst:
    torch.manual_seed(0)
    return LBurst(LBurstNet(NetConfig(frames=3)))


@pytest.fixture(scope="module")
def burst() -> np.ndarray:
    return np.random.default_rng(0).integers(0, 256, (3, 40, 56, 3), dtype=np.uint8)


def as_tensor(burst: np.ndarray) -> torch.Tensor:
    """A NumPy burst (N, H, W, 3) as torch's (N, 3, H, W)."""
    return torch.from_numpy(burst).permute(0, 3, 1, 2)


def assert_same(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_to_moves_the_network_and_returns_the_model_like_a_module():
    torch.manual_seed(0)
    model = LBurst(LBurstNet(NetConfig(frames=1)), device="cpu")  # the construction option still works
    assert model.device == torch.device("cpu")
    assert model.to("cpu") is model and model.to(torch.device("cpu")) is model
    assert model.fast_net is not None  # built on first use: moved as well
    assert model.to("meta") is model  # a device without data: where every parameter must go
    assert model.device == torch.device("meta")
    assert {p.device.type for p in model.net.parameters()} == {"meta"}
    assert {p.device.type for p in model.fast_net.parameters()} == {"meta"}
    with pytest.raises(ValueError, match="LBurst.to takes a device"):
        model.to(torch.float16)


def test_to_refuses_a_gpu_for_a_cpu_only_runtime():
    runner = lambda x: x  # noqa: E731 - a stand-in for ONNX Runtime: not a torch module
    model = LBurst(None, runner=runner, frames=1)
    assert model.to("cpu") is model
    with pytest.raises(ValueError, match="runs on the CPU only"):
        model.to("cuda")
    with pytest.raises(ValueError, match="runs on the CPU only"):
        model.to(torch.device("cuda", 0))


def test_a_float_tensor_gives_exactly_the_uint8_features(model, burst):
    expected = model.extract(burst, **OPTIONS)
    assert len(expected["keypoints"]) > 0
    x = as_tensor(burst).float() / 255  # kornia's convention
    assert_same(model.extract(x, **OPTIONS), expected)
    assert_same(model.extract(as_tensor(burst) * (1 / 255.0), **OPTIONS), expected)  # other float rounding
    assert_same(model.extract(x.half(), **OPTIONS), expected)
    assert_same(model.extract(x.double(), **OPTIONS), expected)
    assert_same(model.extract(as_tensor(burst), **OPTIONS), expected)  # uint8 tensor
    assert_same(model.extract(x.contiguous(memory_format=torch.channels_last), **OPTIONS), expected)


def test_a_float_tensor_of_more_than_eight_bits_keeps_its_precision(model, burst):
    x = (
        as_tensor(burst).float()
        + torch.rand(burst.shape[0], 3, *burst.shape[1:3], generator=torch.Generator().manual_seed(0))
    ) / 256
    array = burst_from_tensor(x)
    assert array.dtype == np.uint16 and array.shape == burst.shape
    np.testing.assert_array_equal(array, np.round(x.permute(0, 2, 3, 1).numpy() * 65535).astype(np.uint16))
    assert_same(model.extract(x, **OPTIONS), model.extract(array, **OPTIONS))


def test_a_batch_tensor_gives_a_list_of_features(model, burst):
    other = burst[:, ::-1].copy()
    x = torch.stack([as_tensor(burst), as_tensor(other)]).float() / 255
    found = model.extract(x, **OPTIONS)
    assert isinstance(found, list) and len(found) == 2
    for feats, single in zip(found, (burst, other)):
        expected = model.extract(single, **OPTIONS)
        np.testing.assert_allclose(feats["keypoints"], expected["keypoints"], atol=1e-4)
        np.testing.assert_allclose(feats["descriptors"], expected["descriptors"], atol=1e-4)
        np.testing.assert_array_equal(feats["image_size"], [56, 40])
    one = model.extract(x[:1], **OPTIONS)
    assert isinstance(one, list) and len(one) == 1  # a batch of one is still a batch
    assert isinstance(model.extract_batch([burst], **OPTIONS), list)
    turned = model.extract(x, rotations=2, **OPTIONS)
    assert isinstance(turned, list) and len(turned) == 2 and "rotations" in turned[0]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda x: x * 255, r"must be in \[0, 1\], this one spans \[0, 255\]"),
        (lambda x: x - 0.5, r"must be in \[0, 1\]"),
        (lambda x: x.masked_fill(x > 0.9, float("nan")), "NaN or infinite"),
        (lambda x: x[:2], "takes 3-frame bursts, got 2 frames"),
        (lambda x: x.permute(0, 2, 3, 1), r"must be \(N, 3, H, W\).*channels last"),
        (lambda x: x[:, :1], r"must be \(N, 3, H, W\).*gray"),
        (lambda x: x[0, 0], r"must be \(N, 3, H, W\)"),
        (lambda x: (x * 255).int(), "must be uint8 or float in \\[0, 1\\], got torch.int32"),
    ],
)
def test_wrong_tensors_are_one_line_errors(model, burst, make, message):
    with pytest.raises(ValueError, match=message) as info:
        model.extract(make(as_tensor(burst).float() / 255))
    assert "\n" not in str(info.value)


def test_image_size_is_width_then_height_as_lightglue(model, burst):
    feats = model.extract(burst, **OPTIONS)
    assert feats["image_size"].dtype == np.int64 and feats["image_size"].tolist() == [56, 40]
    turned = model.extract(burst, rotations=4, **OPTIONS)  # sets extracted from turned bursts
    assert turned["image_size"].tolist() == [56, 40]
    assert len(turned["rotations"]) == len(turned["keypoints"])
    single = LBurst(LBurstNet(NetConfig(frames=1)))
    assert single.extract(burst[1], **OPTIONS)["image_size"].tolist() == [56, 40]
