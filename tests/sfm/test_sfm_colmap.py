"""The COLMAP database import (exact read-back) and the reference epipolar distance."""

import numpy as np
import pytest

from lburst.sfm.colmap import ColmapJob, ColmapOptions, default_camera, pycolmap, read_inliers, write_database
from lburst.sfm.metrics import epipolar_distances


def small_job(tmp_path):
    rng = np.random.default_rng(0)
    names = ["a", "b", "c"]
    keypoints = [rng.uniform(0, 300, size=(k, 2)).astype(np.float32) for k in (50, 40, 30)]
    keypoints[0][0] = (0.0, 0.0)  # the centre of the top-left pixel
    pairs = np.array([[0, 1], [0, 2], [1, 2]])
    matches = [
        np.stack([rng.permutation(ka)[:m], rng.permutation(kb)[:m]], 1)
        for (ka, kb), m in zip([(50, 40), (50, 30), (40, 30)], (20, 10, 0))
    ]
    cams = [default_camera(320, 240), default_camera(320, 240, "PINHOLE", focal=300.0)]
    job = ColmapJob(names, str(tmp_path / "images"), cams, [0, 1, 0])
    return job, keypoints, pairs, matches


def test_database_import_reads_back_exactly(tmp_path):
    job, keypoints, pairs, matches = small_job(tmp_path)
    db_path = tmp_path / "database.db"
    ids = write_database(db_path, job, keypoints, pairs, matches)
    with pycolmap.Database.open(str(db_path)) as db:
        assert db.num_images() == 3 and db.num_frames() == 3 and db.num_cameras() == 2
        for name, image_id, kp, cam in zip(job.names, ids, keypoints, job.camera_of_image):
            image = db.read_image(image_id)
            assert image.name == f"{name}.png"
            stored = db.read_keypoints(image_id)
            assert stored.shape == kp.shape
            np.testing.assert_array_equal(stored, kp + np.float32(0.5))  # COLMAP's pixel convention
            camera = db.read_camera(image.camera_id)
            assert camera.model.name == job.cameras[cam]["model"]
            np.testing.assert_array_equal(camera.params, job.cameras[cam]["params"])
        assert db.read_keypoints(ids[0])[0].tolist() == [0.5, 0.5]
        for (a, b), m in zip(pairs, matches):
            np.testing.assert_array_equal(db.read_matches(ids[a], ids[b]), m.astype(np.uint32))


def test_database_import_rejects_what_colmap_would_abort_on(tmp_path):
    job, keypoints, pairs, matches = small_job(tmp_path)
    bad_kp = [np.c_[keypoints[0], np.ones(50, np.float32)]] + keypoints[1:]  # (K, 3)
    with pytest.raises(ValueError, match="must be \\(K, 2\\)"):
        write_database(tmp_path / "x.db", job, bad_kp, pairs, matches)
    bad_matches = [np.array([[0, 40]])] + matches[1:]  # image b has 40 keypoints: index 40 does not exist
    with pytest.raises(ValueError, match="index missing keypoints"):
        write_database(tmp_path / "y.db", job, keypoints, pairs, bad_matches)


def test_read_inliers_orders_pairs_by_image(tmp_path):
    job, keypoints, pairs, matches = small_job(tmp_path)
    db_path = tmp_path / "database.db"
    ids = write_database(db_path, job, keypoints, pairs, matches)
    geometry = pycolmap.TwoViewGeometry()
    geometry.config = pycolmap.TwoViewGeometryConfiguration.CALIBRATED
    geometry.inlier_matches = matches[0][:5].astype(np.uint32)
    with pycolmap.Database.open(str(db_path)) as db:
        db.write_two_view_geometry(ids[0], ids[1], geometry)
    v_pairs, inliers = read_inliers(db_path, ids)
    assert v_pairs.tolist() == [[0, 1]]
    np.testing.assert_array_equal(inliers[0], matches[0][:5])


def test_epipolar_distance_of_a_rectified_pair():
    # two pinhole cameras 1 m apart along x: epipolar lines are the image rows
    camera = {"model": "PINHOLE", "width": 640, "height": 480, "params": [500.0, 500.0, 320.0, 240.0]}
    pose_a = (np.eye(3), np.zeros(3))
    pose_b = (np.eye(3), np.array([-1.0, 0.0, 0.0]))
    points = np.array([[0.3, -0.2, 5.0], [-1.0, 0.5, 8.0], [0.0, 0.0, 3.0]])
    project = lambda p, t: (p + t)[:, :2] / (p + t)[:, 2:] * 500 + [320, 240]  # noqa: E731
    xa, xb = project(points, pose_a[1]), project(points, pose_b[1])
    np.testing.assert_allclose(epipolar_distances(xa, xb, camera, camera, pose_a, pose_b), 0, atol=1e-9)
    xb_moved = xb + [[0, 3.0], [7.0, 0.0], [0, -1.5]]  # off the row by 3 px; along it; off by 1.5 px
    np.testing.assert_allclose(
        epipolar_distances(xa, xb_moved, camera, camera, pose_a, pose_b), [3.0, 0.0, 1.5], atol=1e-9
    )


def test_a_failing_colmap_child_is_reported_not_fatal(tmp_path):
    from lburst.sfm.colmap import ColmapError, run_job_subprocess

    job, _, _, _ = small_job(tmp_path)
    job.save(tmp_path / "job.json")
    (tmp_path / "input.npz").write_bytes(b"not an npz")
    with pytest.raises(ColmapError, match="exited with 1") as err:
        run_job_subprocess(tmp_path)
    assert "colmap.log" in str(err.value)


def test_the_child_reports_each_stage_as_it_ends(tmp_path):
    from lburst.sfm.colmap import run_job_subprocess

    job, keypoints, pairs, matches = small_job(tmp_path)
    job.save(tmp_path / "job.json")
    np.savez(
        tmp_path / "input.npz",
        pairs=pairs,
        **{f"kp_{i}": kp for i, kp in enumerate(keypoints)},
        **{f"m_{p}": m for p, m in enumerate(matches)},
    )
    lines: list[str] = []
    summary = run_job_subprocess(tmp_path, report=lines.append)
    assert not summary["converged"]  # random matches: nothing verified, nothing to map
    assert [line.rsplit(": ", 1)[0] for line in lines] == [
        "COLMAP feature and match import (3 images, 3 pairs)",
        "COLMAP geometric verification",
    ]
    assert all(line.endswith(" s") and float(line.rsplit(": ", 1)[1][:-2]) >= 0 for line in lines)


def test_a_long_stage_is_reported_while_it_runs(tmp_path):
    from lburst.sfm.colmap import HEARTBEAT_SECONDS, StageLog, StageReader

    now = [0.0]
    lines: list[str] = []
    reader = StageReader(tmp_path / "stages.txt", lines.append, clock=lambda: now[0])
    reader.poll()  # no file yet: nothing
    log = StageLog(tmp_path / "stages.txt")
    with log.stage("mapping"):
        reader.poll()
        now[0] = HEARTBEAT_SECONDS - 1
        reader.poll()
        assert lines == []
        now[0] = HEARTBEAT_SECONDS + 1
        reader.poll()
        reader.poll()  # once per interval
        assert lines == [f"COLMAP mapping: running, {HEARTBEAT_SECONDS + 1:.0f} s so far"]
    reader.poll()
    assert len(lines) == 2 and lines[1].startswith("COLMAP mapping: ") and lines[1].endswith(" s")
    now[0] = 100.0
    reader.poll()  # no stage under way: silence
    assert len(lines) == 2


def test_the_mapper_runs_again_while_images_stay_unregistered(tmp_path, monkeypatch):
    """map_database keeps the attempt with the most registered images (then 3D points), with a
    new seed per attempt, and stops once every image of the database is registered."""
    import lburst.sfm.colmap as colmap

    job, keypoints, pairs, matches = small_job(tmp_path)
    write_database(tmp_path / "database.db", job, keypoints, pairs, matches)

    class Model:
        def __init__(self, images, points):
            self.images, self.points = images, points

        def num_reg_images(self):
            return self.images

        def num_points3D(self):
            return self.points

    runs = {0: Model(2, 50), 10007: Model(2, 80), 20014: Model(3, 10), 30021: Model(3, 99)}
    seeds = []

    def one_run(db, images, folder, options, stages, use_priors, label="", joins=None):
        seeds.append((options.seed, folder.name))
        joins.append({"images": options.seed, "points": 40})  # how the joins of this attempt's model hold
        return runs[options.seed]

    monkeypatch.setattr(colmap, "_map_once", one_run)
    joins = []
    best = colmap.map_database(
        tmp_path / "database.db", tmp_path, tmp_path / "sparse", ColmapOptions(mapper_attempts=4), joins=joins
    )
    assert best is runs[20014]  # every image registered: no fourth attempt
    assert joins == [{"images": 20014, "points": 40}]  # the joins of the model kept, not of the others
    assert seeds == [(0, "sparse"), (10007, "attempt1"), (20014, "attempt2")]
    seeds.clear()
    best = colmap.map_database(
        tmp_path / "database.db", tmp_path, tmp_path / "sparse", ColmapOptions(mapper_attempts=2)
    )
    assert best is runs[10007] and len(seeds) == 2  # same images registered: more 3D points
    seeds.clear()
    assert (
        colmap.map_database(tmp_path / "database.db", tmp_path, tmp_path / "s", ColmapOptions(mapper_attempts=1))
        is runs[0]
    )
    with pytest.raises(ValueError, match="mapper_attempts"):
        ColmapOptions(mapper_attempts=0)
