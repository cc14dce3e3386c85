"""The network reproduces the published code's outputs and loads checkpoints safely."""

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from lburst.model.extractor import LBurst, frame_permutation
from lburst.model.network import (
    CheckpointError,
    LBurstNet,
    NetConfig,
    load_checkpoint,
    normalize_burst,
    save_checkpoint,
)

CHECKPOINTS = {"lburst_b5": "RoBLo_N16_B5.pt", "r2d2": "R2D2.pt"}


@pytest.fixture(scope="module")
def reference(anchors):
    return dict(np.load(anchors / "reference_outputs.npz"))


@pytest.mark.parametrize("key", sorted(CHECKPOINTS))
def test_dense_maps_and_descriptors_match_published_code(anchors, reference, key):
    model = LBurst.from_checkpoint(anchors / CHECKPOINTS[key], device="cpu")
    dense = model.dense(reference["burst"])
    assert dense["repeatability"].shape == (480, 640)
    np.testing.assert_allclose(dense["repeatability"], reference[f"{key}_repeatability"], atol=1e-5)
    np.testing.assert_allclose(dense["reliability"], reference[f"{key}_reliability"], atol=1e-5)
    y, x = reference[f"{key}_desc_yx"].T
    np.testing.assert_allclose(dense["descriptors"][y, x], reference[f"{key}_desc_samples"], atol=1e-5)


@pytest.mark.parametrize("fast", [True, False], ids=["fast", "plain"])
@pytest.mark.parametrize("key", sorted(CHECKPOINTS))
def test_multiscale_keypoints_are_the_published_set(anchors, reference, key, fast):
    model = LBurst.from_checkpoint(anchors / CHECKPOINTS[key], device="cpu")
    feats = model.extract(reference["burst"], top_k=2000, published_coordinates=True, fast=fast)
    ours = np.c_[feats["keypoints"], feats["scales"]]
    ref = reference[f"{key}_keypoints"]
    dist, idx = cKDTree(ours).query(ref)
    assert dist.max() == 0  # identical coordinates and scales
    assert len(set(idx)) == len(ref) == len(ours)
    np.testing.assert_allclose(feats["scores"][idx], reference[f"{key}_scores"], atol=1e-5)
    np.testing.assert_allclose(feats["descriptors"][idx], reference[f"{key}_descriptors"], atol=1e-5)
    # the corrected convention differs by exactly the documented half-pixel term 0.5 * (W / w - 1)
    corrected = model.extract(reference["burst"], top_k=2000, fast=fast)
    np.testing.assert_array_equal(corrected["scores"], feats["scores"])  # same keypoints, same order
    h, w = reference["burst"].shape[1:3]
    level = 32 / feats["scales"].astype(np.float64)  # the level's scale s
    ratio = np.stack([w / np.round(w * level), h / np.round(h * level)], -1)
    np.testing.assert_allclose(corrected["keypoints"], feats["keypoints"] + 0.5 * (ratio - 1), atol=1e-4)


def test_published_frame_order():
    assert frame_permutation(5, "published") == [1, 0, 2, 3, 4]
    assert frame_permutation(7, "published") == [2, 1, 0, 3, 4, 5, 6]
    assert frame_permutation(3, "published") == [0, 1, 2]
    assert frame_permutation(5, "temporal") == [0, 1, 2, 3, 4]
    with pytest.raises(ValueError, match="frame order"):
        frame_permutation(5, "reversed")


TILINGS = {
    "default tiles": {},
    "bands of 3 rows": {"head_band_rows": 3},
    "stripes of 4 rows": {"stripe_rows": 4},
    "whole map": {"tiled": False},
}


@pytest.mark.parametrize("tiling", TILINGS.values(), ids=TILINGS.keys())
@pytest.mark.parametrize("size", [(75, 98), (64, 80)])
def test_fast_network_matches_the_plain_one(size, tiling):
    """Same maps and descriptors (the keypoint identity is checked on the reference burst above)."""
    from lburst.model.fast import FastLBurstNet, descriptors_at

    torch.manual_seed(0)
    net = LBurstNet(NetConfig(frames=3)).eval()
    for m in net.modules():  # non-trivial BatchNorm statistics, so folding is exercised
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
    x = torch.randn(1, 9, *size)
    with torch.inference_mode():
        plain = net(x)
        rep, rel, half = FastLBurstNet(net, **tiling)(x)
        torch.testing.assert_close(rep, plain["repeatability"], atol=1e-5, rtol=0)
        torch.testing.assert_close(rel, plain["reliability"], atol=1e-5, rtol=0)
        yy, xx = torch.meshgrid(torch.arange(size[0] // 2 * 2), torch.arange(size[1] // 2 * 2), indexing="ij")
        desc = descriptors_at(half, yy.flatten(), xx.flatten())
        torch.testing.assert_close(desc, plain["descriptors"][0, :, yy.flatten(), xx.flatten()].t(), atol=1e-5, rtol=0)


@pytest.mark.parametrize("rows", [1, 3, 8])
def test_banded_heads_match_the_whole_map(rows):
    """Bands of 1, 3 (not dividing 37) and 8 rows, each cut with its context rows."""
    from lburst.model.fast import FastLBurstNet

    torch.manual_seed(0)
    net = LBurstNet(NetConfig(frames=1)).eval()
    half = torch.randn(1, 128, 37, 29).contiguous(memory_format=torch.channels_last)
    with torch.inference_mode():
        whole = FastLBurstNet(net, tiled=False)._heads(half)
        banded = FastLBurstNet(net, head_band_rows=rows)._heads(half)
    assert banded.shape == whole.shape == (1, 3, 74, 58)
    torch.testing.assert_close(banded, whole, atol=1e-6, rtol=1e-6)  # the same sums; oneDNN may order them otherwise


@pytest.mark.parametrize("rows", [2, 4, 6, 200])
def test_striped_front_layers_match_the_whole_map(rows):
    """Stripes of 2 to 6 rows (the first and last touch the zero padding) and one stripe, odd height."""
    from lburst.model.fast import FastLBurstNet

    torch.manual_seed(0)
    fast = FastLBurstNet(LBurstNet(NetConfig(frames=1)).eval(), stripe_rows=rows)
    x = torch.randn(1, 3, 75, 42).contiguous(memory_format=torch.channels_last)
    with torch.inference_mode():
        whole = fast.body[: fast.pool_index + 1](x)
        striped = fast._striped_front(x)
    assert striped.shape == whole.shape == (1, 64, 37, 21)
    torch.testing.assert_close(striped, whole, atol=1e-6, rtol=1e-6)


def test_stripes_must_have_an_even_number_of_rows():
    from lburst.model.fast import FastLBurstNet

    with pytest.raises(ValueError, match="stripe_rows"):
        FastLBurstNet(LBurstNet(NetConfig(frames=1)), stripe_rows=3)


def test_odd_sizes_give_full_size_maps_with_no_keypoints_on_the_missing_row():
    torch.manual_seed(0)
    net = LBurstNet(NetConfig(frames=3)).eval()
    model = LBurst(net)
    burst = np.random.default_rng(0).integers(0, 255, (3, 37, 50, 3), dtype=np.uint8)
    dense = model.dense(burst)
    assert dense["repeatability"].shape == (37, 50)
    assert dense["descriptors"].shape == (37, 50, 128)
    assert (dense["repeatability"][-1] == 0).all() and (dense["reliability"][-1] == 0).all()
    np.testing.assert_allclose(np.linalg.norm(dense["descriptors"], axis=-1), 1, atol=1e-5)


def test_normalisation_of_uint8_and_uint16_agree():
    rng = np.random.default_rng(0)
    b8 = rng.integers(0, 256, (1, 4, 5, 3), dtype=np.uint8)
    b16 = b8.astype(np.uint16) * 257
    torch.testing.assert_close(normalize_burst(b8), normalize_burst(b16))
    x = normalize_burst(b8)
    assert x.shape == (1, 3, 4, 5)
    assert x[0, 0, 0, 0].item() == pytest.approx((b8[0, 0, 0, 0] / 255 - 0.485) / 0.229, abs=1e-6)


def test_wrong_frame_count_is_an_error():
    model = LBurst(LBurstNet(NetConfig(frames=5)))
    with pytest.raises(ValueError, match="5-frame"):
        model.extract(np.zeros((3, 32, 32, 3), np.uint8))


def test_save_and_load_round_trip(tmp_path):
    torch.manual_seed(0)
    net = LBurstNet(NetConfig(frames=3))
    save_checkpoint(net, tmp_path / "n.pt", meta={"step": 7})
    loaded, extra = load_checkpoint(tmp_path / "n.pt")
    assert extra["net"] == "Fast_Quad_L2Net_ConfCFS(inchan=9)" and extra["meta"]["step"] == 7
    for (k, a), b in zip(net.state_dict().items(), loaded.state_dict().values()):
        torch.testing.assert_close(a, b, msg=k)


def test_corrupt_and_truncated_checkpoints_are_clear_errors(tmp_path):
    net = LBurstNet(NetConfig(frames=1))
    good = tmp_path / "good.pt"
    save_checkpoint(net, good)
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(good.read_bytes()[:1000])
    with pytest.raises(CheckpointError, match="truncated.pt: not a readable checkpoint"):
        load_checkpoint(truncated)
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint at all")
    with pytest.raises(CheckpointError, match="garbage.pt"):
        load_checkpoint(garbage)
    with pytest.raises(CheckpointError, match="not found"):
        load_checkpoint(tmp_path / "missing.pt")
    wrong_net = tmp_path / "wrong.pt"
    torch.save({"net": "os.system('rm -rf /')", "state_dict": {}}, wrong_net)
    with pytest.raises(CheckpointError, match="unsupported network"):
        load_checkpoint(wrong_net)
    mismatch = tmp_path / "mismatch.pt"
    torch.save({"net": "Fast_Quad_L2Net_ConfCFS(inchan=15)", "state_dict": net.state_dict()}, mismatch)
    with pytest.raises(CheckpointError, match="do not fit"):
        load_checkpoint(mismatch)


class _Payload:
    """An object whose unpickling would run code (what weights_only=True refuses)."""

    def __reduce__(self):
        return (print, ("this must never run",))


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_a_checkpoint_with_non_finite_weights_is_refused_by_name(tmp_path, bad):
    net = LBurstNet(NetConfig(frames=1))
    state = net.state_dict()
    state["ops.3.weight"][0, 0, 0, 0] = bad
    path = tmp_path / "diverged.pt"
    torch.save({"net": net.config.net_string(), "state_dict": state}, path)
    with pytest.raises(CheckpointError, match=r"diverged.pt: 1 weight tensors hold NaN or inf.*'ops.3.weight'"):
        load_checkpoint(path)


def test_an_unsafe_pickle_is_refused_without_advising_weights_only_false(tmp_path, capsys):
    path = tmp_path / "unsafe.pt"
    torch.save({"net": "Fast_Quad_L2Net_ConfCFS(inchan=3)", "state_dict": {}, "x": _Payload()}, path)
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "weights_only=True only" in message
    assert "weights_only=False" not in message and "this must never run" not in capsys.readouterr().out


def test_images_smaller_than_min_size_are_processed_at_their_own_size():
    torch.manual_seed(0)
    model = LBurst(LBurstNet(NetConfig(frames=1)).eval())
    image = np.random.default_rng(0).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    feats = model.extract(image, rel_thr=0, rep_thr=0)
    assert len(feats["keypoints"]) > 0 and set(feats["scales"]) == {32.0}


def test_learned_method_spec_sets_the_precision_and_rejects_unknown_ones(tmp_path):
    from lburst.methods import create

    save_checkpoint(LBurstNet(NetConfig(frames=1)), tmp_path / "net.pt")
    extractor = create(f"lburst:{tmp_path / 'net.pt'},precision=bf16,fast=true")
    assert extractor.options["precision"] == "bf16" and extractor.options["fast"] is True
    with pytest.raises(ValueError, match="precision must be fp32, bf16 or fp16"):
        create(f"lburst:{tmp_path / 'net.pt'},precision=int8")
