"""Homography benchmark: sequence reading, the burst protocol, an end-to-end run (metrics: test_bench_metrics.py)."""

import json

import cv2
import numpy as np
import pytest
import skimage.data

from lburst.bench.homography import BenchMethod, NoiseLevel, noise_levels, protocol_burst, run_homography_benchmark
from lburst.bench.metrics import project
from lburst.bench.sequences import read_sequence, resize_matrix
from lburst.noise import GaussianNoise


def _write_sequence(folder, layout="oxford", size=(160, 200)):
    folder.mkdir(parents=True)
    base = cv2.resize(skimage.data.astronaut(), (size[1] + 60, size[0] + 60))
    for k in range(1, 7):
        t = np.array([[1, 0, -2.0 * (k - 1)], [0, 1, -1.0 * (k - 1)], [0, 0, 1]])  # content moves by (+2, +1) per image
        img = cv2.warpPerspective(base, np.linalg.inv(t), (size[1], size[0]))
        name = f"img{k}.png" if layout == "oxford" else f"{k}.ppm"
        cv2.imwrite(str(folder / name), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
        if k > 1:
            h = np.array([[1, 0, 2.0 * (k - 1)], [0, 1, 1.0 * (k - 1)], [0, 0, 1]])
            np.savetxt(folder / (f"H1to{k}p" if layout == "oxford" else f"H_1_{k}"), h)


@pytest.mark.parametrize("layout", ["oxford", "hpatches"])
def test_both_layouts_and_resizing_keep_geometry(tmp_path, layout):
    _write_sequence(tmp_path / "v_seq", layout)
    seq = read_sequence(tmp_path / "v_seq")
    assert len(seq.images) == 6 and len(seq.homographies) == 5 and seq.kind == "viewpoint"
    small = read_sequence(tmp_path / "v_seq", max_side=100)
    assert max(small.images[0].shape[:2]) == 100
    # a point maps consistently: resize then H' equals H then resize
    p = np.array([[37.0, 81.0]])
    s = resize_matrix(100 / 200, 80 / 160)
    np.testing.assert_allclose(
        project(small.homographies[2], project(s, p)), project(s, project(seq.homographies[2], p))
    )


def test_bad_sequence_files_are_named(tmp_path):
    _write_sequence(tmp_path / "s")
    (tmp_path / "s" / "H1to4p").write_text("1 2\n3 4\n")
    with pytest.raises(ValueError, match="H1to4p: expected a 3x3 matrix"):
        read_sequence(tmp_path / "s")
    (tmp_path / "s" / "H1to4p").unlink()
    with pytest.raises(FileNotFoundError, match="H1to4p: homography file missing"):
        read_sequence(tmp_path / "s")


def test_protocol_burst_is_deterministic_and_keeps_the_middle_frame():
    image = skimage.data.astronaut()[:128, :160]
    level = NoiseLevel("sigma50", GaussianNoise(50.0))
    a, motion_a = protocol_burst(image, "graf", 2, level)
    b, motion_b = protocol_burst(image, "graf", 2, level)
    np.testing.assert_array_equal(a, b)
    assert motion_a == motion_b and motion_a.is_translation and max(abs(m) for m in motion_a.shift) <= 3
    clean, _ = protocol_burst(image, "graf", 2, NoiseLevel("sigma0", None))
    np.testing.assert_array_equal(clean[2], image)
    other, motion_other = protocol_burst(image, "graf", 2, NoiseLevel("sigma100", GaussianNoise(100.0)))
    assert (other != a).any() and motion_other != motion_a  # another noise level draws another seed
    assert [lv.label for lv in noise_levels([25, 0], ["lowlight:night"])] == ["sigma25", "sigma0", "lowlight:night"]


def test_rotating_burst_levels_are_labelled_and_the_oracle_merge_undoes_their_motion():
    from lburst.bench.homography import MotionRange, oracle_merge

    image = skimage.data.astronaut()[100:228, 100:260]
    (level,) = noise_levels([0], [], MotionRange(1.0, 0.01, 1.0))
    assert level.label == "sigma0+rot1-zoom0.01-flow1"
    burst, motion = protocol_burst(image, "graf", 2, level)
    assert not motion.is_translation and abs(motion.rotation_deg) <= 1 and abs(motion.zoom) <= 0.01
    np.testing.assert_array_equal(burst[2], image)
    assert np.abs(burst[0].astype(float) - image).mean() > 5  # the end frames really moved
    merged = oracle_merge(burst, motion)
    inner = (slice(12, -12), slice(12, -12))
    assert np.abs(merged[inner] - image[inner]).mean() < 4.0  # bilinear blur only


def test_end_to_end_with_sift_on_a_clean_known_sequence(tmp_path):
    _write_sequence(tmp_path / "data" / "seq")
    results = run_homography_benchmark(tmp_path / "data", ["sift"], [0], tmp_path / "out", progress=False)
    summary = results["methods"]["sift"]["sigma0"]["summary"]["all"]
    assert summary["mma"][2] > 0.8 and summary["rep3"] > 0.5
    assert (tmp_path / "out" / "results.md").is_file() and (tmp_path / "out" / "mma.png").is_file()
    # a re-run reads the cache: same numbers
    again = run_homography_benchmark(tmp_path / "data", ["sift"], [0], tmp_path / "out", progress=False)
    assert again["methods"]["sift"]["sigma0"]["summary"]["all"] == summary


def test_recomputed_results_are_identical(tmp_path):
    _write_sequence(tmp_path / "data" / "seq", size=(96, 128))
    first = run_homography_benchmark(tmp_path / "data", ["sift"], [25], tmp_path / "a", progress=False)
    second = run_homography_benchmark(tmp_path / "data", ["sift"], [25], tmp_path / "b", progress=False)
    assert first["methods"]["sift"]["sigma25"]["pairs"] == second["methods"]["sift"]["sigma25"]["pairs"]


def test_weights_retrained_at_the_same_path_are_not_served_cached_results(tmp_path):
    import shutil

    import torch

    from lburst.weights import weights_path

    _write_sequence(tmp_path / "data" / "seq", size=(96, 128))
    ckpt = tmp_path / "model.pt"

    def run():
        return run_homography_benchmark(tmp_path / "data", [f"r2d2:{ckpt}"], [0], tmp_path / "out", progress=False)[
            "methods"
        ][f"r2d2:{ckpt}"]["sigma0"]["pairs"]

    shutil.copy(weights_path("lburst-b1"), ckpt)
    first = run()
    assert run() == first  # same weights: read from the cache
    state = torch.load(ckpt, weights_only=True)
    state["state_dict"] = {k: v * 0.5 if v.is_floating_point() else v for k, v in state["state_dict"].items()}
    torch.save(state, ckpt)  # "retrained" in place
    assert run() != first
    assert len(list((tmp_path / "out" / "cache").iterdir())) == 2


def test_a_sequence_image_replaced_under_the_same_name_is_run_again(tmp_path):
    _write_sequence(tmp_path / "data" / "seq", size=(96, 128))

    def run(out):
        return run_homography_benchmark(tmp_path / "data", ["sift"], [25], tmp_path / out, progress=False)["methods"][
            "sift"
        ]["sigma25"]["pairs"]["seq"]

    first = run("out")
    image = tmp_path / "data" / "seq" / "img3.png"
    cv2.imwrite(str(image), cv2.flip(cv2.imread(str(image)), -1))  # another picture, the same name
    again, fresh = run("out"), run("fresh")
    assert again == fresh
    assert again[1] != first[1] and again[0] == first[0]  # pair (1, 3) changed, pair (1, 2) did not


def test_every_k_th_sequence_in_name_order(tmp_path):
    for name in ("a", "b", "c"):
        _write_sequence(tmp_path / "data" / name, size=(96, 128))
    results = run_homography_benchmark(tmp_path / "data", ["sift"], [0], tmp_path / "out", progress=False, every=2)
    assert results["protocol"]["every"] == 2
    assert sorted(results["methods"]["sift"]["sigma0"]["pairs"]) == ["a", "c"]
    with pytest.raises(ValueError, match="every must be an integer >= 1"):
        run_homography_benchmark(tmp_path / "data", ["sift"], [0], tmp_path / "out", progress=False, every=0)


@pytest.mark.parametrize("deg", [90, 180, 37])
def test_turned_views_keep_their_geometry_and_the_table_is_written(tmp_path, deg):
    """SIFT is rotation-invariant: with images 2-6 turned, the composed homographies must still
    put its matches in place, and a run with no pair rotated <= 25 degrees still writes its table."""
    _write_sequence(tmp_path / "data" / "seq")
    results = run_homography_benchmark(tmp_path / "data", ["sift"], [0], tmp_path / "out", progress=False, rotation=deg)
    summary = results["methods"]["sift"]["sigma0"]["summary"]
    assert summary["all"]["mma"][2] > 0.8
    assert summary["rotation_le_25"]["pairs"] == 0
    assert results["protocol"]["rotation_deg"] == deg
    assert f"turned by {deg} degrees" in (tmp_path / "out" / "results.md").read_text()


def test_input_modes_parse_from_the_published_spellings_and_back():
    """``gold:CKPT`` and ``oracle-merge+X`` are input modes, not name prefixes: parsed once, written
    back as published (tables, docs), and ``--input`` gives a plain spec a mode."""
    from lburst.bench.homography import BenchMethod, InputMode

    gold = BenchMethod.parse("gold:w/R2D2.pt")
    assert gold == BenchMethod("r2d2:w/R2D2.pt", InputMode.GOLD) and gold.name == "gold:w/R2D2.pt"
    oracle = BenchMethod.parse("oracle-merge+r2d2:w/R2D2.pt")
    assert oracle == BenchMethod("r2d2:w/R2D2.pt", InputMode.ORACLE_MERGE)
    assert oracle.name == "oracle-merge+r2d2:w/R2D2.pt"
    assert BenchMethod.parse("gold+sift") == BenchMethod("sift", InputMode.GOLD) == BenchMethod.parse("sift", "gold")
    assert BenchMethod.parse("merge+sift") == BenchMethod("merge+sift", InputMode.BURST)  # a method, not a mode
    assert BenchMethod.parse("oracle-merge+sift", "gold").mode is InputMode.ORACLE_MERGE  # its own mode wins
    for method in (gold, oracle, BenchMethod("sift", InputMode.GOLD), BenchMethod("lburst")):
        assert BenchMethod.parse(method.name) == method
    with pytest.raises(ValueError, match="input mode 'clean' is not one of burst, gold, oracle-merge"):
        BenchMethod.parse("sift", "clean")


def test_each_input_mode_gives_the_method_what_it_names(tmp_path):
    """gold: the clean image; oracle-merge: the burst's frames aligned with the true motion and
    averaged (less noise than any one frame); burst: the burst."""
    from lburst.bench.homography import InputMode, MethodRunner
    from lburst.burst.motion import BurstMotion

    image = cv2.resize(skimage.data.astronaut(), (96, 64))
    shift = (2.0, 1.0)
    noise = np.random.default_rng(0).normal(0, 20, (5, *image.shape))
    clean = np.stack([np.roll(image, (k, 2 * k), axis=(0, 1)) for k in range(-2, 3)])
    burst = np.clip(np.round(clean + noise), 0, 255).astype(np.uint8)
    seen = {}
    for mode in InputMode:
        runner = MethodRunner(BenchMethod("sift", mode), top_k=100)
        runner.extractor = lambda b, mode=mode: seen.setdefault(mode, b)
        runner(image, burst, BurstMotion(shift))
    assert seen[InputMode.GOLD].shape == (1, 64, 96, 3) and np.array_equal(seen[InputMode.GOLD][0], image)
    assert seen[InputMode.BURST] is burst
    merged = seen[InputMode.ORACLE_MERGE]

    def error(frame):  # RMS against the clean image, inside the borders the motion uncovers
        return np.sqrt(np.mean((frame[8:-8, 8:-8].astype(float) - image[8:-8, 8:-8]) ** 2))

    assert merged.shape == (1, 64, 96, 3) and error(merged[0]) < 0.6 * error(burst[2])  # 5 frames averaged


def test_the_command_line_input_option_runs_every_plain_spec_in_that_mode(tmp_path, capsys):
    from lburst.cli import main

    _write_sequence(tmp_path / "data" / "seq", size=(96, 128))
    args = ["bench", "homography", str(tmp_path / "data"), "--sigma", "25", "--out", str(tmp_path / "out")]
    assert main([*args, "--methods", "sift", "oracle-merge+sift", "--input", "gold"]) == 0
    table = capsys.readouterr().out
    assert "| gold+sift |" in table and "| oracle-merge+sift |" in table
    summary = json.loads((tmp_path / "out" / "results.json").read_text())["methods"]
    assert sorted(summary) == ["gold+sift", "oracle-merge+sift"]


def test_recoloured_views_keep_the_first_image_and_the_geometry_and_repeat(tmp_path):
    """``color_jitter`` changes images 2-6 only, the same way in every run, and leaves the
    homographies alone: SIFT (on grey levels) still matches; a bad jitter is one clear error."""
    from lburst.bench.sequences import read_sequence, recolor_sequence

    _write_sequence(tmp_path / "data" / "seq")
    seq = read_sequence(tmp_path / "data" / "seq")
    jitter = (0.2, 0.2, 0.2, 0.1)
    once, twice = recolor_sequence(seq, jitter), recolor_sequence(seq, jitter)
    assert np.array_equal(once.images[0], seq.images[0])
    assert all(np.array_equal(a, b) for a, b in zip(once.images, twice.images))
    assert all(np.abs(a.astype(int) - b).mean() > 1 for a, b in zip(once.images[1:], seq.images[1:]))
    assert all(np.array_equal(a, b) for a, b in zip(once.homographies, seq.homographies))
    results = run_homography_benchmark(
        tmp_path / "data", ["sift"], [0], tmp_path / "out", progress=False, color_jitter=jitter
    )
    assert results["methods"]["sift"]["sigma0"]["summary"]["all"]["mma"][2] > 0.8
    assert results["protocol"]["color_jitter"] == list(jitter)
    assert "recoloured" in (tmp_path / "out" / "results.md").read_text()
    with pytest.raises(ValueError, match="must be four numbers in"):
        run_homography_benchmark(
            tmp_path / "data", ["sift"], [0], tmp_path / "out", progress=False, color_jitter=(0.2, 0.2, 2.0, 0.1)
        )
