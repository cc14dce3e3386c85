"""Training: a short run learns, and a stopped-and-resumed run equals an uninterrupted one."""

import csv
from dataclasses import replace

import cv2
import numpy as np
import pytest
import skimage.data
import torch

from lburst.model.network import LBurstNet, NetConfig, load_checkpoint
from lburst.train.data import PairDataset, list_photos
from lburst.train.loop import TrainConfig, train, training_step
from lburst.train.pairs import PairConfig

TINY = PairConfig(frames=3, crop=64, long_side=(160, 256), max_burst_motion=6, max_pair_shift=6)


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    folder = tmp_path_factory.mktemp("photos")
    for name in ("astronaut", "coffee", "chelsea"):
        cv2.imwrite(str(folder / f"{name}.png"), cv2.cvtColor(getattr(skimage.data, name)(), cv2.COLOR_RGB2BGR))
    return folder


def _log(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_a_few_steps_on_one_batch_lower_the_loss(photos):
    ds = PairDataset(list_photos([photos]), TINY, seed=0)
    items = [ds[i] for i in range(2)]
    batch = {k: torch.stack([it[k] for it in items]) for k in items[0]}
    torch.manual_seed(0)
    net = LBurstNet(NetConfig(frames=3)).train()
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    losses = []
    for _ in range(12):
        loss = training_step(net, batch, patch=8)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert np.mean(losses[-3:]) < np.mean(losses[:3]) - 0.02


def test_a_run_leaves_its_callers_thread_count_and_random_state(photos, tmp_path):
    """``train`` sets torch's threads and seeds torch for the run only (the caller's own draws go on)."""
    threads = torch.get_num_threads()
    torch.manual_seed(7)
    expected = torch.rand(3)
    torch.manual_seed(7)
    cfg = TrainConfig(frames=3, batch_size=2, steps=1, patch=8, workers=0, pair=TINY, threads=threads + 1)
    train([photos], tmp_path, cfg, progress=False)
    assert torch.get_num_threads() == threads
    assert torch.equal(torch.rand(3), expected)


def test_stopped_and_resumed_run_matches_an_uninterrupted_one(photos, tmp_path):
    cfg = TrainConfig(frames=3, batch_size=2, steps=4, patch=8, workers=0, pair=TINY, snapshot_every=2)
    train([photos], tmp_path / "full", cfg, progress=False)
    train([photos], tmp_path / "split", replace(cfg, steps=2), progress=False)
    with pytest.raises(FileExistsError, match="--resume"):
        train([photos], tmp_path / "split", cfg, progress=False)
    train([photos], tmp_path / "split", cfg, resume=True, progress=False)
    full, split = _log(tmp_path / "full" / "log.csv"), _log(tmp_path / "split" / "log.csv")
    assert [r["step"] for r in split] == ["1", "2", "3", "4"]
    # same data stream and RNG state; multi-threaded CPU kernels may differ in the last bits
    np.testing.assert_allclose([float(r["loss"]) for r in split], [float(r["loss"]) for r in full], atol=1e-4)
    a = torch.load(tmp_path / "full" / "last.pt", weights_only=True)
    b = torch.load(tmp_path / "split" / "last.pt", weights_only=True)
    assert a["step"] == b["step"] == 4
    for k in a["state_dict"]:
        torch.testing.assert_close(a["state_dict"][k], b["state_dict"][k], atol=1e-4, rtol=1e-4, msg=k)
    net, extra = load_checkpoint(tmp_path / "full" / "final.pt")  # the published layout
    assert extra["net"] == "Fast_Quad_L2Net_ConfCFS(inchan=9)"
    for run in ("full", "split"):  # snapshots every 2 steps, across the resume too
        snaps = sorted(p.name for p in (tmp_path / run / "snapshots").iterdir())
        assert snaps == ["step_000002.pt", "step_000004.pt"], run
    last_snapshot, _ = load_checkpoint(tmp_path / "full" / "snapshots" / "step_000004.pt")
    for k, v in net.state_dict().items():
        torch.testing.assert_close(last_snapshot.state_dict()[k], v, atol=0, rtol=0, msg=k)


def test_training_pairs_flow_maps_a_onto_b(photos):
    """Noise-free pair: B's common frame sampled at the flow reproduces A's common frame."""
    from lburst.train.pairs import training_pair

    cfg = replace(TINY, crop=96, noise_variance=(0.0, 0.0), max_burst_motion=0.0)
    photo = cv2.cvtColor(cv2.imread(str(photos / "astronaut.png")), cv2.COLOR_BGR2RGB)
    photo = cv2.GaussianBlur(photo, (0, 0), 4)  # smooth: resampling errors stay small
    pair = training_pair(photo, np.random.default_rng(3), cfg)
    a, b = pair.burst_a[1], pair.burst_b[1]
    warped = cv2.remap(b, pair.flow[..., 0], pair.flow[..., 1], cv2.INTER_LINEAR)
    inner = pair.mask & (cv2.erode(pair.mask.astype(np.uint8), np.ones((5, 5))) > 0)
    assert inner.mean() > 0.3
    assert np.abs(warped - a)[inner].mean() < 1.0  # resampling and rounding only
    # and the flow is the homography: a point maps where G says
    g = pair.homography
    p = g @ np.array([10.0, 20.0, 1.0])
    np.testing.assert_allclose(pair.flow[20, 10], p[:2] / p[2], atol=1e-3)


def test_flow_sends_blobs_of_a_onto_the_same_blobs_of_b():
    """Ground truth independent of the flow's own formula: blob centres found in both common frames."""
    from scipy import ndimage

    from lburst.train.pairs import training_pair

    rng = np.random.default_rng(0)
    size = 400
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
    photo = np.zeros((size, size), np.float64)
    for cx, cy in rng.uniform(60, size - 60, (12, 2)):
        photo += 200 * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * 3.0**2))
    photo = np.repeat(np.clip(photo, 0, 255).astype(np.uint8)[..., None], 3, axis=2)
    cfg = replace(
        TINY,
        crop=160,
        long_side=(400, 400),
        noise_variance=(0.0, 0.0),
        max_burst_motion=0.0,
        max_rotation_deg=10.0,
        max_tilt=0.1,
        max_pair_shift=8.0,
    )
    pair = training_pair(photo, np.random.default_rng(5), cfg)

    def centres(img):
        g = img[..., 0].astype(np.float64)
        labels, n = ndimage.label(g > 40)
        c = np.array(ndimage.center_of_mass(g, labels, range(1, n + 1)))[:, ::-1]  # (x, y)
        sizes = ndimage.sum(np.ones_like(g), labels, range(1, n + 1))
        touching = [np.any(labels[[0, -1], :] == i + 1) or np.any(labels[:, [0, -1]] == i + 1) for i in range(n)]
        return c[(sizes > 20) & ~np.array(touching)]

    ca, cb = centres(pair.burst_a[1]), centres(pair.burst_b[1])
    assert len(ca) >= 3
    checked = 0
    for x, y in ca:
        target = np.array(
            [
                cv2.remap(pair.flow[..., 0], np.float32([[x]]), np.float32([[y]]), cv2.INTER_LINEAR)[0, 0],
                cv2.remap(pair.flow[..., 1], np.float32([[x]]), np.float32([[y]]), cv2.INTER_LINEAR)[0, 0],
            ]
        )
        dist = np.linalg.norm(cb - target, axis=1)
        if dist.min() < 5:
            assert dist.min() < 0.1  # blob centres, so interpolation and blob shape distortion are small
            checked += 1
    assert checked >= 3


class _Recorded(torch.nn.Module):
    """``net`` that keeps the outputs of its last forward pass."""

    def __init__(self, net: torch.nn.Module) -> None:
        super().__init__()
        self.net, self.outputs = net, {}

    def forward(self, x, **kwargs):
        self.outputs = self.net(x, **kwargs)
        return self.outputs


@pytest.mark.parametrize("threads", [1, 2])
def test_bf16_autocast_step_gives_the_fp32_losses_and_gradient_direction(photos, threads):
    """The bf16 forward pass changes the losses by rounding only, and the network's gradient
    direction too: with the loss's own gradient at the outputs held fixed (fp32's), the bf16
    backward pass gives the fp32 gradient at cosine 0.987 (0.9869 to 0.9873 with oneDNN's AMX,
    AVX512-BF16, AVX512 and AVX2 kernels, ``ONEDNN_MAX_CPU_ISA``, at 1 and 2 threads).

    The whole step's gradient is not compared so: rounding leaves the descriptors 2 % off
    (0.3 % after the first layer, growing at each BatchNorm), and the reliability loss's
    gradient is discontinuous in them (quantised AP's triangular bins, the best positive of
    each query): 2 % of random change turns it to cosine 0.87 where 1 % leaves 0.997.  With
    the 31 queries of this batch the step's cosine then depends on which of them cross a
    bin, that is on the kernels' rounding: 0.79 to 0.87 over the same kernels and threads
    (0.788: AVX512-BF16 at one thread, as a Zen 4 EPYC measures).  It stays a descent
    direction of the fp32 loss, which is what a training step needs (and the loss curve
    of a 428-step run is unchanged, see the README)."""
    ds = PairDataset(list_photos([photos]), TINY, seed=0)
    items = [ds[i] for i in range(2)]
    batch = {k: torch.stack([it[k] for it in items]) for k in items[0]}
    torch.manual_seed(0)
    net = _Recorded(LBurstNet(NetConfig(frames=3)).train())
    params = list(net.parameters())
    keys = ("descriptors", "repeatability", "reliability")
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        results = {}
        for precision in ("fp32", "bf16"):
            losses = training_step(net, batch, patch=8, generator=torch.Generator().manual_seed(0), precision=precision)
            outputs = [net.outputs[k].float() for k in keys]
            step = torch.autograd.grad(losses["loss"], params, retain_graph=True)
            results[precision] = ({k: v.item() for k, v in losses.items()}, torch.cat([g.flatten() for g in step]))
            if precision == "fp32":
                upstream = torch.autograd.grad(losses["loss"], outputs)  # the loss's gradient at the fp32 outputs
            else:
                backward = torch.autograd.grad(outputs, params, upstream)  # ... through the bf16 network
    finally:
        torch.set_num_threads(before)
    (l32, g32), (l16, g16) = results["fp32"], results["bf16"]
    for key in ("cosim", "peaky", "ap"):
        assert l16[key] == pytest.approx(l32[key], abs=0.02), key
    assert torch.nn.functional.cosine_similarity(g32, torch.cat([g.flatten() for g in backward]), dim=0) > 0.95
    assert torch.dot(g32, g16) > 0  # a bf16 step lowers the fp32 loss
    assert not torch.equal(g32, g16)  # autocast took part
    with pytest.raises(ValueError, match="precision"):
        training_step(net, batch, patch=8, precision="int8")


def test_tensorboard_log_has_the_losses_of_every_step(photos, tmp_path):
    pytest.importorskip("tensorboard")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    cfg = TrainConfig(frames=3, batch_size=2, steps=2, patch=8, workers=0, pair=TINY, tensorboard=True)
    train([photos], tmp_path, cfg, progress=False)
    events = EventAccumulator(str(tmp_path / "tensorboard"))
    events.Reload()
    loss = [(e.step, e.value) for e in events.Scalars("train/loss")]
    logged = [(int(r["step"]), float(r["loss"])) for r in _log(tmp_path / "log.csv")]
    assert [s for s, _ in loss] == [1, 2]
    np.testing.assert_allclose([v for _, v in loss], [v for _, v in logged], atol=1e-5)


def test_two_process_data_parallel_run_logs_the_mean_of_each_ranks_share(photos, tmp_path):
    """torchrun with 2 CPU processes (Gloo): rank r trains on stream samples r, r + 2, ...;
    the logged step-1 loss is the mean of the two ranks' losses at the common start."""
    import subprocess
    import sys
    from pathlib import Path

    helper = Path(__file__).parents[1] / "helpers" / "ddp_train.py"
    cmd = [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        "--nproc_per_node",
        "2",
        str(helper),
        str(photos),
        str(tmp_path / "run"),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    log = _log(tmp_path / "run" / "log.csv")
    assert [r["step"] for r in log] == ["1", "2"]
    assert torch.load(tmp_path / "run" / "last.pt", weights_only=True)["step"] == 2
    ds = PairDataset(list_photos([photos]), TINY, seed=0)
    expected = []
    for rank in (0, 1):
        items = [ds[rank], ds[rank + 2]]
        batch = {k: torch.stack([it[k] for it in items]) for k in items[0]}
        torch.manual_seed(0)
        net = LBurstNet(NetConfig(frames=3)).to(memory_format=torch.channels_last).train()
        with torch.no_grad():
            expected.append(training_step(net, batch, 8, torch.Generator().manual_seed(rank))["loss"].item())
    assert float(log[0]["loss"]) == pytest.approx(np.mean(expected), abs=1e-4)
    assert abs(expected[0] - expected[1]) > 1e-3  # the ranks did see different data


def test_an_interrupted_run_keeps_its_finished_steps(photos, tmp_path, monkeypatch):
    """Ctrl-C during step 3: last.pt and log.csv hold steps 1-2, and --resume finishes the run."""
    import lburst.train.loop as loop

    calls = {"n": 0}
    real_step = loop.training_step

    def interrupted_at_third(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real_step(*args, **kwargs)

    cfg = TrainConfig(frames=3, batch_size=2, steps=4, patch=8, workers=0, pair=TINY)
    monkeypatch.setattr(loop, "training_step", interrupted_at_third)
    with pytest.raises(KeyboardInterrupt):
        train([photos], tmp_path, cfg, progress=False)
    assert torch.load(tmp_path / "last.pt", weights_only=True)["step"] == 2
    assert [r["step"] for r in _log(tmp_path / "log.csv")] == ["1", "2"]
    monkeypatch.setattr(loop, "training_step", real_step)
    train([photos], tmp_path, cfg, resume=True, progress=False)
    assert [r["step"] for r in _log(tmp_path / "log.csv")] == ["1", "2", "3", "4"]


def test_validation_photos_are_a_fixed_tenth_never_trained_on(tmp_path):
    from lburst.train.data import is_validation_photo

    names = [f"photo_{i:03d}" for i in range(200)]
    for name in names:
        (tmp_path / f"{name}.jpg").write_bytes(b"")
    train_set = {p.stem for p in list_photos([tmp_path])}
    val_set = {p.stem for p in list_photos([tmp_path], split="validation")}
    assert not train_set & val_set and train_set | val_set == set(names)
    assert 10 <= len(val_set) <= 32  # about a tenth
    assert all(is_validation_photo(f"other/folder/{n}.png") for n in val_set)  # a rule on the name only


def test_burst_preset_pairs_have_a_clean_copy_and_general_motion(photos):
    from lburst.train.loop import PRESETS

    cfg = replace(PRESETS["burst"]["pair"], crop=64, long_side=(160, 256), max_pair_shift=6)
    ds = PairDataset(list_photos([photos], split="all"), cfg, seed=0, clean=True)
    item = ds[0]
    noise = (item["burst_a"] - item["clean_a"]).std()
    assert item["clean_a"].shape == item["burst_a"].shape and noise > 5
    quiet = PairDataset(
        list_photos([photos], split="all"), replace(cfg, noise_std=(0.0, 0.0), lowlight_prob=0.0), seed=0, clean=True
    )[0]
    assert torch.equal(quiet["burst_a"], quiet["clean_a"])


def test_distillation_pulls_the_noisy_output_towards_the_clean_one(photos):
    from lburst.train.losses import distillation_loss

    cfg = replace(TINY, noise_variance=None, noise_std=(60.0, 60.0))
    ds = PairDataset(list_photos([photos], split="all"), cfg, seed=0, clean=True)
    batch = {k: torch.stack([ds[i][k] for i in range(2)]) for k in ds[0]}
    torch.manual_seed(0)
    net = LBurstNet(NetConfig(frames=3)).train()
    same = {
        "descriptors": torch.nn.functional.normalize(torch.randn(1, 8, 4, 4), dim=1),
        "repeatability": torch.rand(1, 1, 4, 4),
        "reliability": torch.rand(1, 1, 4, 4),
    }
    assert distillation_loss(same, same).item() == pytest.approx(0.0, abs=1e-6)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    values = []
    for _ in range(6):
        losses = training_step(
            net, batch, patch=8, generator=torch.Generator().manual_seed(0), distill_weight=10.0, teacher=net
        )
        opt.zero_grad()
        losses["loss"].backward()
        opt.step()
        values.append(losses["distill"].item())
    assert values[-1] < values[0]
    with pytest.raises(ValueError, match="teacher"):
        training_step(net, batch, patch=8, distill_weight=1.0)


def test_sigterm_stops_a_run_like_ctrl_c_keeping_its_finished_steps(photos, tmp_path, monkeypatch):
    """A run in the background ignores SIGINT; SIGTERM during step 3 keeps steps 1-2."""
    import os
    import signal

    import lburst.train.loop as loop

    calls = {"n": 0}
    real_step = loop.training_step

    def terminated_at_third(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return real_step(*args, **kwargs)

    cfg = TrainConfig(frames=3, batch_size=2, steps=4, patch=8, workers=0, pair=TINY)
    monkeypatch.setattr(loop, "training_step", terminated_at_third)
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt):
        train([photos], tmp_path, cfg, progress=False)
    # the signal arrives before step 3 runs: steps 1 and 2 are kept, and nothing of step 3
    assert torch.load(tmp_path / "last.pt", weights_only=True)["step"] == 2
    assert [r["step"] for r in _log(tmp_path / "log.csv")] == ["1", "2"]
    assert signal.getsignal(signal.SIGTERM) is before  # the handler is put back


def test_a_burst_network_replicated_from_a_single_image_one_equals_it_on_the_mean():
    from lburst.model.network import replicate_frames

    torch.manual_seed(0)
    single = LBurstNet(NetConfig(frames=1)).eval()
    wide = replicate_frames(single, 5).eval()
    x = torch.randn(2, 15, 48, 56)
    a, b = wide(x), single(x.view(2, 5, 3, 48, 56).mean(1))
    for key in a:
        torch.testing.assert_close(a[key], b[key], atol=1e-5, rtol=1e-4)
    with pytest.raises(ValueError, match="single-image"):
        replicate_frames(wide, 3)


def test_aligned_preset_frames_are_warped_back_onto_the_common_frame(photos):
    from lburst.train.loop import PRESETS

    base = replace(
        PRESETS["burst"]["pair"],
        crop=96,
        long_side=(200, 256),
        max_pair_shift=6,
        noise_std=(0.0, 0.0),
        lowlight_prob=0.0,
        burst_rotation_deg=0.0,
        burst_zoom=0.0,
        burst_flow_px=0.0,
    )
    photo_list = list_photos([photos], split="all")
    moving = PairDataset(photo_list, base, seed=1)[0]["burst_a"]
    aligned = PairDataset(photo_list, replace(base, align_error_px=0.0), seed=1)[0]["burst_a"]
    inner = (slice(None), slice(8, -8), slice(8, -8))

    def spread(burst):  # how far the frames are from the common one
        return float((burst[0][inner] - burst[2][inner]).abs().mean())

    assert torch.equal(moving[2], aligned[2])
    assert spread(aligned) < 0.3 * spread(moving)


def test_a_calibrated_sensors_noise_takes_its_share_of_training_bursts(monkeypatch):
    from lburst.noise import LowLightNoise, SensorNoise
    from lburst.train import pairs

    flat = np.full((5, 48, 48, 3), 100.0, np.float32)
    one = replace(PairConfig(), lowlight_prob=0.0, sensor_prob=1.0, sensors=("a7s2@1600",), lowlight_photons=(20, 20))

    def variance(noise):  # of the 8-bit frames a training burst gets: rounded and clipped
        return np.clip(np.round(noise(flat, np.random.default_rng(1))), 0, 255).var()

    sensor, lowlight = variance(SensorNoise.preset("a7s2", 1600, photons=20)), variance(LowLightNoise(20))
    got = pairs._noise(flat, np.random.default_rng(0), one).var()
    assert abs(got / sensor - 1) < 0.05 and got > 1.5 * lowlight

    mix = replace(PairConfig(), lowlight_prob=0.33, sensor_prob=0.3)
    drawn = []
    real = pairs.sensor_from_spec
    monkeypatch.setattr(pairs, "sensor_from_spec", lambda spec: drawn.append(spec) or real(spec))
    rng = np.random.default_rng(0)
    for _ in range(400):
        pairs._noise(flat[:1, :4, :4], rng, mix)
    assert abs(len(drawn) / 400 - 0.3) < 0.07
    names = {spec.split(",")[0] for spec in drawn}
    photons = [float(spec.split("photons=")[1]) for spec in drawn]
    assert names == set(pairs.SENSOR_MIX) and 3.0 <= min(photons) and max(photons) <= 60.0


def test_a_teacher_on_the_clean_burst_is_frozen_and_needs_a_teacher(photos, tmp_path):
    """``teacher_sees='clean'``: the frozen teacher reads the noise-free burst A (the loader
    must then deliver it), its weights never move, and the option is refused without a
    teacher or with an unknown input."""
    base = TrainConfig(frames=3, batch_size=2, steps=1, patch=8, workers=0, pair=TINY)
    train([photos], tmp_path / "start", base, progress=False)
    start = tmp_path / "start" / "final.pt"
    before = {k: v.clone() for k, v in load_checkpoint(start)[0].state_dict().items()}
    cfg = replace(base, steps=2, init=str(start), teacher=str(start), teacher_sees="clean", distill_weight=1.0)
    train([photos], tmp_path / "run", cfg, progress=False)
    rows = _log(tmp_path / "run" / "log.csv")
    assert [r["step"] for r in rows] == ["1", "2"]
    assert all(float(r["distill"]) > 0 for r in rows)  # noisy student against clean target
    for k, v in load_checkpoint(start)[0].state_dict().items():
        torch.testing.assert_close(v, before[k], rtol=0, atol=0, msg=k)
    moved = load_checkpoint(tmp_path / "run" / "final.pt")[0].state_dict()
    assert any(not torch.equal(moved[k], before[k]) for k in before if before[k].is_floating_point())
    with pytest.raises(ValueError, match="needs a --teacher"):
        train([photos], tmp_path / "x", replace(base, teacher_sees="clean", distill_weight=1.0), progress=False)
    with pytest.raises(ValueError, match="teacher_sees 'blurry'"):
        train([photos], tmp_path / "y", replace(cfg, teacher_sees="blurry"), progress=False)


def test_weight_average_follows_the_steps_and_survives_a_resume(photos, tmp_path):
    decay = 0.5
    cfg = TrainConfig(frames=3, batch_size=2, steps=4, patch=8, workers=0, pair=TINY, snapshot_every=1, ema_decay=decay)
    train([photos], tmp_path / "full", cfg, progress=False)
    train([photos], tmp_path / "split", replace(cfg, steps=2), progress=False)
    train([photos], tmp_path / "split", cfg, resume=True, progress=False)
    snaps = tmp_path / "full" / "snapshots"
    raw = [load_checkpoint(snaps / f"step_{s:06d}.pt")[0].state_dict() for s in range(1, 5)]
    expected = dict(raw[0])  # the first update copies the weights
    for w in raw[1:]:
        expected = {k: decay * v + (1 - decay) * w[k] if v.is_floating_point() else w[k] for k, v in expected.items()}
    averaged, _ = load_checkpoint(snaps / "step_000004.ema.pt")
    final, _ = load_checkpoint(tmp_path / "full" / "final.pt")
    resumed, _ = load_checkpoint(tmp_path / "split" / "final.pt")
    for k, v in averaged.state_dict().items():
        if v.is_floating_point():
            torch.testing.assert_close(v, expected[k], atol=1e-6, rtol=1e-6, msg=k)
        torch.testing.assert_close(final.state_dict()[k], v, atol=0, rtol=0, msg=k)
        torch.testing.assert_close(resumed.state_dict()[k], v, atol=1e-4, rtol=1e-4, msg=k)
    assert any(not torch.equal(v, raw[3][k]) for k, v in averaged.state_dict().items())  # not the last step's
    with pytest.raises(ValueError, match="ema_decay 1.0"):
        train([photos], tmp_path / "bad", replace(cfg, ema_decay=1.0), progress=False)
