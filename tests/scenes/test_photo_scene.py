"""``lburst simulate scene``: bursts from photos, seeded per photo, with a clean-SIFT reference."""

import shutil

import cv2
import numpy as np
import pytest

from lburst.scenes.photo_scene import REFERENCE_SOURCE, simulate_scene
from lburst.sfm.poses import trajectory_errors
from lburst.sfm.reference import Reference
from lburst.sfm.scene import reference_cameras


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    """Six clean photos (the common frames of a small daylight flight) and the flight's exact reference."""
    from lburst.scenes.night_flight import NightFlightConfig, make_night_flight

    root = tmp_path_factory.mktemp("photo_scene")
    cfg = NightFlightConfig.daylight(n_bursts=6, frames_per_burst=1, width=320, height=240, noise="none")
    make_night_flight(root / "flight", cfg, progress=False)
    (root / "photos").mkdir()
    for folder in sorted(p for p in (root / "flight").iterdir() if p.is_dir()):
        shutil.copy(folder / "frame_000.png", root / "photos" / f"{folder.name}.png")
    return root


def test_scene_bursts_and_reference(photos):
    out = photos / "scene"
    ref = simulate_scene(photos / "photos", out, frames=3, motion_px=1.5, noise="gaussian:10", seed=0, progress=False)
    names = sorted(p.stem for p in (photos / "photos").iterdir())
    for name in names:
        frames = sorted((out / name).iterdir())
        assert [f.name for f in frames] == ["frame_000.png", "frame_001.png", "frame_002.png"]
        clean = cv2.imread(str(photos / "photos" / f"{name}.png")).astype(np.float32)
        middle = cv2.imread(str(frames[1])).astype(np.float32)
        # the middle frame keeps the photo's pixel grid: it differs from the photo by the noise only
        assert np.abs(middle - clean).mean() < 12
        assert np.abs(middle - clean).mean() < np.abs(middle - np.roll(clean, 1, axis=1)).mean()
    # the reference: every photo registered by SIFT, per-image cameras, and the exact flight up to a similarity
    assert ref is not None and ref.source == REFERENCE_SOURCE
    saved = Reference.load(out / "reference.json")
    assert sorted(saved.poses) == names and saved.length > 0
    assert saved.camera["model"] == "PINHOLE"
    assert set(reference_cameras(out / "reference.json")) == set(names)
    exact = Reference.load(photos / "flight" / "reference.json")
    err = trajectory_errors([saved.poses[n] for n in names], [exact.poses[n] for n in names])
    assert 100 * err["ate_rmse"] / exact.length < 1.0


def test_rerun_resumes_and_seeds_are_per_photo(photos):
    out = photos / "scene2"
    simulate_scene(photos / "photos", out, frames=3, noise="gaussian:10", seed=3, reference=False, progress=False)
    first = {p: p.stat().st_mtime_ns for p in out.rglob("*.png")}
    simulate_scene(photos / "photos", out, frames=3, noise="gaussian:10", seed=3, reference=False, progress=False)
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*.png")} == first  # nothing rewritten
    # one photo alone gives the same burst as within the whole set
    alone = photos / "alone"
    alone.mkdir()
    shutil.copy(photos / "photos" / "0003.png", alone / "0003.png")
    simulate_scene(alone, photos / "scene3", frames=3, noise="gaussian:10", seed=3, reference=False, progress=False)
    for k in range(3):
        a = cv2.imread(str(out / "0003" / f"frame_{k:03d}.png"))
        b = cv2.imread(str(photos / "scene3" / "0003" / f"frame_{k:03d}.png"))
        np.testing.assert_array_equal(a, b)


def test_no_photos(tmp_path):
    from lburst.sfm.scene import SceneError

    with pytest.raises(SceneError, match="no bursts"):
        simulate_scene(tmp_path, tmp_path / "out", progress=False)


def test_reference_options_are_kept_and_a_change_remakes_the_reference(photos):
    from lburst.scenes.photo_scene import REFERENCE_DIR, non_default_options, reference_options_used

    out = photos / "scene_single"
    ref = simulate_scene(
        photos / "photos",
        out,
        frames=3,
        noise="gaussian:10",
        progress=False,
        reference_options={"single_camera": True, "num_threads": 2},
    )
    assert ref is not None and len(ref.poses) == 6
    assert reference_options_used(out) == {"single_camera": True}  # defaults are not recorded
    cameras = reference_cameras(out / "reference.json")
    assert len({str(c["params"]) for c in cameras.values()}) == 1  # one shared camera
    stamp = (out / "reference.json").stat().st_mtime_ns
    simulate_scene(
        photos / "photos", out, frames=3, noise="gaussian:10", progress=False, reference_options={"single_camera": True}
    )
    assert (out / "reference.json").stat().st_mtime_ns == stamp  # same options: reused
    simulate_scene(photos / "photos", out, frames=3, noise="gaussian:10", progress=False)
    assert reference_options_used(out) == {} and (out / REFERENCE_DIR / "options.json").is_file()
    assert len({str(c["params"]) for c in reference_cameras(out / "reference.json").values()}) == 6
    # the CLI's defaults are the defaults: a reference made before the options existed is reused
    import argparse

    from lburst.cli.simulate_scene import configure_parser, reference_options

    parser = argparse.ArgumentParser()
    configure_parser(parser)
    assert non_default_options(reference_options(parser.parse_args(["photos", "--out", "scene"]))) == {}


def test_cli_reference_options():
    import argparse

    from lburst.cli.simulate_scene import configure_parser

    parser = argparse.ArgumentParser()
    configure_parser(parser)
    args = parser.parse_args(["photos", "--out", "scene", "--reference-single-camera", "--reference-fix-intrinsics"])
    assert args.reference_single_camera and args.reference_fix_intrinsics and args.reference_threads == 2
    assert "--reference-single-camera" in parser.format_help()


def test_reference_spread_is_measured_kept_and_dropped_with_its_reference(photos):
    import json

    from lburst.scenes.photo_scene import REFERENCE_DIR
    from lburst.scenes.reference_spread import SPREAD_FILE, load_spread, reference_spread, summary

    out = photos / "scene_spread"
    simulate_scene(photos / "photos", out, frames=3, noise="gaussian:10", progress=False, reference_seeds=[1, 2])
    record = load_spread(out, REFERENCE_DIR)
    assert record is not None and [r["seed"] for r in record["runs"]] == [1, 2] and record["images"] == 6
    from lburst.sfm.result import ReconstructionResult

    saved = Reference.load(out / "reference.json")
    names = sorted(saved.poses)
    for run in record["runs"]:
        # the ATE is the seed's own clean run against reference.json, as the benchmark measures a method
        rerun = ReconstructionResult.load(out / REFERENCE_DIR / f"seed{run['seed']}" / "result.json")
        assert sorted(rerun.poses) == names and run["registered"] == 6
        own = trajectory_errors([rerun.poses[n] for n in names], [saved.poses[n] for n in names], length=saved.length)
        assert run["ate_rmse"] == pytest.approx(own["ate_rmse"]) and run["ate_max"] == pytest.approx(own["ate_max"])
        # both clean runs find the small daylight flight about alike: within 2 % of its path
        assert run["ate_percent"] < 2.0
    assert "seeds 1, 2" in summary(record)
    # a rerun reads the seeds' runs back instead of reconstructing again
    result = out / REFERENCE_DIR / "seed1" / "result.json"
    stamp = result.stat().st_mtime_ns
    assert (
        reference_spread(photos / "photos", out, [1], "sift", REFERENCE_DIR, {}, progress=False)["runs"][0]
        == record["runs"][0]
    )
    assert result.stat().st_mtime_ns == stamp
    # a spread made for another reference.json is not this reference's
    data = json.loads((out / "reference.json").read_text())
    data["length"] = 2 * data["length"]
    (out / "reference.json").write_text(json.dumps(data))
    assert (out / REFERENCE_DIR / SPREAD_FILE).is_file() and load_spread(out, REFERENCE_DIR) is None
    # a reference made again with other options drops the reruns made for the old one
    simulate_scene(
        photos / "photos", out, frames=3, noise="gaussian:10", progress=False, reference_options={"single_camera": True}
    )
    assert not (out / REFERENCE_DIR / "seed1").exists() and not (out / REFERENCE_DIR / SPREAD_FILE).exists()


def test_reference_spread_refuses_bad_seeds(photos):
    from lburst.errors import LBurstValueError
    from lburst.scenes.reference_spread import reference_spread

    for seeds in ([], [-1], [True]):
        with pytest.raises(LBurstValueError, match="reference seed"):
            reference_spread(photos / "photos", photos / "nowhere", seeds, "sift", ".reference", {}, progress=False)
