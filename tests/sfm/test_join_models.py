"""Joining the models the incremental mapper split one database into (:mod:`lburst.sfm.join`).

A synthetic scene: 400 points in front of 8 pinhole cameras along a curved path.
Model A holds cameras 0-4 and 7 in the ground-truth frame, model B cameras 4-7 in
another frame (a known similarity), so they share two images (4 and 7), like the two
models of a looping flight.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lburst.sfm.colmap import ColmapJob, ColmapOptions, map_database, pycolmap, verify, write_database
from lburst.sfm.join import join_models, sim3_from_shared_images
from lburst.sfm.poses import path_length, trajectory_errors

W, H, F = 640, 480, 500.0
CAMERA = {"model": "PINHOLE", "width": W, "height": H, "params": [F, F, W / 2, H / 2], "prior_focal": True}
A_IMAGES, B_IMAGES = [0, 1, 2, 3, 4, 7], [4, 5, 6, 7]


def scene(seed: int = 0):
    """Points (P, 3), world-to-camera poses (R, t) of 8 cameras, and the points each camera sees (8, P)."""
    rng = np.random.default_rng(seed)
    points = rng.uniform([-8, -3, 8], [8, 3, 14], size=(400, 3))
    poses, visible = [], []
    for i in range(8):
        centre = np.array([i - 3.5, 0.6 * np.sin(i), 0.5 * np.cos(i)])
        z = np.array([0.4 * centre[0], 0.0, 11.0]) - centre
        z /= np.linalg.norm(z)
        x = np.cross([0.1 * np.sin(2 * i), 1.0, 0.0], z)  # a little roll
        x /= np.linalg.norm(x)
        R = np.stack([x, np.cross(z, x), z])
        poses.append((R, -R @ centre))
        uv, depth = project(points, R, -R @ centre)
        visible.append((depth > 0) & (uv >= 0).all(1) & (uv < [W, H]).all(1))
    return points, poses, np.array(visible)


def project(points: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (COLMAP's convention) and depths of points (P, 3) in camera (R, t)."""
    cam = points @ R.T + t
    return cam[:, :2] / cam[:, 2:] * F + [W / 2, H / 2], cam[:, 2]


def rigid(R: np.ndarray, t: np.ndarray) -> pycolmap.Rigid3d:
    return pycolmap.Rigid3d(pycolmap.Rotation3d(R), np.asarray(t, dtype=np.float64))


def known_sim3() -> pycolmap.Sim3d:
    R = Rotation.from_rotvec([0.4, -1.1, 0.7]).as_matrix()
    return pycolmap.Sim3d(2.7, pycolmap.Rotation3d(R), np.array([5.0, -2.0, 3.0]))


def ground_truth(poses) -> pycolmap.Reconstruction:
    """A model of the 8 cameras (image ids 1-8, no keypoints) in the ground-truth frame."""
    rec = pycolmap.Reconstruction()
    camera = pycolmap.Camera.create_from_model_name(1, "PINHOLE", F, W, H)
    rec.add_camera_with_trivial_rig(camera)
    for i, (R, t) in enumerate(poses):
        image = pycolmap.Image(name=f"k{i:02d}.png", camera_id=1, image_id=i + 1)
        rec.add_image_with_trivial_frame(image, rigid(R, t))
    return rec


def submodel(
    rec: pycolmap.Reconstruction, keep: list[int], sim: pycolmap.Sim3d | None = None
) -> pycolmap.Reconstruction:
    """A copy of ``rec`` with only the images ``keep`` (indices of image ids sorted) registered, mapped by ``sim``."""
    out = pycolmap.Reconstruction(rec)
    image_ids = sorted(out.images)
    for i, image_id in enumerate(image_ids):
        if i not in keep:
            out.deregister_frame(out.images[image_id].frame_id)
    if sim is not None:
        out.transform(sim)
    return out


def jitter(rec: pycolmap.Reconstruction, rng: np.random.Generator, degrees: float = 0.3, metres: float = 0.02) -> None:
    """Turn every registered camera of ``rec`` about a random axis and move its centre, by about the amounts given."""
    for frame_id in rec.reg_frame_ids():
        pose = rec.frames[frame_id].rig_from_world
        R = pose.rotation.matrix()
        centre = -R.T @ pose.translation + rng.normal(0, metres, 3)
        R = Rotation.from_rotvec(rng.normal(0, np.radians(degrees), 3)).as_matrix() @ R
        rec.frames[frame_id].rig_from_world = rigid(R, -R @ centre)


def test_sim3_from_two_shared_images_is_exact():
    _, poses, _ = scene()
    gt = ground_truth(poses)
    sim = known_sim3()
    a, b = submodel(gt, A_IMAGES), submodel(gt, B_IMAGES, sim)
    estimated = sim3_from_shared_images(a, b)  # a_from_b = sim^-1
    assert estimated is not None
    np.testing.assert_allclose(estimated.scale, 1 / 2.7, rtol=1e-6)
    np.testing.assert_allclose(estimated.rotation.matrix(), sim.rotation.matrix().T, atol=1e-6)
    np.testing.assert_allclose(estimated.translation, sim.inverse().translation, atol=1e-6)
    # and the other way round, and from four shared images
    np.testing.assert_allclose(sim3_from_shared_images(b, a).matrix(), sim.matrix(), atol=1e-6)
    c = submodel(gt, [2, 3, 4, 5, 6, 7], sim)
    np.testing.assert_allclose(sim3_from_shared_images(c, a).matrix(), sim.matrix(), atol=1e-6)


def test_sim3_needs_two_shared_images_that_agree():
    _, poses, _ = scene()
    gt = ground_truth(poses)
    a = submodel(gt, A_IMAGES)
    assert sim3_from_shared_images(a, submodel(gt, [4, 5, 6], known_sim3())) is None  # one shared image
    assert sim3_from_shared_images(a, submodel(gt, [5, 6], known_sim3())) is None  # none
    b = submodel(gt, B_IMAGES, known_sim3())
    pose = b.images[8].cam_from_world()  # image 7 turned by 20 degrees about its centre
    turn = Rotation.from_rotvec([0.0, np.radians(20), 0.0]).as_matrix()
    R = turn @ pose.rotation.matrix()
    b.frames[b.images[8].frame_id].rig_from_world = rigid(R, turn @ pose.translation)
    assert sim3_from_shared_images(a, b) is None


def test_a_model_sharing_fewer_than_two_images_is_not_joined(tmp_path):
    _, poses, _ = scene()
    gt = ground_truth(poses)
    a, b = submodel(gt, [0, 1, 2, 3, 4]), submodel(gt, [4, 5, 6, 7], known_sim3())
    before = {i: a.images[i].cam_from_world().matrix() for i in a.reg_image_ids()}
    opts = pycolmap.IncrementalPipelineOptions()
    joined = join_models([b, a], tmp_path / "missing.db", tmp_path, tmp_path, opts)
    assert joined is a and a.num_reg_images() == 5
    for image_id, matrix in before.items():
        np.testing.assert_array_equal(a.images[image_id].cam_from_world().matrix(), matrix)


@pytest.fixture(scope="module")
def database(tmp_path_factory):
    """A verified COLMAP database of the scene (keypoints: projections + 0.3 px noise) and its ground-truth model."""
    points, poses, visible = scene()
    rng = np.random.default_rng(1)
    root = tmp_path_factory.mktemp("join")
    (root / "images").mkdir()
    keypoints, index = [], []
    for (R, t), seen in zip(poses, visible):
        uv, _ = project(points[seen], R, t)
        keypoints.append((uv + rng.normal(0, 0.3, uv.shape) - 0.5).astype(np.float32))  # lburst's convention
        index.append(np.cumsum(seen) - 1)  # keypoint of each point in this image
    pairs, matches = [], []
    for a in range(8):
        for b in range(a + 1, 8):
            both = np.flatnonzero(visible[a] & visible[b])
            pairs.append((a, b))
            matches.append(np.stack([index[a][both], index[b][both]], 1))
    job = ColmapJob([f"k{i:02d}" for i in range(8)], str(root / "images"), [CAMERA], [0] * 8)
    db_path = root / "database.db"
    image_ids = write_database(db_path, job, keypoints, np.array(pairs), matches)
    verify(db_path, ColmapOptions(num_threads=1))
    with pycolmap.Database.open(str(db_path)) as db:
        cache = pycolmap.DatabaseCache.create(db, pycolmap.DatabaseCacheOptions())
    gt = pycolmap.Reconstruction()
    gt.load(cache)  # every image of the database, none registered
    for image_id, (R, t) in zip(image_ids, poses):
        frame_id = gt.images[image_id].frame_id
        gt.frames[frame_id].rig_from_world = rigid(R, t)
        gt.register_frame(frame_id)
    (root / "gt").mkdir()
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads = 1
    pycolmap.triangulate_points(gt, str(db_path), str(root / "images"), str(root / "gt"), options=opts)
    assert gt.num_points3D() > 300  # the models carry 3D points, as the mapper's do
    return db_path, root, gt, poses


@pytest.mark.parametrize("from_disk", [False, True], ids=["in-memory", "read-back"])
def test_join_models_through_two_shared_images(database, tmp_path, from_disk, caplog):
    db_path, root, gt, poses = database
    a, b = submodel(gt, A_IMAGES), submodel(gt, B_IMAGES)
    jitter(a, np.random.default_rng(2))  # models of their own: the shared images' poses differ a little
    jitter(b, np.random.default_rng(3))
    b.transform(known_sim3())
    if from_disk:  # a model read from disk holds its registered images only
        (tmp_path / "a").mkdir()
        a.write_binary(str(tmp_path / "a"))
        a = pycolmap.Reconstruction(str(tmp_path / "a"))
        assert a.num_images() == 6
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads = 1
    links = []
    with caplog.at_level(logging.INFO, logger="lburst.sfm.join"):
        joined = join_models({0: a, 1: b}.values(), db_path, root / "images", tmp_path, opts, links=links)
    assert "joined the largest model (6 images)" in caplog.text and "k04.png, k07.png" in caplog.text
    # the join: 2 new images, tied to the 6 others by the points they share with them
    new = {joined.find_image_with_name(n).image_id for n in ("k05.png", "k06.png")}
    spanning = sum(
        {e.image_id in new for e in point.track.elements} == {True, False} for point in joined.points3D.values()
    )
    assert links == [{"images": 2, "points": spanning}] and spanning > 100
    assert joined is not a and joined.num_reg_images() == 8
    assert a.num_reg_images() == b.num_reg_images() + 2 == 6  # the input models are not changed
    names = [f"k{i:02d}.png" for i in range(8)]
    estimated = []
    for name in names:
        pose = joined.find_image_with_name(name).cam_from_world()
        estimated.append((pose.rotation.matrix(), np.asarray(pose.translation)))
    errors = trajectory_errors(estimated, poses)
    length = path_length(np.array([-R.T @ t for R, t in poses]))
    assert errors["ate_rmse"] < 1e-3 * length
    assert errors["rpe_rot_rmse_deg"] < 0.1
    assert joined.num_points3D() > 300
    assert joined.compute_mean_reprojection_error() < 0.6
    for name in ("k05.png", "k06.png"):  # B's own images see the new points
        assert joined.find_image_with_name(name).num_points3D > 200


@pytest.mark.parametrize("join", [True, False], ids=["join", "no-join"])
def test_map_database_joins_split_models_when_asked(database, tmp_path, monkeypatch, join):
    db_path, root, gt, _ = database
    models = {0: submodel(gt, B_IMAGES, known_sim3()), 1: submodel(gt, A_IMAGES)}
    monkeypatch.setattr("pycolmap.incremental_mapping", lambda *args, **kwargs: models)  # a split the mapper made
    options = ColmapOptions(num_threads=1, join_models=join)
    rec = map_database(db_path, root / "images", tmp_path, options)
    assert rec.num_reg_images() == (8 if join else 6)
    assert (rec is models[1]) != join
