"""The light network: its checkpoints, its inference form against its training form, its
descriptor sampling, and distillation from a teacher."""

import math

import cv2
import numpy as np
import pytest
import skimage.data
import torch
import torch.nn.functional as F

from lburst import LBurst
from lburst.model.fast import descriptor_stride, descriptors_at
from lburst.model.lite import LiteConfig, LiteNet
from lburst.model.network import CheckpointError, LBurstNet, NetConfig, load_checkpoint, save_checkpoint
from lburst.train.data import PairDataset, list_photos
from lburst.train.distill import lite_distillation_step, teacher_form
from lburst.train.loop import TrainConfig, _normalise, train
from lburst.train.pairs import PairConfig

SMALL = LiteConfig(frames=3, dim=16, fine=8, coarse=16, dilations=(1, 2))
HALF = LiteConfig(frames=3, dim=16, fine=8, coarse=16, dilations=(1, 2), desc_stride=2)
TINY = PairConfig(frames=3, crop=64, long_side=(160, 256), max_burst_motion=6, max_pair_shift=6)


def _trained_bn_net(config=SMALL, seed=0) -> LiteNet:
    """A random net whose BatchNorm statistics moved away from (0, 1), as after training."""
    torch.manual_seed(seed)
    net = LiteNet(config).train()
    with torch.no_grad():
        for _ in range(3):
            net(torch.randn(2, config.in_channels, 40, 48) * 2 + 0.5)
    return net.eval()


def test_net_string_round_trips_and_rejects_other_strings():
    for config in (LiteConfig(), SMALL, HALF):
        assert LiteConfig.from_net_string(config.net_string()) == config
    # the shipped network's string (and so its checkpoint) does not change with desc_stride's default
    assert LiteConfig().net_string() == "LBurstLite(inchan=15,dim=128,fine=32,coarse=96,dilations=1-2-4-8)"
    with pytest.raises(ValueError, match="desc_stride"):
        LiteConfig(desc_stride=3)
    for bad in ("LBurstLite(inchan=14)", "LBurstLite(inchan=15,width=3)", "LBurstLite(inchan=15,dim=x)", "Other()"):
        with pytest.raises(ValueError):
            LiteConfig.from_net_string(bad)
    with pytest.raises(ValueError, match="odd"):
        LiteConfig(frames=4)


@pytest.mark.parametrize("config", [SMALL, HALF], ids=["quarter", "half"])
@pytest.mark.parametrize("size", [(64, 96), (61, 75)])
def test_inference_form_equals_the_training_form_in_eval_mode(size, config):
    net = _trained_bn_net(config)
    x = torch.randn(1, config.in_channels, *size)
    with torch.no_grad():
        out = net(x)
        rep, rel, desc = net.inference().core(x)
    stride = config.desc_stride
    assert rep.shape == rel.shape == (1, 1, *size)
    assert desc.shape == (1, config.dim, math.ceil(size[0] / stride), math.ceil(size[1] / stride))
    assert descriptor_stride(desc.shape[-1], size[1]) == stride
    torch.testing.assert_close(rep, out["repeatability"], atol=1e-5, rtol=1e-4)
    torch.testing.assert_close(rel, out["reliability"], atol=1e-5, rtol=1e-4)
    dense = F.interpolate(desc, scale_factor=float(stride), mode="bilinear", align_corners=False)
    dense = dense[..., : size[0], : size[1]]
    torch.testing.assert_close(F.normalize(dense, dim=1), out["descriptors"], atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("width", [64, 61, 1024, 1023])
def test_descriptor_stride_tells_the_half_map_from_the_quarter_map(width):
    assert descriptor_stride(width // 2, width) == 2
    assert descriptor_stride(math.ceil(width / 4), width) == 4


def test_keypoint_descriptors_are_the_upsampled_quarter_map_at_the_keypoints():
    torch.manual_seed(0)
    desc = torch.randn(1, 8, 13, 17)
    height, width = 50, 66
    dense = F.interpolate(desc, scale_factor=4.0, mode="bilinear", align_corners=False)[..., :height, :width]
    y, x = torch.meshgrid(torch.arange(height), torch.arange(width), indexing="ij")
    got = descriptors_at(desc, y.reshape(-1), x.reshape(-1), stride=4)
    want = F.normalize(dense[0].reshape(8, -1).t(), dim=1)
    torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("stride", [4, 2])
def test_checkpoint_round_trip_and_extraction(tmp_path, stride):
    config = LiteConfig(frames=3, desc_stride=stride)
    net = _trained_bn_net(config)
    path = tmp_path / "lite.pt"
    save_checkpoint(net, path, meta={"input": "aligned"})
    loaded, extra = load_checkpoint(path)
    assert isinstance(loaded, LiteNet) and loaded.config == config
    assert extra["net"].startswith("LBurstLite(inchan=9")
    for k, v in net.state_dict().items():
        torch.testing.assert_close(loaded.state_dict()[k], v, atol=0, rtol=0)
    model = LBurst.from_checkpoint(path, device="cpu")
    assert model.align and model.frames == 3
    burst = np.random.default_rng(0).integers(0, 255, (3, 90, 120, 3), np.uint8)
    feats = model.extract(burst, top_k=50, rel_thr=0.0, rep_thr=0.0)
    assert feats["keypoints"].shape == (50, 2) and feats["descriptors"].shape == (50, 128)
    np.testing.assert_allclose(np.linalg.norm(feats["descriptors"], axis=1), 1, atol=1e-5)
    dense = model.dense(burst)
    assert dense["descriptors"].shape == (90, 120, 128) and dense["repeatability"].shape == (90, 120)
    # the sparse descriptors are the dense map's at the keypoints, whatever the map's stride
    x, y = feats["keypoints"].round().astype(int).T
    np.testing.assert_allclose(feats["descriptors"], dense["descriptors"][y, x], atol=1e-4)


def test_a_checkpoint_with_a_broken_light_net_string_is_a_clear_error(tmp_path):
    path = tmp_path / "bad.pt"
    torch.save({"net": "LBurstLite(inchan=15,dim=0)", "state_dict": {}}, path)
    with pytest.raises(CheckpointError, match="bad.pt"):
        load_checkpoint(path)


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    folder = tmp_path_factory.mktemp("photos")
    for name in ("astronaut", "coffee", "chelsea"):
        cv2.imwrite(str(folder / f"{name}.png"), cv2.cvtColor(getattr(skimage.data, name)(), cv2.COLOR_RGB2BGR))
    return folder


def _student_and_teacher(photos, stride=4):
    """Two pairs of 3-frame bursts, their normalised input, a random teacher, a small student and its optimiser."""
    ds = PairDataset(list_photos([photos]), TINY, seed=0)
    items = [ds[i] for i in range(2)]
    batch = {k: torch.stack([it[k] for it in items]) for k in items[0]}
    x = torch.cat([_normalise(batch["burst_a"]), _normalise(batch["burst_b"])])
    torch.manual_seed(1)
    teacher = teacher_form(LBurstNet(NetConfig(frames=3)).eval())
    torch.manual_seed(0)
    net = LiteNet(LiteConfig(frames=3, fine=16, coarse=32, desc_stride=stride)).train()
    return batch, x, teacher, net, torch.optim.Adam(net.parameters(), lr=3e-3)


@pytest.mark.parametrize("stride", [4, 2])
def test_distillation_pulls_the_student_towards_the_teacher(photos, stride):
    batch, x, teacher, net, opt = _student_and_teacher(photos, stride)
    parts = []
    for _ in range(25):
        losses = lite_distillation_step(net, teacher, batch, x, patch=8)
        opt.zero_grad()
        losses["loss"].backward()
        opt.step()
        parts.append([losses[k].item() for k in ("distill_desc", "distill_rep", "distill_rel")])
    first, last = np.mean(parts[:3], axis=0), np.mean(parts[-3:], axis=0)
    assert np.all(last < 0.8 * first), (first, last)


def test_a_light_run_with_a_teacher_trains_and_resumes(photos, tmp_path):
    torch.manual_seed(0)
    teacher = tmp_path / "teacher.pt"
    save_checkpoint(LBurstNet(NetConfig(frames=3)), teacher)
    cfg = TrainConfig(
        frames=3, batch_size=2, steps=2, patch=8, workers=0, pair=TINY, arch="lite", teacher=str(teacher),
        distill_weight=1.0,
    )  # fmt: skip
    train([photos], tmp_path / "run", cfg, progress=False)
    train([photos], tmp_path / "run", TrainConfig(steps=3, workers=0), resume=True, progress=False)
    net, extra = load_checkpoint(tmp_path / "run" / "final.pt")
    assert isinstance(net, LiteNet) and extra["meta"]["step"] == 3
    state = torch.load(tmp_path / "run" / "last.pt", weights_only=True)
    assert state["config"]["arch"] == "lite" and state["config"]["teacher"] == str(teacher)
    with pytest.raises(ValueError, match="architecture"):
        train([photos], tmp_path / "other", TrainConfig(frames=3, steps=1, workers=0, pair=TINY, init=str(teacher),
                                                        arch="lite"), progress=False)  # fmt: skip


def test_the_ap_term_raises_the_students_cross_view_ap(photos):
    batch, x, teacher, net, opt = _student_and_teacher(photos)
    aps = []
    for step in range(25):
        generator = torch.Generator().manual_seed(step)
        losses = lite_distillation_step(
            net, teacher, batch, x, patch=8, distill_weight=0.0, ap_weight=1.0, generator=generator
        )
        opt.zero_grad()
        losses["loss"].backward()
        opt.step()
        aps.append(losses["ap"].item())
    assert "ap" not in lite_distillation_step(net, teacher, batch, x, patch=8)
    assert 0 <= min(aps) and max(aps) <= 1
    assert np.mean(aps[-3:]) > np.mean(aps[:3]) + 0.05, aps
