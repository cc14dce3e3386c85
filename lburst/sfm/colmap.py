"""The pycolmap (4.x) bridge: a COLMAP database from our features and matches, COLMAP's
geometric verification, mapping, and export of the largest model.

Everything that calls pycolmap runs in a child process (:func:`run_job` through
``python -m lburst.cli.colmap_job JOB_DIR``) because COLMAP aborts the whole process on some
inputs (failed ``CHECK``s); the parent reads the files the child leaves in ``JOB_DIR``:

- written by the parent: ``job.json`` (:class:`ColmapJob`) and ``input.npz`` with
  ``kp_<i>`` (K_i, 2) float32 keypoints of image ``i`` in lburst's convention (pixel
  centres at integer coordinates: +0.5 is added for COLMAP here, once), ``pairs``
  (P, 2) image indices and ``m_<p>`` (M_p, 2) keypoint indices of pair ``p``'s matches;
- written by the child: ``database.db``, ``verified.npz`` (``pairs`` (Q, 2) image
  indices, ``inl_<q>`` (M_q, 2) keypoint indices of the inlier matches COLMAP kept),
  ``model/`` (COLMAP binary model), ``model.ply`` and ``output.json``
  (:func:`summarize`: registered images with world-to-camera ``R``, ``t`` and camera;
  ``verify_seconds`` and ``map_seconds``, the wall time of verification and of the mapper),
  and ``stages.txt`` (:class:`StageLog`), each stage's start and end as it happens, which
  the parent reports while it waits (:func:`run_job_subprocess`).

Note: ``cv2`` is imported before ``pycolmap`` on purpose: importing pycolmap first makes
later PNG writes by OpenCV (or PIL) in the same process abort with ``free(): invalid
pointer`` (their bundled zlib/libpng clash).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, ContextManager, Iterator

import numpy as np

from lburst.camera_dict import check_camera  # noqa: F401  (re-exported: lburst.sfm.cameras, tests)
from lburst.errors import LBurstError, LBurstValueError
from lburst.extras import pycolmap  # imported on first use, after cv2 (see the module docstring)
from lburst.numbers import check_integer
from lburst.process import folder_lock
from lburst.sfm.join import join_models
from lburst.sfm.prior_alignment import align_to_priors
from lburst.sfm.trust import model_measures


def atomic_path(path: str | Path):
    """:func:`lburst.burst.io.atomic_path`, imported when first written (it loads OpenCV)."""
    from lburst.burst.io import atomic_path as _atomic_path

    return _atomic_path(path)


def opencv_path(path: str | Path) -> str:
    """:func:`lburst.burst.io.opencv_path`, imported when first used."""
    from lburst.burst.io import opencv_path as _opencv_path

    return _opencv_path(path)


DEFAULT_FOCAL_FACTOR = 1.2  # COLMAP's own default prior: f = 1.2 * max(W, H)
STAGE_FILE = "stages.txt"
HEARTBEAT_SECONDS = 10.0  # a stage that runs longer is reported as still running this often
POLL_SECONDS = 0.2  # how often the parent looks for new stage lines


class StageLog:
    """The child's record of its stages in ``job_dir/stages.txt``, one tab-separated line per
    event, written and flushed as it happens: ``start NAME`` and ``end NAME SECONDS``."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.write_text("")

    def _write(self, *fields: str) -> None:
        with open(self.path, "a") as f:
            f.write("\t".join(fields) + "\n")

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Record the block as stage ``name`` (its start, then its end with the seconds it took)."""
        self._write("start", name)
        start = time.perf_counter()
        yield
        self._write("end", name, f"{time.perf_counter() - start:.3f}")


def _stage(stages: StageLog | None, name: str) -> ContextManager[None]:
    """``stages.stage(name)``, or nothing without a log."""
    return stages.stage(name) if stages is not None else contextlib.nullcontext()


class StageReader:
    """The parent's side of :class:`StageLog`: :meth:`poll` reports each stage that ended as
    ``COLMAP NAME: SECONDS s``, and a stage that has run :data:`HEARTBEAT_SECONDS` since
    the last line as ``COLMAP NAME: running, N s so far``."""

    def __init__(self, path: str | Path, report: Callable[[str], None], clock: Callable[[], float] = time.monotonic):
        self.path = Path(path)
        self.report = report
        self.clock = clock
        self.offset = 0
        self.running: tuple[str, float] | None = None  # the stage under way and when it started
        self.last_line = clock()

    def poll(self) -> None:
        """Report what the log gained since the last call, or a heartbeat."""
        for fields in self._new_lines():
            if fields[0] == "start" and len(fields) == 2:
                self.running = (fields[1], self.clock())
            elif fields[0] == "end" and len(fields) == 3:
                self.running = None
                self._say(f"COLMAP {fields[1]}: {float(fields[2]):.1f} s")
        if self.running is not None and self.clock() - self.last_line >= HEARTBEAT_SECONDS:
            name, start = self.running
            self._say(f"COLMAP {name}: running, {self.clock() - start:.0f} s so far")

    def _say(self, line: str) -> None:
        self.report(line)
        self.last_line = self.clock()

    def _new_lines(self) -> list[list[str]]:
        """The complete lines written since the last call, split into fields."""
        try:
            with open(self.path, "rb") as f:
                f.seek(self.offset)
                data = f.read()
        except FileNotFoundError:
            return []
        complete = data[: data.rfind(b"\n") + 1]
        self.offset += len(complete)
        return [line.split("\t") for line in complete.decode(errors="replace").splitlines() if line]


class ColmapError(LBurstError, RuntimeError):
    """COLMAP failed (or aborted); the message says how, with the end of its log."""


#: threads of COLMAP's verification and mapping, and of ``lburst reconstruct`` and ``lburst bench
#: reconstruction``, unless given (a shared machine; a run is repeatable for one thread count)
DEFAULT_THREADS = 2


@dataclass
class ColmapOptions:
    """Verification and mapping settings (COLMAP defaults unless noted).

    Attributes:
        mapper: ``'incremental'`` (COLMAP) or ``'global'`` (GLOMAP, built into pycolmap 4.x).
        num_threads: threads for verification and mapping (:data:`DEFAULT_THREADS`).
        seed: seed of RANSAC and of the mapper (runs are repeatable).
        min_num_inliers: fewest inliers for a verified pair (COLMAP: 15).
        max_error: RANSAC epipolar error threshold in pixels (COLMAP: 4).
        max_num_trials: most RANSAC trials per model in verification (COLMAP: 10000; with
            mutual-NN matches, which keep many outliers, this bound sets the run time).
        min_model_size: fewest registered images for a model to be kept (3; COLMAP's 10
            would drop every model of a small scene).
        refine_focal_length, refine_extra_params: bundle adjustment of the intrinsics.
        near: pairs of images more than this far apart in image order (a recording's
            keyframes: time) are loop candidates, kept after verification only when they
            pass :func:`loop_test`; 0: every verified pair is kept (COLMAP's behaviour).
        loop_inlier_fraction: a loop candidate needs at least this fraction of the median
            inlier count of the adjacent pairs (images 1 apart).
        abs_pose_min_num_inliers: fewest 2D-3D inliers to register an image in incremental
            mapping (COLMAP: 30).
        two_view_tracks: incremental mapping triangulates tracks seen by two images only
            (COLMAP ignores them).  With sequential pairs of dark keyframes most tracks
            are two-view; without them too few points hold the scale and the trajectory
            can shrink along the chain.
        mapper_threads: threads of the mapper; ``None``: ``num_threads``.  Only one thread
            makes incremental mapping repeatable (docs/recordings.md).
        join_models: when incremental mapping splits the images into several models, join
            to the largest those sharing at least two registered images with it
            (:func:`lburst.sfm.join.join_models`: a similarity from the shared camera poses,
            then triangulation and bundle adjustment); the largest model alone is kept
            when the joined one is worse (a dark looping flight can split into two models that
            share too few 3D points for COLMAP's own alignments).
        mapper_attempts: most runs of the mapper while its model leaves images unregistered
            (:func:`map_database`): with one camera per photo, whose focal length and
            distortion the mapper must find, a first model of a small photo set can keep only a
            few of its images (docs/results/reconstruction.md).
    """

    mapper: str = "incremental"
    num_threads: int = DEFAULT_THREADS
    seed: int = 0
    min_num_inliers: int = 15
    max_error: float = 4.0
    max_num_trials: int = 10000
    min_model_size: int = 3
    refine_focal_length: bool = True
    refine_extra_params: bool = True
    near: int = 0
    loop_inlier_fraction: float = 0.4
    abs_pose_min_num_inliers: int = 30
    two_view_tracks: bool = False
    mapper_threads: int | None = None
    join_models: bool = True
    mapper_attempts: int = 3

    def __post_init__(self) -> None:
        self.mapper_attempts = check_integer(self.mapper_attempts, "mapper_attempts", 1, 100)


@dataclass
class ColmapJob:
    """What the child process is asked to do (saved as ``job.json``).

    ``cameras`` are COLMAP camera dicts ``{model, width, height, params, prior_focal}``;
    image ``i`` (named ``names[i]``, stored as ``names[i] + '.png'`` in ``image_dir``)
    uses camera ``camera_of_image[i]``.  ``positions``: each image's prior camera centre
    ``[X, Y, Z]`` (m) or ``None`` (:mod:`lburst.sfm.positions`), held in bundle adjustment
    with a standard deviation of ``position_std`` m per coordinate; ``None``: no priors.
    """

    names: list[str]
    image_dir: str
    cameras: list[dict]
    camera_of_image: list[int]
    options: ColmapOptions = field(default_factory=ColmapOptions)
    positions: list[list[float] | None] | None = None
    position_std: float = 2.0

    def save(self, path: Path) -> None:
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(asdict(self), indent=1))

    @classmethod
    def load(cls, path: Path) -> "ColmapJob":
        data = json.loads(Path(path).read_text())
        data["options"] = ColmapOptions(**data["options"])
        return cls(**data)


def image_file(name: str) -> str:
    """File name of image ``name`` in the COLMAP image folder."""
    return f"{name}.png"


def camera_params(model: str, width: int, height: int, focal: float) -> list[float]:
    """Parameters of a COLMAP camera ``model`` with focal ``focal``, centred principal point, no distortion."""
    cx, cy = width / 2.0, height / 2.0
    params = {
        "SIMPLE_PINHOLE": [focal, cx, cy],
        "PINHOLE": [focal, focal, cx, cy],
        "SIMPLE_RADIAL": [focal, cx, cy, 0.0],
        "RADIAL": [focal, cx, cy, 0.0, 0.0],
        "OPENCV": [focal, focal, cx, cy, 0.0, 0.0, 0.0, 0.0],
    }
    if model not in params:
        raise LBurstValueError(f"unsupported camera model {model!r}; use one of {', '.join(params)}")
    return params[model]


def default_camera(width: int, height: int, model: str = "SIMPLE_RADIAL", focal: float | None = None) -> dict:
    """A camera dict; without ``focal``, COLMAP's default prior ``f = 1.2 * max(W, H)`` (not trusted)."""
    f = DEFAULT_FOCAL_FACTOR * max(width, height) if focal is None else focal
    return {
        "model": model,
        "width": int(width),
        "height": int(height),
        "params": camera_params(model, width, height, f),
        "prior_focal": focal is not None,
    }


def exif_camera(path: str | Path, model: str = "SIMPLE_RADIAL") -> dict | None:
    """Camera dict with the focal length from the image's EXIF (COLMAP's sensor database), or ``None``."""
    camera = pycolmap.infer_camera_from_image(opencv_path(path))
    if not camera.has_prior_focal_length:
        return None
    return default_camera(camera.width, camera.height, model, focal=float(camera.focal_length))


def _pycolmap_camera(camera: dict) -> pycolmap.Camera:
    cam = pycolmap.Camera.create_from_model_name(0, camera["model"], 1.0, int(camera["width"]), int(camera["height"]))
    cam.params = np.asarray(camera["params"], dtype=np.float64)
    cam.has_prior_focal_length = bool(camera.get("prior_focal", False))
    return cam


def write_database(
    db_path: str | Path, job: ColmapJob, keypoints: list[np.ndarray], pairs: np.ndarray, matches: list[np.ndarray]
) -> list[int]:
    """Create ``db_path`` afresh with the job's cameras, one rig and frame per image, keypoints and matches.

    ``keypoints[i]`` (K_i, 2) are in lburst's convention and stored +0.5 (COLMAP's);
    ``matches[p]`` (M_p, 2) index the keypoints of images ``pairs[p]``.  Returns the
    database image id of each image.  Raises ``ValueError`` for malformed input
    (pycolmap would abort the process on it).
    """
    db_path = Path(db_path)
    if len(keypoints) != len(job.names) or len(pairs) != len(matches):
        raise LBurstValueError("one keypoint array per image and one match array per pair are needed")
    for i, kp in enumerate(keypoints):
        if kp.ndim != 2 or kp.shape[1] != 2:
            raise LBurstValueError(f"keypoints of {job.names[i]!r} must be (K, 2), got {kp.shape}")
    for (a, b), m in zip(pairs, matches):
        if m.ndim != 2 or m.shape[1] != 2:
            raise LBurstValueError(f"matches of pair {a, b} must be (M, 2), got {m.shape}")
        if len(m) and (m.min() < 0 or m[:, 0].max() >= len(keypoints[a]) or m[:, 1].max() >= len(keypoints[b])):
            raise LBurstValueError(f"matches of pair {job.names[a]!r}-{job.names[b]!r} index missing keypoints")
    for suffix in ("", "-wal", "-shm"):
        Path(str(db_path) + suffix).unlink(missing_ok=True)
    image_ids: list[int] = []
    with pycolmap.Database.open(str(db_path)) as db:
        camera_ids, rig_ids = [], []
        for camera in job.cameras:
            cam = _pycolmap_camera(camera)
            cam.camera_id = db.write_camera(cam)
            rig = pycolmap.Rig()
            rig.add_ref_sensor(cam.sensor_id)
            camera_ids.append(cam.camera_id)
            rig_ids.append(db.write_rig(rig))
        positions = job.positions or [None] * len(job.names)
        for name, cam_index, kp, position in zip(job.names, job.camera_of_image, keypoints, positions):
            image = pycolmap.Image(name=image_file(name), camera_id=camera_ids[cam_index])
            image.image_id = db.write_image(image)
            frame = pycolmap.Frame()
            frame.rig_id = rig_ids[cam_index]
            frame.add_data_id(image.data_id)
            db.write_frame(frame)
            db.write_keypoints(image.image_id, np.ascontiguousarray(kp, dtype=np.float32) + np.float32(0.5))
            image_ids.append(image.image_id)
            if position is not None:
                db.write_pose_prior(_position_prior(image.data_id, position, job.position_std))
        for (a, b), m in zip(pairs, matches):
            db.write_matches(image_ids[a], image_ids[b], np.ascontiguousarray(m, dtype=np.uint32))
    return image_ids


def _position_prior(data_id, position: list[float], std: float) -> pycolmap.PosePrior:
    """COLMAP's prior of an image's centre (Cartesian, metres), ``std`` m on each coordinate."""
    return pycolmap.PosePrior(
        corr_data_id=data_id,
        position=np.asarray(position, dtype=np.float64),
        position_covariance=np.eye(3) * float(std) ** 2,
        coordinate_system=pycolmap.PosePriorCoordinateSystem.CARTESIAN,
    )


def verify(db_path: str | Path, options: ColmapOptions) -> None:
    """COLMAP's geometric verification of every matched pair in the database (E, F or H with RANSAC)."""
    two_view = pycolmap.TwoViewGeometryOptions()
    two_view.min_num_inliers = options.min_num_inliers
    two_view.ransac.max_error = options.max_error
    two_view.ransac.random_seed = options.seed
    two_view.ransac.max_num_trials = options.max_num_trials
    verifier = pycolmap.GeometricVerifierOptions()
    verifier.num_threads = options.num_threads
    pycolmap.geometric_verification(str(db_path), verifier_options=verifier, two_view_geometry_options=two_view)


def read_inliers(db_path: str | Path, image_ids: list[int]) -> tuple[np.ndarray, list[np.ndarray]]:
    """Verified pairs (Q, 2) as image indices ``a < b`` and their inlier keypoint index pairs (M_q, 2)."""
    index = {image_id: i for i, image_id in enumerate(image_ids)}
    pairs, inliers = [], []
    with pycolmap.Database.open(str(db_path)) as db:
        pair_ids, geometries = db.read_two_view_geometries()
    for pair_id, geometry in zip(pair_ids, geometries):
        id1, id2 = pycolmap.pair_id_to_image_pair(pair_id)
        m = np.asarray(geometry.inlier_matches, dtype=np.int64).reshape(-1, 2)
        a, b = index[id1], index[id2]
        if a > b:
            a, b, m = b, a, m[:, ::-1]
        if len(m):
            pairs.append((a, b))
            inliers.append(np.ascontiguousarray(m))
    return np.array(pairs, dtype=np.int64).reshape(-1, 2), inliers


def loop_test(
    pairs: np.ndarray, inlier_counts, near: int, fraction: float, min_inliers: int = 0
) -> tuple[np.ndarray, float]:
    """Which verified pairs ``(a, b)`` (image indices in trajectory order) to keep: all those
    at most ``near`` apart, and farther ones (loop candidates) with at least ``threshold``
    inliers; returns ``(keep (Q,) bool, threshold)``.

    ``threshold`` is ``fraction`` times the median inlier count of the adjacent pairs
    (``b - a == 1``; without one, of the pairs at most ``near`` apart), and at least
    ``min_inliers``; with no such pair at all no loop candidate is kept.  COLMAP's own
    test (a fixed count, 15) is too weak on noisy matches: images that share little or
    nothing of the view still give 20-50 inliers that fit one epipolar geometry, as many
    as true pairs farther apart, while the neighbours of a recording, which share most
    of the view, give several times more.  ``near`` 0: everything is kept.
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    counts = np.asarray(inlier_counts, dtype=np.float64).reshape(-1)
    if near < 1:
        return np.ones(len(pairs), bool), 0.0
    gap = pairs[:, 1] - pairs[:, 0]
    reference = counts[gap == 1] if (gap == 1).any() else counts[gap <= near]
    threshold = max(float(min_inliers), fraction * float(np.median(reference))) if len(reference) else np.inf
    return (gap <= near) | (counts >= threshold), threshold


def refuse_pairs(db_path: str | Path, image_ids: list[int], pairs: np.ndarray) -> None:
    """Delete the two-view geometries of ``pairs`` (image indices) from the database, so the mapper does not use them."""
    with pycolmap.Database.open(str(db_path)) as db:
        for a, b in np.asarray(pairs).reshape(-1, 2):
            db.delete_two_view_geometry(image_ids[a], image_ids[b])


#: how far apart the seeds of a mapper's further attempts are (:attr:`ColmapOptions.mapper_attempts`)
ATTEMPT_SEED_STEP = 10007


def map_database(
    db_path: str | Path,
    image_dir: str | Path,
    work_dir: str | Path,
    options: ColmapOptions,
    stages: StageLog | None = None,
    use_priors: bool = False,
    joins: list[dict] | None = None,
) -> pycolmap.Reconstruction | None:
    """Run the mapper; return the model with the most registered images (joined with the
    others where ``options.join_models`` says so), or ``None`` if none.  ``stages``: where
    to record the mapping and the joining as stages.  ``use_priors``: the incremental mapper
    holds the cameras near the database's position priors in bundle adjustment and returns
    the model in their frame (the global mapper does not take them: refused).  ``joins``:
    when given, receives how each join of the returned model holds
    (:func:`lburst.sfm.join.join_links`).

    While the model leaves images of the database unregistered, the mapper runs again, up to
    ``options.mapper_attempts`` runs in all, with seed ``seed + k * ATTEMPT_SEED_STEP`` for the
    k-th further run (in ``work_dir/attempt<k>``), and the model with the most registered
    images, then the most 3D points, is kept: the choice reads nothing but the models."""
    with pycolmap.Database.open(str(db_path)) as db:
        total = db.num_images()
    best, best_joins, label = None, [], ""
    for attempt in range(options.mapper_attempts):
        run, folder = options, Path(work_dir)
        if attempt:
            run = replace(options, seed=options.seed + attempt * ATTEMPT_SEED_STEP)
            folder = folder / f"attempt{attempt}"
            registered = 0 if best is None else best.num_reg_images()
            label = f", again: {registered} of {total} images registered, seed {run.seed}"
        links: list[dict] = []
        model = _map_once(db_path, image_dir, folder, run, stages, use_priors, label, joins=links)
        if model is not None and (best is None or _size(model) > _size(best)):
            best, best_joins = model, links
        if best is not None and best.num_reg_images() >= total:
            break
    if joins is not None:
        joins.extend(best_joins)
    return best


def _size(model: pycolmap.Reconstruction) -> tuple[int, int]:
    """What :func:`map_database` ranks its attempts' models by."""
    return model.num_reg_images(), model.num_points3D()


def _map_once(
    db_path: str | Path,
    image_dir: str | Path,
    work_dir: str | Path,
    options: ColmapOptions,
    stages: StageLog | None,
    use_priors: bool,
    label: str = "",
    joins: list[dict] | None = None,
) -> pycolmap.Reconstruction | None:
    """One run of the mapper (:func:`map_database`); ``label`` ends its stages' names,
    ``joins`` receives how its joins hold."""
    pycolmap.set_random_seed(options.seed)
    threads = options.num_threads if options.mapper_threads is None else options.mapper_threads
    work_dir = Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    if options.mapper == "incremental":
        opts = pycolmap.IncrementalPipelineOptions()
        opts.num_threads = threads
        opts.random_seed = options.seed
        opts.min_model_size = options.min_model_size
        opts.mapper.abs_pose_min_num_inliers = options.abs_pose_min_num_inliers
        opts.triangulation.ignore_two_view_tracks = not options.two_view_tracks
        opts.ba_refine_focal_length = options.refine_focal_length
        opts.ba_refine_extra_params = options.refine_extra_params
        opts.use_prior_position = use_priors
        with _stage(stages, f"mapping (incremental, with bundle adjustment){label}"):
            models = pycolmap.incremental_mapping(str(db_path), str(image_dir), str(work_dir), opts)
        if len(models) > 1 and options.join_models:
            with _stage(stages, f"joining {len(models)} models (triangulation, bundle adjustment){label}"):
                return join_models(models.values(), db_path, image_dir, work_dir, opts, links=joins)
    elif options.mapper == "global":
        if use_priors:
            raise LBurstValueError("position priors need the incremental mapper (--mapper incremental)")
        opts = pycolmap.GlobalPipelineOptions()
        opts.num_threads = threads
        opts.random_seed = options.seed
        opts.min_model_size = options.min_model_size
        opts.mapper.bundle_adjustment.refine_focal_length = options.refine_focal_length
        opts.mapper.bundle_adjustment.refine_extra_params = options.refine_extra_params
        with _stage(stages, f"mapping (global, with bundle adjustment){label}"):
            models = pycolmap.global_mapping(str(db_path), str(image_dir), str(work_dir), opts)
    else:
        raise LBurstValueError(f"unknown mapper {options.mapper!r}: expected 'incremental' or 'global'")
    if not models:
        return None
    return max(models.values(), key=lambda rec: rec.num_reg_images())


def summarize(rec: pycolmap.Reconstruction | None) -> dict:
    """JSON-ready summary: registered images (name without suffix -> R, t world-to-camera, camera) and model statistics."""
    if rec is None:
        return {"converged": False, "registered": {}, "num_points3D": 0}
    registered = {}
    for image_id in rec.reg_image_ids():
        image = rec.images[image_id]
        pose = image.cam_from_world()
        camera = rec.cameras[image.camera_id]
        registered[Path(image.name).stem] = {
            "R": pose.rotation.matrix().tolist(),
            "t": np.asarray(pose.translation).tolist(),
            "camera": {
                "model": camera.model.name,
                "width": camera.width,
                "height": camera.height,
                "params": np.asarray(camera.params).tolist(),
            },
            "num_points3D": int(image.num_points3D),
        }
    return {
        "converged": True,
        "registered": registered,
        "num_points3D": int(rec.num_points3D()),
        "num_observations": int(rec.compute_num_observations()),
        "mean_track_length": float(rec.compute_mean_track_length()) if rec.num_points3D() else 0.0,
        "mean_reprojection_error": float(rec.compute_mean_reprojection_error()) if rec.num_points3D() else 0.0,
    }


def shared_points3D(rec: pycolmap.Reconstruction | None, name_a: str, name_b: str) -> int | None:
    """3D points of ``rec`` whose tracks hold both images (names without suffix), ``None`` when
    either is not registered: how a loop's two ends are tied in the model, directly or through
    the images between."""
    if rec is None:
        return None
    ids = {Path(rec.images[image_id].name).stem: image_id for image_id in rec.reg_image_ids()}
    if name_a not in ids or name_b not in ids:
        return None
    a, b = ids[name_a], ids[name_b]
    return sum(1 for point in rec.points3D.values() if {a, b} <= {element.image_id for element in point.track.elements})


def export_model(rec: pycolmap.Reconstruction, job_dir: Path) -> None:
    """Write ``job_dir/model`` (COLMAP binary) and ``job_dir/model.ply`` (the 3D points), replacing old ones."""
    tmp = job_dir / "model.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    rec.write_binary(str(tmp))
    shutil.rmtree(job_dir / "model", ignore_errors=True)
    tmp.rename(job_dir / "model")
    with atomic_path(job_dir / "model.ply") as ply:
        rec.export_PLY(str(ply))


def run_job(job_dir: str | Path) -> dict:
    """Do the job of ``job_dir`` in this process (see the module docstring); return the summary."""
    job_dir = Path(job_dir)
    job = ColmapJob.load(job_dir / "job.json")
    data = np.load(job_dir / "input.npz")
    keypoints = [data[f"kp_{i}"] for i in range(len(job.names))]
    pairs = data["pairs"].reshape(-1, 2)
    matches = [data[f"m_{p}"] for p in range(len(pairs))]
    db_path = job_dir / "database.db"
    stages = StageLog(job_dir / STAGE_FILE)
    with stages.stage(f"feature and match import ({len(job.names)} images, {len(pairs)} pairs)"):
        image_ids = write_database(db_path, job, keypoints, pairs, matches)
    with stages.stage("geometric verification"):
        start = time.perf_counter()
        verify(db_path, job.options)
        verified = time.perf_counter()
        v_pairs, inliers = read_inliers(db_path, image_ids)
        keep, threshold = loop_test(
            v_pairs,
            [len(m) for m in inliers],
            job.options.near,
            job.options.loop_inlier_fraction,
            job.options.min_num_inliers,
        )
        refused = v_pairs[~keep]
        refused_counts = np.array([len(m) for m, k in zip(inliers, keep) if not k], dtype=np.int64)
        if len(refused):
            refuse_pairs(db_path, image_ids, refused)
    v_pairs, inliers = v_pairs[keep], [m for m, k in zip(inliers, keep) if k]
    with atomic_path(job_dir / "verified.npz") as tmp:
        np.savez(
            tmp,
            pairs=v_pairs,
            refused=refused,
            refused_inliers=refused_counts,
            **{f"inl_{q}": m for q, m in enumerate(inliers)},
        )
    mapping = time.perf_counter()
    priors = job.positions is not None and any(p is not None for p in job.positions)
    joins: list[dict] = []
    rec = (
        map_database(db_path, job.image_dir, job_dir / "mapper", job.options, stages, priors, joins)
        if len(v_pairs)
        else None
    )
    mapped = time.perf_counter()
    alignment = align_to_priors(rec, job.names, job.positions) if rec is not None and priors else None
    if rec is not None:
        with stages.stage("export"):
            export_model(rec, job_dir)
    summary = summarize(rec)
    if rec is not None:  # what lburst.sfm.trust.assess reads besides the summary
        summary.update(model_measures(rec, job.names), joins=joins)
    summary["prior_alignment"] = alignment
    summary["first_last_points3D"] = shared_points3D(rec, job.names[0], job.names[-1])
    summary.update(verify_seconds=round(verified - start, 3), map_seconds=round(mapped - mapping, 3))
    if job.options.near:
        summary.update(loop_threshold=threshold if np.isfinite(threshold) else None, refused_pairs=refused.tolist())
    with atomic_path(job_dir / "output.json") as tmp:
        tmp.write_text(json.dumps(summary))
    return summary


def _wait(proc: subprocess.Popen, timeout: float | None, reader: StageReader | None) -> None:
    """Wait for ``proc``, polling ``reader`` meanwhile; ``subprocess.TimeoutExpired`` after ``timeout`` s."""
    deadline = None if timeout is None else time.monotonic() + timeout
    while True:
        wait = POLL_SECONDS if deadline is None else min(POLL_SECONDS, max(deadline - time.monotonic(), 0))
        try:
            proc.wait(timeout=wait)
            break
        except subprocess.TimeoutExpired:
            if reader is not None:
                reader.poll()
            if deadline is not None and time.monotonic() >= deadline:
                raise
    if reader is not None:
        reader.poll()


def run_job_subprocess(
    job_dir: str | Path, timeout: float | None = None, report: Callable[[str], None] | None = None
) -> dict:
    """Run :func:`run_job` in a child Python process (COLMAP's log goes to ``job_dir/colmap.log``).

    ``report``: called with a line as each stage ends (:class:`StageReader`: the feature
    import, the geometric verification, the mapping with its bundle adjustments, any
    joining of models, the export, each with its seconds), and every
    :data:`HEARTBEAT_SECONDS` while a stage runs on.  Raises ``ColmapError`` with the end of
    the log when the child fails or aborts.
    """
    job_dir = Path(job_dir)
    with folder_lock(job_dir):  # one COLMAP per job folder; the child dies with this process
        (job_dir / "output.json").unlink(missing_ok=True)
        (job_dir / STAGE_FILE).unlink(missing_ok=True)
        log_path = job_dir / "colmap.log"
        reader = StageReader(job_dir / STAGE_FILE, report) if report is not None else None
        with open(log_path, "w") as log:
            proc = subprocess.Popen(
                [sys.executable, "-m", "lburst.cli.colmap_job", str(job_dir), "--parent", str(os.getpid())],
                stdout=log,
                stderr=subprocess.STDOUT,
            )
            try:
                _wait(proc, timeout, reader)
            except subprocess.TimeoutExpired as err:
                raise ColmapError(f"COLMAP did not finish in {timeout} s (log: {log_path})") from err
            finally:
                if proc.poll() is None:  # timed out or interrupted: the child goes too
                    proc.kill()
                    proc.wait()
        if proc.returncode != 0 or not (job_dir / "output.json").is_file():
            how = (
                f"was killed by signal {-proc.returncode}" if proc.returncode < 0 else f"exited with {proc.returncode}"
            )
            raise ColmapError(
                f"COLMAP {how} (log: {log_path}):\n{failure_summary(log_path.read_text(errors='replace'))}"
            )
        return json.loads((job_dir / "output.json").read_text())


def failure_summary(log: str, lines: int = 8) -> str:
    """What a failed COLMAP log says went wrong: its ``Check failed:`` line (without glog's
    prefix) and the message after it, else its last Python error, else its last ``lines`` lines."""
    rows = log.splitlines()
    for i, row in enumerate(rows):
        if "Check failed" in row:
            text = row[row.index("Check failed") :]
            following = rows[i + 1].strip() if i + 1 < len(rows) else ""
            return text if not following or following.startswith("***") else f"{text} {following}"
    errors = [row for row in rows if re.match(r"^[A-Za-z_.]*(Error|Exception)\b", row)]
    return errors[-1] if errors else "\n".join(rows[-lines:])
