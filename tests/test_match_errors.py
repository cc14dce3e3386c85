"""scripts/match_errors.py: putative matches judged against the reference poses, exactly."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from lburst.sfm.reference import Reference
from lburst.sfm.scene import save_reference

pytest.importorskip("pycolmap")


def _rotation(deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


CAMERA = {"model": "PINHOLE", "width": 640, "height": 480, "params": [500.0, 500.0, 320.0, 240.0]}
POSES = {"a": (np.eye(3), np.zeros(3)), "b": (_rotation(10), np.array([-1.0, 0.0, 0.2]))}


def _seen(rng: np.random.Generator, count: int) -> dict[str, np.ndarray]:
    """Pixels of ``count`` random points 6-10 m ahead in the images of :data:`POSES` under :data:`CAMERA`."""
    world = np.c_[rng.uniform(-2, 2, (count, 2)), rng.uniform(6, 10, count)]
    pixels = {}
    for name, (r, t) in POSES.items():
        cam = world @ r.T + t
        pixels[name] = 500 * cam[:, :2] / cam[:, 2:] + [320, 240]
    return pixels


@pytest.mark.parametrize("layout", ["per_image", "shared"])  # a photo set's cameras; a synthetic flight's one
def test_true_matches_have_no_error_and_swapped_ones_are_wrong(tmp_path, layout, load_script):
    me = load_script("match_errors")
    rng = np.random.default_rng(0)
    camera, poses = CAMERA, POSES
    scene = tmp_path / "scene"
    scene.mkdir()
    per_image = {n: camera for n in poses} if layout == "per_image" else None
    save_reference(Reference("sift-clean", camera, poses), scene / "reference.json", per_image)
    kps = {name: pixels.astype(np.float32) for name, pixels in _seen(rng, 200).items()}
    run = tmp_path / "run"
    run.mkdir()
    matches = np.arange(200, dtype=np.int32)
    matches[150:] = rng.permutation(matches[150:])  # 50 matches to other points: nearly all wrong
    with h5py.File(run / "features.h5", "w") as f:
        for name in poses:
            f[f"{name}.png/keypoints"] = kps[name]
            f[f"{name}.png/scores"] = np.linspace(0, 1, 200, dtype=np.float32)
    with h5py.File(run / "matches.h5", "w") as f:
        f["a.png/b.png/matches0"] = matches
    cameras, reference = me.reference_geometry(scene)
    found = me.putative_matches(run, cameras, reference)
    errors = found["pairs"][("a", "b")][3]
    assert np.abs(errors[:150]).max() < 1e-3  # true correspondences lie on their epipolar lines
    assert np.mean(errors[150:] > me.WRONG_PX) > 0.8
    summary = me.summary(found, me.pair_scales([found]), ["a", "b"])
    assert summary["putative"] == 200 and summary["right"] >= 150
    assert summary["by_gap"]["1"]["pairs"] == 1 and summary["by_gap"]["1"]["right"] == summary["right"]
    assert 150 <= summary["by_gap"]["1"]["under_1px"] <= summary["right"]
    assert summary["by_score_quartile"][3]["wrong"] > summary["by_score_quartile"][0]["wrong"] == 0
    # the relative pose from these matches (25 % outliers) is the reference one
    assert max(found["pose_errors"]) < 0.5
    assert summary["pose_auc"]["5"] > 0.9


def test_a_wrong_relative_pose_is_measured_in_degrees_and_the_auc_follows_its_curve(load_script):
    import pycolmap

    me = load_script("match_errors")
    cameras = {n: pycolmap.Camera(**CAMERA) for n in "ab"}
    kps = _seen(np.random.default_rng(1), 300)
    told = {"a": POSES["a"], "b": (_rotation(13), POSES["b"][1])}  # a reference 3 degrees off the truth
    error = me.relative_pose_error(cameras, told, "a", "b", kps["a"], kps["b"])
    assert error == pytest.approx(3.0, abs=0.05)
    assert me.relative_pose_error(cameras, told, "a", "b", kps["a"][:4], kps["b"][:4]) == 180.0
    auc = me.pose_auc([0.0, 2.0, 4.0, 30.0])
    # trapezoids under the curve through (0, 1/4), (2, 2/4), (4, 3/4), flat to the limit (as SuperGlue's)
    assert auc["5"] == pytest.approx((2 * 0.375 + 2 * 0.625 + 1 * 0.75) / 5)
    assert auc["20"] == pytest.approx((2 * 0.375 + 2 * 0.625 + 16 * 0.75) / 20)


def test_on_a_rendered_flight_a_match_sliding_along_its_epipolar_line_is_caught(load_script):
    """At the renderer's depth, true matches have no full error; a match to the point of the
    same ray at another depth lies on its epipolar line (no Sampson error) but is far off."""
    me = load_script("match_errors")
    import pycolmap

    cameras = {n: pycolmap.Camera(**CAMERA) for n in "ab"}
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    depth = np.full((480, 640), 8.0)
    depth[:, 600:] = np.inf  # sky: no surface to measure against
    truth = {"K": K, "depth": {"a": depth, "b": depth}}
    rng = np.random.default_rng(2)
    ka = np.c_[rng.uniform(20, 580, 100), rng.uniform(20, 460, 100)]
    ka[-5:, 0] = 620  # in the sky
    rot, t = POSES["b"]

    def seen_in_b(z: float) -> np.ndarray:
        cam = (np.c_[ka + 0.5, np.ones(len(ka))] @ np.linalg.inv(K).T * z) @ rot.T + t
        return (cam @ K.T)[:, :2] / (cam @ K.T)[:, 2:] - 0.5

    kb = seen_in_b(8.0)
    kb[:30] = seen_in_b(5.0)[:30]  # the same ray, 3 m nearer: on the epipolar line, 20-60 px away
    transfer = me.transfer_px(truth, POSES, "a", "b", ka, kb)
    full, deeper = transfer[:, 0], transfer[:, 1]
    sampson = me.sampson_px(cameras, POSES, "a", "b", ka + 0.5, kb + 0.5)
    assert np.isnan(transfer[-5:]).all()
    np.testing.assert_allclose(transfer[30:95], 0, atol=1e-6)
    assert (full[:30] > me.WRONG_PX).all() and (sampson[:30] < 1e-3).all()
    # the slid matches are nearer points of the same rays: off by their whole error, towards less depth
    np.testing.assert_allclose(deeper[:30], -full[:30], rtol=1e-9)
    # the same for a camera that moves forwards: a's centre lies behind b (the focus of expansion)
    ahead = {"a": POSES["a"], "b": (np.eye(3), np.array([0.3, 0.0, -1.0]))}
    cam = np.c_[ka[:30] + 0.5, np.ones(30)] @ np.linalg.inv(K).T * 5.0 + ahead["b"][1]
    nearer = (cam @ K.T)[:, :2] / (cam @ K.T)[:, 2:] - 0.5
    forward = me.transfer_px(truth, ahead, "a", "b", ka[:30], nearer)
    assert (forward[:, 0] > 1).all()
    np.testing.assert_allclose(forward[:, 1], -forward[:, 0], rtol=1e-9)
    run = {
        "pairs": {("a", "b"): (ka, kb, np.ones(100), sampson, transfer)},
        "sizes": {"a": (640, 480), "b": (640, 480)},
    }
    found = me.full_error_summary(run, ["a", "b"])
    assert found["measured"] == 95 and found["right"] == 65 and found["along_line"] == 30
    assert found["by_gap"]["1"]["along_line"] == 30 and found["by_pair"] == {"a b": 65}
    assert found["by_gap"]["1"]["deeper_px"] == pytest.approx(0, abs=1e-6)  # the right ones are exact
    cells = {(int(x // 40), int(y // 40)) for x, y in kb[30:95]}  # the right ones, in b
    assert found["by_gap"]["1"]["coverage"] == pytest.approx(len(cells) / (16 * 12))


def test_coverage_counts_the_cells_that_hold_a_point_partial_cells_included(load_script):
    me = load_script("match_errors")
    points = np.array([[1.0, 1.0], [39.9, 39.9], [40.0, 0.0], [99.0, 59.0]])  # cells (0,0) twice, (1,0), (2,1)
    assert me.coverage(points, (100, 60)) == pytest.approx(3 / (3 * 2))
    assert me.coverage(np.zeros((0, 2)), (100, 60)) == 0.0


def test_keypoints_spread_evenly_put_a_tenth_in_the_densest_tenth_of_cells(load_script):
    me = load_script("match_errors")
    grid = np.stack(np.meshgrid(np.arange(20, 400, 40), np.arange(20, 400, 40)), -1).reshape(-1, 2).astype(float)
    assert me.densest_tenth(grid, (400, 400)) == pytest.approx(0.1)  # one keypoint in each of 100 cells
    bunched = np.r_[grid, np.full((100, 2), 5.0)]  # and 100 more in one cell: 101 + 9 of 200
    assert me.densest_tenth(bunched, (400, 400)) == pytest.approx(110 / 200)
