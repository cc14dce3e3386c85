"""Joining the models that COLMAP's incremental mapper split one database into.

On a dark looping flight the mapper can lose the thread and start a new model, which
then holds a stretch of keyframes the largest model lacks; the two often share only two
registered images (where the new model was started and where the old one picked up
again), too few for ``pycolmap.align_reconstructions_via_proj_centers`` (3 images) and
too few common 3D points for alignment by reprojection.  Two shared camera poses do fix
the similarity between the models' world frames (with 5 constraints to spare), so
:func:`join_models` estimates it from them (:func:`sim3_from_shared_images`), registers
in the largest model the images it lacks with their transformed poses, re-triangulates
every point from the database's verified matches and runs a global bundle adjustment.

Every model is of the same database, so an image has the database's id in each of them.
A pose is world-to-camera (COLMAP's ``cam_from_world``: ``x_cam = R @ x_world + t``).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from lburst.errors import LBurstValueError
from lburst.extras import pycolmap

log = logging.getLogger(__name__)


def shared_images(target: pycolmap.Reconstruction, source: pycolmap.Reconstruction) -> list[int]:
    """Ids of the images registered in both models, ascending."""
    return sorted(target_id for target_id, _ in target.find_common_reg_image_ids(source))


def camera_points(rec: pycolmap.Reconstruction, image_ids: list[int]) -> np.ndarray | None:
    """Four points per camera that carry its pose: its centre and the points one unit along its x, y and z axes.

    The unit is the model's own spread of these camera centres (RMS distance from their
    mean), so the points of two models scale like the models and one similarity maps
    them onto each other.

    Args:
        rec: the model.
        image_ids: registered images of ``rec`` (N).

    Returns:
        the points (4N, 3), or ``None`` when the centres coincide (no scale).
    """
    poses = [rec.images[image_id].cam_from_world() for image_id in image_ids]
    rotations = np.stack([pose.rotation.matrix() for pose in poses])  # rows: the camera axes in the world
    centres = -np.einsum("nji,nj->ni", rotations, np.stack([pose.translation for pose in poses]))
    unit = float(np.sqrt(np.mean(np.sum((centres - centres.mean(0)) ** 2, axis=1))))
    if not unit > 1e-9 * max(1.0, float(np.abs(centres).max())):
        return None
    return np.concatenate([centres[:, None], centres[:, None] + unit * rotations], axis=1).reshape(-1, 3)


def sim3_from_shared_images(
    target: pycolmap.Reconstruction, source: pycolmap.Reconstruction, max_misfit: float = 0.1
) -> pycolmap.Sim3d | None:
    """The similarity ``target_from_source`` between two models' world frames, from the images they share.

    Least squares (Umeyama, ``pycolmap.estimate_sim3d``) over the :func:`camera_points`
    of every shared image, so two shared images are enough.

    Args:
        target: the model to map into.
        source: the model to map from.
        max_misfit: largest RMS distance of the mapped ``source`` points from the
            ``target`` points, in units of the target's spread of shared camera centres
            (about the angle in radians by which the models disagree on the cameras'
            relative poses); a worse fit gives ``None``.

    Returns:
        ``x_target = scale * R @ x_source + t``, or ``None`` with fewer than two shared
        images, shared cameras at one place, or a misfit above ``max_misfit``.
    """
    image_ids = shared_images(target, source)
    if len(image_ids) < 2:
        return None
    tgt, src = camera_points(target, image_ids), camera_points(source, image_ids)
    if tgt is None or src is None:
        return None
    sim = pycolmap.estimate_sim3d(src, tgt)
    if sim is None:
        return None
    mapped = src @ (sim.scale * sim.rotation.matrix()).T + sim.translation
    unit = np.linalg.norm(tgt[1::4] - tgt[0::4], axis=1).mean()
    misfit = float(np.sqrt(np.mean(np.sum((mapped - tgt) ** 2, axis=1)))) / unit
    if misfit > max_misfit:
        log.info("models disagree on their %d shared images (misfit %.3f > %.3f)", len(image_ids), misfit, max_misfit)
        return None
    return sim


def add_frames(target: pycolmap.Reconstruction, source: pycolmap.Reconstruction, sim: pycolmap.Sim3d) -> list[int]:
    """Register in ``target`` the frames registered in ``source`` only, with their poses mapped by ``sim``.

    Frames (and their cameras, rigs and images) that ``target`` lacks altogether are
    copied from ``source`` without 3D points; ``target``'s cameras are kept.  A frame's
    pose is its rig's: the offsets of a rig's cameras are not scaled (the rigs of
    :func:`lburst.sfm.colmap.write_database` hold one camera each).

    Args:
        target: the model to add to (changed in place).
        source: the model to take frames from.
        sim: ``target_from_source``.

    Returns:
        the ids of the frames registered.
    """
    added = []
    registered = set(target.reg_frame_ids())
    for frame_id in source.reg_frame_ids():
        if frame_id in registered:
            continue
        frame = source.frames[frame_id]
        pose = sim.transform_camera_world(frame.rig_from_world)
        if target.exists_frame(frame_id):
            target.frames[frame_id].rig_from_world = pose
        else:
            for image_id in frame.image_ids:
                camera_id = source.images[image_id.id].camera_id
                if not target.exists_camera(camera_id):
                    target.add_camera(source.cameras[camera_id])
            if not target.exists_rig(frame.rig_id):
                target.add_rig(source.rigs[frame.rig_id])
            new = pycolmap.Frame()
            new.frame_id, new.rig_id, new.rig_from_world = frame_id, frame.rig_id, pose
            for data_id in frame.data_ids:
                new.add_data_id(data_id)
            target.add_frame(new)
            for image_id in frame.image_ids:
                image = source.images[image_id.id]
                keypoints = np.array([p.xy for p in image.points2D], dtype=np.float64).reshape(-1, 2)
                copy = pycolmap.Image(
                    name=image.name, keypoints=keypoints, camera_id=image.camera_id, image_id=image.image_id
                )
                copy.frame_id = frame_id
                target.add_image(copy)
        target.register_frame(frame_id)
        added.append(frame_id)
    return added


def refine(
    rec: pycolmap.Reconstruction,
    db_path: str | Path,
    image_dir: str | Path,
    out_dir: str | Path,
    options: pycolmap.IncrementalPipelineOptions,
    rounds: int = 3,
) -> None:
    """Triangulate every 3D point afresh from the database's verified matches and run a global bundle adjustment.

    Rounds are repeated while they add observations: the first triangulation drops the
    observations that the less accurate poses of joined images reproject too far
    (``options.mapper.filter_max_reproj_error``); after the adjustment they fit again.

    Args:
        rec: the model (changed in place); its image ids must be the database's.
        db_path: the COLMAP database.
        image_dir: its image folder (must exist; colours are read from it).
        out_dir: where ``pycolmap.triangulate_points`` writes the model (made if missing).
        options: the mapper's options: triangulation, intrinsics refinement and threads.
        rounds: most rounds.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    ba = pycolmap.BundleAdjustmentOptions()
    ba.refine_focal_length = options.ba_refine_focal_length
    ba.refine_principal_point = options.ba_refine_principal_point
    ba.refine_extra_params = options.ba_refine_extra_params
    ba.print_summary = False
    ba.ceres.solver_options.num_threads = options.num_threads
    observations = 0
    for _ in range(rounds):
        pycolmap.triangulate_points(rec, str(db_path), str(image_dir), str(out_dir), clear_points=True, options=options)
        count = rec.compute_num_observations()
        if count == 0:
            break
        pycolmap.bundle_adjustment(rec, ba)
        if count <= observations:
            break
        observations = count
    rec.update_point_3d_errors()


def join_models(
    models: Iterable[pycolmap.Reconstruction],
    db_path: str | Path,
    image_dir: str | Path,
    work_dir: str | Path,
    options: pycolmap.IncrementalPipelineOptions,
    max_reprojection_error: float = 4.0,
    max_misfit: float = 0.1,
    rounds: int = 3,
    links: list[dict] | None = None,
) -> pycolmap.Reconstruction:
    """The largest model, joined with every other model that shares at least two registered images with it.

    Starting from a copy of the largest model, the other model sharing the most images
    is mapped into it (:func:`sim3_from_shared_images`) and its missing frames are
    registered (:func:`add_frames`), until no model shares two images; then the points and
    poses are refined (:func:`refine`).  One line is logged for a join.

    Args:
        models: the mapper's models of the database ``db_path``.
        db_path: the COLMAP database.
        image_dir: its image folder (must exist; colours are read from it).
        work_dir: a folder for the joined model (``work_dir/joined``).
        options: the mapper's options (triangulation, intrinsics refinement, threads).
        max_reprojection_error: largest mean reprojection error (px) of the joined model.
        max_misfit: see :func:`sim3_from_shared_images`.
        rounds: most rounds of :func:`refine`.
        links: when given, receives for each join of the returned model how it holds
            (:func:`join_links`: its new images and the 3D points they share with the rest).

    Returns:
        the joined model; the largest model itself (unchanged) when no model could be
        joined or the joined model is worse: fewer registered images, no 3D points, or a
        mean reprojection error above ``max_reprojection_error``.
    """
    models = sorted(models, key=lambda rec: rec.num_reg_images(), reverse=True)
    if not models:
        raise LBurstValueError("no model to join")
    largest, others = models[0], models[1:]
    joined = pycolmap.Reconstruction(largest)
    joins, added_frames = [], []
    while others:
        shared = [shared_images(joined, rec) for rec in others]
        best = int(np.argmax([len(ids) for ids in shared]))
        if len(shared[best]) < 2:
            break
        rec = others.pop(best)
        names = [joined.images[i].name for i in shared[best]]
        sim = sim3_from_shared_images(joined, rec, max_misfit)
        if sim is None or not (added := add_frames(joined, rec, sim)):
            continue
        joins.append(f"a model of {rec.num_reg_images()} images ({len(added)} new) through {', '.join(names)}")
        added_frames.append(added)
    if not joins:
        if len(models) > 1:
            log.info("kept the largest of %d models: no other could be aligned to it", len(models))
        return largest
    try:
        refine(joined, db_path, image_dir, Path(work_dir) / "joined", options, rounds)
    except (RuntimeError, ValueError) as err:  # pycolmap's failed checks that do not abort
        log.warning("kept the largest model: refining it joined with %s failed: %s", "; ".join(joins), err)
        return largest
    error = joined.compute_mean_reprojection_error() if joined.num_points3D() else float("inf")
    keep = joined.num_reg_images() >= largest.num_reg_images() and error <= max_reprojection_error
    log.info(
        "%s the largest model (%d images) with %s: %d images, %d points, %.2f px",
        "joined" if keep else "kept, not joined",
        largest.num_reg_images(),
        "; ".join(joins),
        joined.num_reg_images(),
        joined.num_points3D(),
        error,
    )
    if keep and links is not None:
        links.extend(join_links(joined, added_frames))
    return joined if keep else largest


def join_links(rec: pycolmap.Reconstruction, added: list[list[int]]) -> list[dict]:
    """For each join, the frames it ``added`` to ``rec``: how many images (``images``) and
    how many 3D points have images both among them and among the others (``points``): how
    firmly the join holds (a fold hangs on a handful)."""
    out = []
    for frames in added:
        ids = {data.id for frame_id in frames for data in rec.frames[frame_id].image_ids}
        points = 0
        for point in rec.points3D.values():
            inside = {element.image_id in ids for element in point.track.elements}
            points += inside == {True, False}
        out.append({"images": len(ids), "points": points})
    return out
