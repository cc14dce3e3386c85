"""Signs of a folded model (lburst.sfm.trust): a model that registered every image but is wrong
is flagged in result.json, report.md and the command's last line, and exits 1; good models pass."""

import json

import numpy as np
import pytest

from lburst.sfm.colmap import pycolmap
from lburst.sfm.trust import MIN_LINK, assess, describe_checks, model_measures

NAMES = [f"{i:04d}" for i in range(12)]


def summary(points=None, step=8.0, steps=None, links=None, errors=None, joins=()) -> dict:
    """A COLMAP child's summary of a straight flight of 12 cameras ``step`` m apart (or the
    given ``steps``), each holding ``points`` 3D points (default 300), with its measures."""
    steps = [step] * (len(NAMES) - 1) if steps is None else steps
    x = np.concatenate([[0.0], np.cumsum(steps)])
    points = points or {}
    registered = {
        n: {"R": np.eye(3).tolist(), "t": [-x[i], 0.0, 0.0], "num_points3D": points.get(n, 300)}
        for i, n in enumerate(NAMES)
    }
    links = links or {}
    return {
        "converged": True,
        "registered": registered,
        "trajectory_links": [[a, b, links.get(a, 600)] for a, b in zip(NAMES, NAMES[1:])],
        "image_reprojection_errors": {n: (errors or {}).get(n, 0.6) for n in NAMES},
        "joins": list(joins),
    }


def test_a_straight_flight_that_holds_together_passes():
    checks = assess(summary(), NAMES, ordered=True)
    assert checks["trusted"] and checks["reasons"] == []
    assert checks["measures"]["fewest_points3D"] == ["0000", 300]
    assert checks["measures"]["weakest_link"] == ["0000", "0001", 600]
    assert describe_checks(checks).startswith("model checks passed: fewest 3D points in an image 300")


def test_turns_that_hold_a_handful_of_points_are_flagged():
    """The night survey's case: its turns held 8-14 points per image, the others hundreds."""
    checks = assess(summary(points={"0005": 8, "0006": 14}), NAMES, ordered=True)
    assert not checks["trusted"]
    assert checks["reasons"] == ["2 images hold few 3D points against the median 300: 0005 (8), 0006 (14)"]


def test_a_small_scene_whose_every_image_holds_few_points_is_not_flagged_for_it():
    points = {n: 20 + i for i, n in enumerate(NAMES)}  # median 25.5: 20 is not under a quarter of it
    assert assess(summary(points=points), NAMES, ordered=True)["trusted"]


def test_parts_tied_by_a_handful_of_points_are_flagged_along_a_trajectory_only():
    folded = summary(links={"0005": 6})
    checks = assess(folded, NAMES, ordered=True)
    assert not checks["trusted"] and "0005-0006 (6)" in checks["reasons"][0]
    assert assess(folded, NAMES, ordered=False)["trusted"]  # a photo set's order is no trajectory


def test_a_jump_in_the_scale_of_the_steps_is_flagged():
    steps = [8.0] * 5 + [60.0] + [8.0] * 5  # a fold: the part after 0006 at another scale
    checks = assess(summary(steps=steps), NAMES, ordered=True)
    assert not checks["trusted"]
    assert checks["reasons"] == [  # the long step 0005-0006 against the steps before and after it
        "the steps to and from a camera differ in scale (a jump in the model's scale) at 0005 (7.5x), 0006 (7.5x)"
    ]
    hover = [8.0] * 5 + [0.01] + [8.0] * 5  # a camera that stands still is no jump
    assert assess(summary(steps=hover), NAMES, ordered=True)["trusted"]
    assert assess(summary(steps=[8.0, 9.0, 7.5, 12.0, 8.0, 6.0, 8.0, 10.0, 8.0, 8.0, 8.0]), NAMES, ordered=True)[
        "trusted"
    ]


def test_a_join_through_a_handful_of_points_is_flagged():
    weak = summary(joins=[{"images": 14, "points": 5}])
    assert assess(weak, NAMES, ordered=False)["reasons"] == [
        "a model of 14 images was joined to the rest through 5 shared 3D points"
    ]
    assert assess(summary(joins=[{"images": 14, "points": MIN_LINK}]), NAMES, ordered=False)["trusted"]


def test_an_image_that_reprojects_far_from_its_keypoints_is_flagged():
    checks = assess(summary(errors={"0003": 3.4}), NAMES, ordered=False)
    assert checks["reasons"] == ["1 images reproject their points far from their keypoints: 0003 (3.4 px)"]


def test_cameras_far_from_the_positions_that_placed_the_model_are_flagged():
    """With the flight's positions as priors (std 2 m) a model stood up to 66 m from them."""
    good = summary()
    truth = {n: -np.asarray(v["R"]).T @ np.asarray(v["t"]) for n, v in good["registered"].items()}
    priors = {n: c + np.array([0.5, -0.5, 1.0]) for n, c in truth.items()}
    assert assess(good, NAMES, ordered=True, priors=priors, prior_std=2.0)["trusted"]
    priors["0004"] = truth["0004"] + np.array([0.0, 66.0, 0.0])
    checks = assess(good, NAMES, ordered=True, priors=priors, prior_std=2.0)
    assert checks["reasons"] == [
        "1 cameras lie over 5 times the prior's standard deviation (2 m) from their positions: 0004 (66 m)"
    ]
    assert checks["measures"]["farthest_from_prior"] == ["0004", 66.0]
    assert assess(good, NAMES, ordered=True, priors=None, prior_std=2.0)["trusted"]  # positions that did not place it


def line_model(links: list[int], offset: float = 0.0) -> "pycolmap.Reconstruction":
    """Four cameras 1 m apart along x looking down z; ``links[k]`` points seen by images k and
    k + 1 only, and 5 points seen by all four; image 0002.png's observations ``offset`` px off."""
    rec = pycolmap.Reconstruction()
    camera = pycolmap.Camera(model="SIMPLE_PINHOLE", width=400, height=300, params=[300.0, 200.0, 150.0], camera_id=1)
    rec.add_camera_with_trivial_rig(camera)
    rng = np.random.default_rng(0)
    tracks = [[k, k + 1] for k, n in enumerate(links) for _ in range(n)] + [[0, 1, 2, 3]] * 5
    xyz = [np.array([1.5, 0.0, 10.0]) + rng.uniform(-3, 3, 3) * [1, 1, 0.2] for _ in tracks]
    poses = [pycolmap.Rigid3d(pycolmap.Rotation3d(), np.array([-float(i), 0.0, 0.0])) for i in range(4)]
    observations = {i: [] for i in range(4)}
    for p, track in enumerate(tracks):
        for i in track:
            xy = np.asarray(camera.img_from_cam(poses[i] * xyz[p])) + (offset if i == 2 else 0.0)
            observations[i].append((p, xy))
    for i in range(4):
        image = pycolmap.Image(name=f"{i:04d}.png", camera_id=1, image_id=i + 1)
        image.points2D = pycolmap.Point2DList([pycolmap.Point2D(xy) for _, xy in observations[i]])
        rec.add_image_with_trivial_frame(image, poses[i])
    for p, track in enumerate(tracks):
        t = pycolmap.Track()
        for i in track:
            t.add_element(i + 1, [q for q, _ in observations[i]].index(p))
        rec.add_point3D(xyz[p], t)
    return rec


def test_the_model_measures_count_the_points_that_tie_each_part_of_the_trajectory_to_the_rest():
    measures = model_measures(line_model([40, 3, 40], offset=1.5), ["0000", "0001", "0002", "0003"])
    # between 0001 and 0002: the 3 points of that pair and the 5 that every image sees
    assert measures["trajectory_links"] == [["0000", "0001", 45], ["0001", "0002", 8], ["0002", "0003", 45]]
    errors = measures["image_reprojection_errors"]
    assert errors["0002"] == pytest.approx(1.5 * np.sqrt(2), abs=1e-6) and errors["0000"] < 1e-6


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """Five single-frame bursts of the daylight flight, 256x192."""
    from lburst.scenes.night_flight import NightFlightConfig, make_night_flight

    out = tmp_path_factory.mktemp("flight")
    cfg = NightFlightConfig.daylight(n_bursts=5, frames_per_burst=1, width=256, height=192, noise="none")
    make_night_flight(out, cfg, progress=False)
    return out


def run(flight, out, capsys) -> tuple[int, list[str], list[str]]:
    from lburst.cli import main

    argv = ["reconstruct", str(flight), "--method", "sift,max_features=1500", "--out", str(out), "--threads", "1"]
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out.strip().splitlines(), captured.err.strip().splitlines()


def test_a_good_model_passes_its_checks_and_says_so_last(flight, tmp_path, capsys):
    code, out, _ = run(flight, tmp_path / "out", capsys)
    assert code == 0 and out[-1].startswith("model checks passed: fewest 3D points in an image")
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["checks"]["trusted"] is True and result["checks"]["measures"]["fewest_points3D"][1] >= 30
    assert "**Checks** (passed): model checks passed" in (tmp_path / "out" / "report.md").read_text()


def test_a_folded_model_exits_1_and_says_why_in_its_last_line_report_and_result(flight, tmp_path, capsys, monkeypatch):
    """COLMAP's summary of the same images, but two of them hold a handful of 3D points."""
    from lburst.sfm import mapping as module  # the stage that runs the COLMAP child

    real = module.run_job_subprocess

    def folded(job_dir, **kwargs):
        found = real(job_dir, **kwargs)
        for name, count in (("0001", 9), ("0002", 12)):
            found["registered"][name]["num_points3D"] = count
        return found

    monkeypatch.setattr(module, "run_job_subprocess", folded)
    code, out, err = run(flight, tmp_path / "out", capsys)
    assert code == 1 and out[-1].startswith("5/5 images registered")
    assert err[-1].startswith("lburst reconstruct: error: the model may be wrong (folded): 2 images hold few 3D points")
    assert "0001 (9), 0002 (12)" in err[-1]
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["checks"]["trusted"] is False and result["status"] == "complete"
    assert "**Checks** (failed): the model may be wrong (folded)" in (tmp_path / "out" / "report.md").read_text()
