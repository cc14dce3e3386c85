"""Pairs of a recording: never exhaustive by default, and far pairs (loop candidates) kept only
when their inlier count passes the loop test, which COLMAP's own verification does not do."""

import json

import numpy as np
import pytest

from lburst.sfm.colmap import ColmapJob, ColmapOptions, default_camera, loop_test, pycolmap, run_job
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.pairs import make_pairs, pair_plan


@pytest.mark.parametrize("n", [2, 3, 7, 15, 20, 21, 40])
def test_a_recording_never_gets_exhaustive_pairs_by_default(n):
    plan = pair_plan(n, ReconstructOptions(), recording=True)
    assert plan.mode == "sequential" and plan.overlap == 2 and plan.retrieval == 5
    assert plan.near == 2  # every retrieval candidate goes through the loop test
    assert plan.abs_pose_inliers == 10 and plan.two_view_tracks and plan.mapper_threads == 1
    if n == 15:  # the night flight: 27 sequential pairs instead of all 105
        assert len(make_pairs(n, plan.mode, plan.overlap)) == 27


def test_a_scene_keeps_its_defaults_and_options_win():
    scene = pair_plan(15, ReconstructOptions(), recording=False)
    assert (scene.mode, scene.overlap, scene.retrieval, scene.near, scene.abs_pose_inliers) == (
        "exhaustive",
        10,
        0,
        0,
        30,
    )
    assert not scene.two_view_tracks and scene.mapper_threads is None  # COLMAP's triangulation, --threads
    assert pair_plan(25, ReconstructOptions(), recording=False).mode == "sequential"
    chosen = pair_plan(15, ReconstructOptions(pairs="exhaustive"), recording=True)
    assert chosen.mode == "exhaustive" and chosen.near == 2  # asked for, but its far pairs are tested
    assert pair_plan(15, ReconstructOptions(overlap=1), recording=True).near == 1
    assert pair_plan(15, ReconstructOptions(overlap=4), recording=True).near == 2
    custom = pair_plan(15, ReconstructOptions(overlap=2, retrieval=0, near=0, abs_pose_inliers=30), recording=True)
    assert (custom.overlap, custom.retrieval, custom.near, custom.abs_pose_inliers) == (2, 0, 0, 30)
    with pytest.raises(ValueError, match="overlap"):
        pair_plan(15, ReconstructOptions(overlap=0), recording=True)


def test_loop_test_on_the_counts_of_the_night_flight():
    # verified inlier counts of the moonless DNG flight (LBurst): adjacent pairs 69-248,
    # a true pair 2 apart 134, false pairs 4 and 9 apart with 38 and 35 inliers
    pairs = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [4, 6], [1, 5], [3, 12], [0, 14]])
    counts = [134, 170, 98, 119, 248, 134, 38, 35, 120]
    keep, threshold = loop_test(pairs, counts, near=2, fraction=0.4, min_inliers=15)
    assert threshold == pytest.approx(0.4 * 134)
    assert keep.tolist() == [True] * 6 + [False, False, True]
    keep, _ = loop_test(pairs, counts, near=0, fraction=0.5)
    assert keep.all()  # no test: COLMAP's verification alone
    keep, threshold = loop_test(np.array([[0, 2], [1, 3], [0, 9]]), [60, 50, 200], near=2, fraction=0.5)
    assert threshold == pytest.approx(27.5) and keep.all()  # no adjacent pair: the median of the near ones
    keep, threshold = loop_test(np.array([[0, 5]]), [500], near=1, fraction=0.5)
    assert threshold == np.inf and not keep.any()  # no neighbour to compare with: no loop is trusted


def _project(points, R, t, f, size):
    cam = points @ R.T + t
    uv = f * cam[:, :2] / cam[:, 2:] + np.array(size) / 2
    inside = (cam[:, 2] > 0) & (uv >= 1).all(1) & (uv < np.array(size) - 1).all(1)
    return uv, inside


def _rot_y(deg):
    a = np.radians(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def false_loop_job(tmp_path, near, two_view_tracks=False):
    """Four views along a line over a random 3D scene, adjacent pairs matched with 150 true
    correspondences each, and a false loop pair (0, 3): 40 matches of extra keypoints that fit
    one epipolar geometry, of other points seen from another pose, as noisy descriptors
    of unrelated views can.  Returns the job folder and how many scene points are matched in
    all three adjacent pairs (the true tracks from view 0 to view 3)."""
    rng = np.random.default_rng(1)
    f, size = 300.0, (320, 240)
    points = np.c_[rng.uniform(-6, 14, 4000), rng.uniform(-4, 4, 4000), rng.uniform(8, 14, 4000)]
    poses = [(np.eye(3), -np.array([2.0 * i, 0, 0])) for i in range(4)]
    uvs, masks = zip(*(_project(points, R, t, f, size) for R, t in poses))
    keypoints, index = [], []
    for i in range(4):
        idx = np.flatnonzero(masks[i])[:1500]
        keypoints.append(uvs[i][idx].astype(np.float32) - 0.5)  # lburst's pixel convention
        index.append({p: k for k, p in enumerate(idx)})
    pairs, matches, chained = [], [], None
    for a in range(3):
        common = [p for p in index[a] if p in index[a + 1]][:150]
        chained = set(common) if chained is None else chained & set(common)
        pairs.append((a, a + 1))
        matches.append(np.array([[index[a][p], index[a + 1][p]] for p in common]))
    other = np.c_[rng.uniform(-3, 3, 400), rng.uniform(-2, 2, 400), rng.uniform(6, 9, 400)]
    uv0, in0 = _project(other, np.eye(3), np.zeros(3), f, size)
    uv3, in3 = _project(other, _rot_y(25.0), np.array([1.0, 0.2, 0.3]), f, size)
    both = np.flatnonzero(in0 & in3)[:40]
    assert len(both) == 40
    k0, k3 = len(keypoints[0]), len(keypoints[3])
    keypoints[0] = np.r_[keypoints[0], uv0[both].astype(np.float32) - 0.5]
    keypoints[3] = np.r_[keypoints[3], uv3[both].astype(np.float32) - 0.5]
    pairs.append((0, 3))
    matches.append(np.stack([k0 + np.arange(40), k3 + np.arange(40)], 1))
    camera = default_camera(*size, "PINHOLE", focal=f)
    options = ColmapOptions(
        num_threads=1, max_num_trials=2000, near=near, refine_focal_length=False, two_view_tracks=two_view_tracks
    )
    job = ColmapJob([f"v{i}" for i in range(4)], str(tmp_path / "images"), [camera], [0] * 4, options)
    job_dir = tmp_path / f"near{near}_{int(two_view_tracks)}"
    job_dir.mkdir()
    job.save(job_dir / "job.json")
    np.savez(
        job_dir / "input.npz",
        pairs=np.array(pairs),
        **{f"kp_{i}": kp for i, kp in enumerate(keypoints)},
        **{f"m_{p}": m for p, m in enumerate(matches)},
    )
    return job_dir, len(chained)


def test_a_false_loop_pair_passes_colmap_but_not_the_loop_test(tmp_path):
    (tmp_path / "images").mkdir()
    plain, _ = false_loop_job(tmp_path, near=0)
    run_job(plain)
    verified = np.load(plain / "verified.npz")
    kept = {tuple(p): len(verified[f"inl_{q}"]) for q, p in enumerate(verified["pairs"])}
    assert set(kept) == {(0, 1), (1, 2), (2, 3), (0, 3)}  # COLMAP verifies the false pair too
    assert kept[(0, 3)] >= 30 and min(kept[(0, 1)], kept[(1, 2)], kept[(2, 3)]) >= 140

    tested, chained = false_loop_job(tmp_path, near=1)
    summary = run_job(tested)
    verified = np.load(tested / "verified.npz")
    assert sorted(map(tuple, verified["pairs"].tolist())) == [(0, 1), (1, 2), (2, 3)]
    assert verified["refused"].tolist() == [[0, 3]] and verified["refused_inliers"][0] >= 30
    assert summary["refused_pairs"] == [[0, 3]] and summary["loop_threshold"] >= 55
    assert json.loads((tested / "output.json").read_text())["refused_pairs"] == [[0, 3]]
    with pycolmap.Database.open(str(tested / "database.db")) as db:
        ids = {image.name: image.image_id for image in db.read_all_images()}
        assert not db.exists_two_view_geometry(ids["v0.png"], ids["v3.png"])
        assert db.exists_two_view_geometry(ids["v0.png"], ids["v1.png"])
    # the loop's two ends stay tied in the model through the views between them
    assert chained > 50 and 0.9 * chained <= summary["first_last_points3D"] <= chained


def test_two_view_tracks_are_triangulated_when_asked(tmp_path):
    # the adjacent pairs' matches are the first 150 common points of each pair, so many
    # points are matched in one pair only: COLMAP leaves those out unless asked
    (tmp_path / "images").mkdir()
    ignored = run_job(false_loop_job(tmp_path, near=1)[0])
    kept = run_job(false_loop_job(tmp_path, near=1, two_view_tracks=True)[0])
    assert len(ignored["registered"]) == len(kept["registered"]) == 4
    assert kept["num_points3D"] > ignored["num_points3D"] + 50
