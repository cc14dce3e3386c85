"""``lburst train`` refuses what would silently do the wrong thing: resuming a run that is
not there, a run of no steps, an unreadable ``last.pt`` (named), and options a resumed run ignores."""

import argparse
import json
import warnings
from dataclasses import replace

import cv2
import pytest
import skimage.data
import torch

from lburst.cli.train import config_from_args, configure_parser, given_options
from lburst.model.network import CheckpointError, training_memory_format
from lburst.train.loop import TrainConfig, check_resume_options, train
from lburst.train.pairs import PairConfig

TINY = PairConfig(frames=3, crop=64, long_side=(160, 256), max_burst_motion=6, max_pair_shift=6)
CFG = TrainConfig(frames=3, batch_size=1, steps=1, patch=8, workers=0, pair=TINY)


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    folder = tmp_path_factory.mktemp("photos")
    cv2.imwrite(str(folder / "astronaut.png"), cv2.cvtColor(skimage.data.astronaut(), cv2.COLOR_RGB2BGR))
    return folder


def test_resume_of_a_missing_run_is_an_error_not_a_new_run(photos, tmp_path):
    with pytest.raises(CheckpointError, match="last.pt: no run to resume"):
        train([photos], tmp_path / "nowhere", CFG, resume=True, progress=False)
    assert not (tmp_path / "nowhere").exists()


def test_zero_steps_write_no_untrained_final_checkpoint(photos, tmp_path):
    with pytest.raises(ValueError, match="at least 1 step"):
        train([photos], tmp_path / "run", TrainConfig(**{**CFG.__dict__, "steps": 0}), progress=False)
    assert not (tmp_path / "run" / "final.pt").exists()


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04 truncated zip"])
def test_an_unreadable_last_pt_is_named(photos, tmp_path, content):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "last.pt").write_bytes(content)
    with pytest.raises(CheckpointError, match=r"run/last.pt: not a readable training state"):
        train([photos], tmp_path / "run", CFG, resume=True, progress=False)


def test_options_a_resumed_run_would_ignore_are_refused(tmp_path):
    (tmp_path / "config.json").write_text(json.dumps({"frames": 5, "batch_size": 4, "steps": 100}))
    parser = argparse.ArgumentParser()
    configure_parser(parser)
    args = parser.parse_args(["--out", str(tmp_path), "--resume", "--frames", "1", "--steps", "200"])
    with pytest.raises(ValueError, match=r"leave out --frames 1 \(the run has 5\)"):
        check_resume_options(tmp_path, given_options(args))
    same = parser.parse_args(["--out", str(tmp_path), "--resume", "--frames", "5", "--steps", "200"])
    check_resume_options(tmp_path, given_options(same))  # more steps, same frames: fine


def test_resume_without_steps_runs_to_the_runs_own_end_not_a_presets(tmp_path):
    (tmp_path / "config.json").write_text(json.dumps({"frames": 5, "steps": 1200, "epochs": None}))
    parser = argparse.ArgumentParser()
    configure_parser(parser)
    assert config_from_args(parser.parse_args(["--out", str(tmp_path), "--resume"])).steps == 1200
    assert config_from_args(parser.parse_args(["--out", str(tmp_path), "--resume", "--steps", "1500"])).steps == 1500
    assert (
        config_from_args(parser.parse_args(["--out", str(tmp_path / "new")])).steps == 20000
    )  # a new run: the preset's


def test_a_resumed_run_takes_the_precision_of_the_machine_it_continues_on(photos, tmp_path):
    with warnings.catch_warnings():  # bf16 on a CPU without native bf16 warns; it still runs
        warnings.simplefilter("ignore", RuntimeWarning)
        train([photos], tmp_path, CFG, progress=False, precision="bf16")
    assert json.loads((tmp_path / "config.json").read_text())["precision"] == "bf16"
    parser = argparse.ArgumentParser()
    configure_parser(parser)
    args = parser.parse_args(["--out", str(tmp_path), "--resume", "--precision", "fp32", "--steps", "2"])
    check_resume_options(tmp_path, given_options(args))  # not refused: precision is the machine's
    train([photos], tmp_path, replace(CFG, steps=2), resume=True, progress=False, precision="fp32")
    assert json.loads((tmp_path / "config.json").read_text())["precision"] == "fp32"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        train([photos], tmp_path, replace(CFG, steps=3), resume=True, progress=False, precision="bf16")
        assert json.loads((tmp_path / "config.json").read_text())["precision"] == "bf16"
        train([photos], tmp_path, replace(CFG, steps=4), resume=True, progress=False)  # not given: the run's own
    assert json.loads((tmp_path / "config.json").read_text())["precision"] == "bf16"  # not the default, fp32


@pytest.mark.parametrize(
    "name, expected", [("channels_last", torch.channels_last), ("contiguous", torch.contiguous_format)]
)
def test_training_memory_format_by_name(name, expected):
    assert training_memory_format("cpu", name) is expected


def test_training_memory_format_auto_follows_the_device_and_cpu(monkeypatch):
    import lburst.model.network as model

    assert training_memory_format("cuda", "auto") is torch.channels_last
    monkeypatch.setattr(model, "cpu_flags", lambda: {"avx2", "fma"})
    assert training_memory_format("cpu", "auto") is torch.contiguous_format
    monkeypatch.setattr(model, "cpu_flags", lambda: {"avx2", "avx512f"})
    assert training_memory_format("cpu", "auto") is torch.channels_last
    with pytest.raises(ValueError, match="memory format must be"):
        training_memory_format("cpu", "nchw")


def test_loss_weights_given_on_the_command_line_reach_the_config(tmp_path):
    parser = argparse.ArgumentParser()
    configure_parser(parser)
    args = [
        "--out",
        str(tmp_path),
        "--preset",
        "aligned",
        "--ap-weight",
        "1",
        "--rel-base",
        "0.3",
        "--spread-weight",
        "2",
    ]
    cfg = config_from_args(parser.parse_args(args))
    assert (cfg.ap_weight, cfg.rel_base, cfg.spread_weight) == (1.0, 0.3, 2.0)
    assert config_from_args(parser.parse_args(["--out", str(tmp_path), "--preset", "aligned"])).ap_weight == 0.25


def test_max_rotation_sets_the_pairs_and_a_resumed_run_keeps_its_own(tmp_path):
    from lburst.cli.train import _check_resumed_pairs

    parser = argparse.ArgumentParser()
    configure_parser(parser)
    cfg = config_from_args(
        parser.parse_args(["--out", str(tmp_path / "new"), "--preset", "lite", "--max-rotation", "180"])
    )
    assert cfg.pair.max_rotation_deg == 180 and cfg.pair.crop == TrainConfig().pair.crop
    assert config_from_args(parser.parse_args(["--out", str(tmp_path / "new")])).pair.max_rotation_deg == 15
    with pytest.raises(SystemExit):
        parser.parse_args(["--out", str(tmp_path), "--max-rotation", "nan"])
    (tmp_path / "config.json").write_text(json.dumps({"pair": {"max_rotation_deg": 15.0}}))
    with pytest.raises(ValueError, match=r"leave out --max-rotation 180 \(the run has 15\)"):
        _check_resumed_pairs(tmp_path, {"max_rotation_deg": 180.0})
    _check_resumed_pairs(tmp_path, {"max_rotation_deg": 15.0})
    _check_resumed_pairs(tmp_path, {"max_rotation_deg": None})


def test_sensor_options_set_the_pairs_are_checked_and_a_resumed_run_keeps_its_own(tmp_path):
    from lburst.cli.train import _check_resumed_pairs
    from lburst.errors import LBurstValueError

    parser = argparse.ArgumentParser()
    configure_parser(parser)
    new = ["--out", str(tmp_path / "new"), "--preset", "aligned"]
    cfg = config_from_args(parser.parse_args([*new, "--sensor-prob", "0.3", "--sensors", "imx686@6400"]))
    assert (cfg.pair.sensor_prob, cfg.pair.sensors, cfg.pair.lowlight_prob) == (0.3, ("imx686@6400",), 0.33)
    with pytest.raises(LBurstValueError, match=r"--noise-std/--sensor-prob/--sensors: .*no calibration at ISO 100"):
        config_from_args(parser.parse_args([*new, "--sensor-prob", "0.3", "--sensors", "imx686@100"]))
    with pytest.raises(LBurstValueError, match=r"sensor_prob 0.9 must lie in \[0, 1 - lowlight_prob\] = \[0, 0.67\]"):
        config_from_args(parser.parse_args([*new, "--sensor-prob", "0.9"]))
    (tmp_path / "config.json").write_text(json.dumps({"pair": {"max_rotation_deg": 15.0}}))
    with pytest.raises(ValueError, match=r"leave out --sensor-prob 0.3 \(the run has 0\)"):
        _check_resumed_pairs(tmp_path, {"sensor_prob": 0.3})
    with pytest.raises(ValueError, match=r"leave out --sensors a7s2@1600 \(the run has imx686@6400 a7s2@1600"):
        _check_resumed_pairs(tmp_path, {"sensors": ("a7s2@1600",)})


def test_the_noise_range_is_set_checked_and_kept_by_a_resumed_run(tmp_path):
    from lburst.cli.train import _check_resumed_pairs
    from lburst.errors import LBurstValueError

    parser = argparse.ArgumentParser()
    configure_parser(parser)
    new = ["--out", str(tmp_path / "new"), "--preset", "aligned"]
    assert config_from_args(parser.parse_args(new)).pair.noise_std == (25.0, 120.0)  # the preset's
    assert config_from_args(parser.parse_args([*new, "--noise-std", "50", "140"])).pair.noise_std == (50.0, 140.0)
    with pytest.raises(LBurstValueError, match=r"noise_std \(140, 50\) must be a range LOW <= HIGH"):
        config_from_args(parser.parse_args([*new, "--noise-std", "140", "50"]))
    (tmp_path / "config.json").write_text(json.dumps({"pair": {"noise_std": [25.0, 120.0]}}))
    with pytest.raises(ValueError, match=r"leave out --noise-std 50 140 \(the run has 25 120\)"):
        _check_resumed_pairs(tmp_path, {"noise_std": (50.0, 140.0)})
    _check_resumed_pairs(tmp_path, {"noise_std": (25.0, 120.0)})


def test_the_viewpoint_range_is_set_checked_reaches_the_homography_and_is_kept_by_a_resumed_run(tmp_path):
    import numpy as np

    from lburst.cli.train import _check_resumed_pairs
    from lburst.errors import LBurstValueError
    from lburst.train.pairs import random_homography

    parser = argparse.ArgumentParser()
    configure_parser(parser)
    new = ["--out", str(tmp_path / "new"), "--preset", "aligned"]
    preset = config_from_args(parser.parse_args(new)).pair
    assert (preset.scale_range, preset.max_tilt) == ((0.8, 1.25), 0.15)
    cfg = config_from_args(
        parser.parse_args([*new, "--scale-range", "2", "2", "--max-tilt", "0", "--max-rotation", "0"])
    )
    assert (cfg.pair.scale_range, cfg.pair.max_tilt) == ((2.0, 2.0), 0.0)
    g = random_homography(np.random.default_rng(0), replace(cfg.pair, max_pair_shift=0.0))
    c = (cfg.pair.crop - 1) / 2
    np.testing.assert_allclose(g, [[2, 0, -c], [0, 2, -c], [0, 0, 1]], atol=1e-9)  # 2x about the crop's centre
    with pytest.raises(LBurstValueError, match=r"scale_range \(2, 0.5\) must be a range 0 < LOW <= HIGH"):
        config_from_args(parser.parse_args([*new, "--scale-range", "2", "0.5"]))
    with pytest.raises(SystemExit):
        parser.parse_args([*new, "--max-tilt", "1.5"])
    (tmp_path / "config.json").write_text(json.dumps({"pair": {"scale_range": [0.8, 1.25]}}))
    with pytest.raises(ValueError, match=r"leave out --scale-range 0.5 2 \(the run has 0.8 1.25\)"):
        _check_resumed_pairs(tmp_path, {"scale_range": (0.5, 2.0)})
    with pytest.raises(ValueError, match=r"leave out --max-tilt 0.3 \(the run has 0.15\)"):
        _check_resumed_pairs(tmp_path, {"max_tilt": 0.3})
    _check_resumed_pairs(tmp_path, {"scale_range": (0.8, 1.25), "max_tilt": None})


def test_color_jitter_changes_the_second_burst_as_set_and_is_kept_by_a_resumed_run(tmp_path):
    import numpy as np

    from lburst.cli.train import _check_resumed_pairs
    from lburst.photometric import color_jitter

    rng = np.random.default_rng(0)
    burst = rng.uniform(40, 180, (3, 16, 16, 3))  # no clipping at 1.3x.astype(np.float32)
    assert color_jitter(burst, rng, (0.0, 0.0, 0.0, 0.0)) is burst
    luma = np.array([0.299, 0.587, 0.114], np.float32)
    gray = np.repeat((burst @ luma)[..., None], 3, -1)
    # saturation alone keeps the luma; a grey burst has no hue or saturation to change
    sat = color_jitter(burst, np.random.default_rng(1), (0.0, 0.0, 0.5, 0.0))
    np.testing.assert_allclose(sat @ luma, burst @ luma, atol=1e-3)
    assert np.abs(sat - burst).max() > 1
    np.testing.assert_allclose(color_jitter(gray, np.random.default_rng(2), (0.0, 0.0, 0.5, 0.5)), gray, atol=1e-3)
    # brightness scales every pixel by one factor, the same in every frame
    bright = color_jitter(burst, np.random.default_rng(3), (0.3, 0.0, 0.0, 0.0))
    factor = bright / burst
    assert np.ptp(factor) < 1e-4 and 0.7 <= factor.mean() <= 1.3 and abs(factor.mean() - 1) > 1e-3

    parser = argparse.ArgumentParser()
    configure_parser(parser)
    new = ["--out", str(tmp_path / "new"), "--preset", "aligned"]
    assert config_from_args(parser.parse_args(new)).pair.color_jitter == (0.0, 0.0, 0.0, 0.0)
    cfg = config_from_args(parser.parse_args([*new, "--color-jitter", "0.2", "0.2", "0.2", "0.1"]))
    assert cfg.pair.color_jitter == (0.2, 0.2, 0.2, 0.1)
    with pytest.raises(SystemExit):
        parser.parse_args([*new, "--color-jitter", "0.2", "0.2", "2", "0.1"])
    (tmp_path / "config.json").write_text(json.dumps({"pair": {}}))
    with pytest.raises(ValueError, match=r"leave out --color-jitter 0.2 0.2 0.2 0.1 \(the run has 0 0 0 0\)"):
        _check_resumed_pairs(tmp_path, {"color_jitter": (0.2, 0.2, 0.2, 0.1)})


def test_the_in_burst_flow_is_set_checked_and_kept_by_a_resumed_run(tmp_path):
    from lburst.cli.train import _check_resumed_pairs

    parser = argparse.ArgumentParser()
    configure_parser(parser)
    new = ["--out", str(tmp_path / "new"), "--preset", "aligned"]
    assert config_from_args(parser.parse_args(new)).pair.burst_flow_px == 1.0
    assert config_from_args(parser.parse_args([*new, "--burst-flow", "3"])).pair.burst_flow_px == 3.0
    with pytest.raises(SystemExit):
        parser.parse_args([*new, "--burst-flow", "-1"])
    (tmp_path / "config.json").write_text(json.dumps({"pair": {"burst_flow_px": 1.0}}))
    with pytest.raises(ValueError, match=r"leave out --burst-flow 3 \(the run has 1\)"):
        _check_resumed_pairs(tmp_path, {"burst_flow_px": 3.0})
