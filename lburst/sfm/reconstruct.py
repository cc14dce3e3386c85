"""``lburst reconstruct``: a scene of bursts to a 3D model with COLMAP, and its metrics.

Pipeline (:func:`reconstruct_scene`): features of each burst's common frame with any
method spec (cached in ``OUT/features/<name>.npz`` under the store's key, :func:`lburst.store.key`,
so an interrupted run resumes; features that ``lburst extract --out DIR`` stored for the same
burst by the same method are taken from ``DIR``, by default ``OUT``, and not computed again), the
common frames written as ``OUT/images/<name>.png`` for COLMAP, image pairs (exhaustive,
or sequential with an overlap for trajectories; a recording's keyframes, which are ordered
in time, always sequential plus retrieval loop candidates, see :func:`pair_plan`),
mutual-nearest-neighbour matching, then
COLMAP in a child process (:mod:`lburst.sfm.colmap`): database, geometric verification,
mapping; with ``progress`` a line on stderr tells each stage's seconds as it ends (matching,
then COLMAP's, :func:`lburst.sfm.colmap.run_job_subprocess`, with a line every
:data:`lburst.sfm.colmap.HEARTBEAT_SECONDS` while one runs long); the largest model is
written to ``OUT/colmap/model`` (binary) and
``OUT/colmap/model.ply``, and ``OUT/result.json`` holds the metrics
(:mod:`lburst.sfm.metrics`), the registered images and their poses.  Every input then leaves
the same files for other tools (:mod:`lburst.sfm.outputs`): hloc's ``features.h5``,
``matches.h5`` and ``pairs.txt``, ``trajectory.tum`` (and ``reference.tum``), ``report.md``.

Cameras: one COLMAP camera per image, as COLMAP does by default (a shared camera whose
intrinsics drift in bundle adjustment, as they do under forward motion, stops every later
registration), or with ``single_camera`` one for all images when their priors agree; by
default (``None``) a recording, which one camera shot, has one camera, a scene one per image
(without a ``meta.json`` camera, one estimated camera put the simulated flight's PNG frames at
0.201 m ATE, one per keyframe at 1.186 m: docs/recordings.md).
The prior is, by ``camera`` option: ``'auto'`` the scene's calibration when it has one (a
recording's ``meta.json`` camera, or ``reference.json`` cameras that are a calibration: see
:mod:`lburst.sfm.reference`), held fixed, else the focal length from EXIF when a single
image has one, else COLMAP's default ``SIMPLE_RADIAL`` with ``f = 1.2 * max(W, H)`` and a
centred principal point; ``'default'`` always the latter; ``'reference'`` the scene's
``reference.json`` cameras (refined too unless ``fix_intrinsics``).
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from lburst import store
from lburst.errors import LBurstError, LBurstValueError
from lburst.features import Features, check_features
from lburst.io import atomic_path, check_output_outside, file_sha1, read_features_npz
from lburst.sfm.outputs import IMAGES, write_common_frame, write_outputs, write_scene_times
from lburst.sfm.pairs import exhaustive_pairs, make_pairs
from lburst.sfm.scene import Scene, SceneError, exif_source, list_scene, load_item, reference_cameras
from lburst.sources import is_recording

AUTO_EXHAUSTIVE_MAX = 20  # pairs='auto' for a scene: exhaustive up to this many images, else sequential
SCENE_OVERLAP = 10  # sequential pairs of a scene: neighbours on each side
# A recording (keyframes in time order), pairs='auto': sequential pairs with this overlap,
# RECORDING_RETRIEVAL retrieval candidates per keyframe, the loop test (ColmapOptions.near)
# for every pair more than RECORDING_NEAR apart, and registration with at least
# RECORDING_ABS_POSE_INLIERS 2D-3D inliers; docs/recordings.md has the measurements.
RECORDING_OVERLAP = 2
RECORDING_NEAR = 2
RECORDING_RETRIEVAL = 5
LOOP_FRACTION = 0.4
RECORDING_ABS_POSE_INLIERS = 10
RESULT_FILE = "result.json"


class ReconstructionError(LBurstError, RuntimeError):
    """A scene that cannot be reconstructed (bad input); the message says which file and why."""


@dataclass
class ReconstructOptions:
    """How to reconstruct (see the module docstring).

    Attributes:
        pairs: ``'exhaustive'``, ``'sequential'`` (neighbours up to ``overlap`` apart) or
            ``'auto'`` (a scene: exhaustive up to 20 images, else sequential; a recording:
            always sequential, :func:`pair_plan`).
        overlap: sequential pairs' reach; ``None``: 10 for a scene, 2 for a recording.
        fallback_exhaustive: rerun with every pair when sequential pairs leave images out.
        camera, camera_model, single_camera, fix_intrinsics: cameras (module docstring).
        mapper: ``'incremental'`` or ``'global'``.
        num_threads, seed: for COLMAP (repeatable for one thread count).
        progress: tqdm bars, and a line on stderr per stage of matching and COLMAP with its seconds.
        extra: further :class:`lburst.sfm.colmap.ColmapOptions` fields, e.g. ``max_num_trials``.
        retrieval: with sequential pairs, also each image's this many most similar images
            farther apart (loop-closure candidates, :mod:`lburst.sfm.retrieval`); ``None``:
            5 for a recording, 0 for a scene.
        near: pairs more than this many images apart must also pass the loop test after
            COLMAP's verification (:func:`lburst.sfm.colmap.loop_test`); ``None``: 2 (at
            most the overlap) for a recording, 0 (no test) for a scene.
        loop_fraction: the loop test's fraction of the adjacent pairs' median inlier count.
        abs_pose_inliers: fewest 2D-3D inliers to register an image (incremental mapper);
            ``None``: 10 for a recording (its camera is one, usually calibrated, and the
            keyframes of a dark recording have few tracks), COLMAP's 30 for a scene.
        mapper_threads: threads of the mapper; ``None``: 1 for a recording (the only
            repeatable choice, :class:`lburst.sfm.colmap.ColmapOptions`), ``num_threads``
            for a scene.
        recording: :class:`lburst.sources.RecordingOptions` for a scene that is a
            recording (video or frame folder); ``None``: the defaults.
        matcher: matcher spec (:mod:`lburst.matching`): ``'mnn'`` (mutual nearest
            neighbours), ``'ratio'``, ``'ratio,ratio=0.9'``, ...
        features: a folder that ``lburst extract --out`` wrote: a burst's features stored
            there under the same key (:func:`lburst.store.key`: same method and burst) are
            used, not computed again; ``None``: the output folder.
    """

    pairs: str = "auto"
    overlap: int | None = None
    fallback_exhaustive: bool = False
    camera: str = "auto"
    camera_model: str = "SIMPLE_RADIAL"
    single_camera: bool | None = None
    fix_intrinsics: bool = False
    mapper: str = "incremental"
    num_threads: int = 2
    seed: int = 0
    progress: bool = True
    extra: dict = field(default_factory=dict)
    retrieval: int | None = None
    near: int | None = None
    loop_fraction: float = LOOP_FRACTION
    abs_pose_inliers: int | None = None
    mapper_threads: int | None = None
    recording: Any = None
    matcher: str = "mnn"
    features: str | Path | None = None


@dataclass
class ReconstructionResult:
    """One method on one scene.

    Attributes:
        scene, method, out_dir: what was run and where its files are.
        names: all images of the scene in trajectory order.
        registered: names of the images in the largest model.
        poses: name -> ``(R (3, 3), t (3,))`` world-to-camera (COLMAP convention, model's frame).
        cameras: name -> COLMAP camera dict of the registered images (as refined).
        metrics: the table's columns (:mod:`lburst.sfm.metrics`), reference ones included
            when the scene has a reference.
        error: why COLMAP failed, or ``None``.
        source_error: for a recording, why reading it stopped early (the keyframes read
            before it were reconstructed), or ``None``.
    """

    scene: str
    method: str
    out_dir: str
    names: list[str]
    registered: list[str] = field(default_factory=list)
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    cameras: dict[str, dict] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    source_error: str | None = None

    @property
    def converged(self) -> bool:
        return bool(self.metrics.get("converged"))

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data["poses"] = {
            n: {"R": np.asarray(R).tolist(), "t": np.asarray(t).tolist()} for n, (R, t) in self.poses.items()
        }
        return data

    def save(self, path: str | Path | None = None) -> Path:
        path = Path(path or Path(self.out_dir) / RESULT_FILE)
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(self.to_json(), indent=1))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "ReconstructionResult":
        data = json.loads(Path(path).read_text())
        data["poses"] = {n: (np.array(p["R"]), np.array(p["t"])) for n, p in data["poses"].items()}
        return cls(**data)

    def match_data(self) -> tuple[list[np.ndarray], np.ndarray, list[np.ndarray]] | None:
        """Keypoints (lburst convention) of every image, verified pairs (Q, 2) and their inliers, from ``out_dir``."""
        out = Path(self.out_dir)
        verified = out / "colmap" / "verified.npz"
        if not verified.is_file():
            return None
        keypoints = [read_features_npz(out / "features" / f"{name}.npz")["keypoints"] for name in self.names]
        data = np.load(verified)
        pairs = data["pairs"].reshape(-1, 2)
        return keypoints, pairs, [data[f"inl_{q}"] for q in range(len(pairs))]


def _safe_name(name: str) -> str:
    """``name`` if COLMAP can store it: no ``/``, not hidden, valid UTF-8."""
    if "/" in name or name.startswith(".") or not name.isprintable() or not _utf8(name):
        raise ReconstructionError(f"image name {name!r} cannot be used as a COLMAP image name (rename it)")
    return name


def _utf8(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def stored_paths(out: Path, name: str, extracted: Path | None, recording: Path | None = None) -> list[Path]:
    """Where the features of burst ``name`` may be stored: reconstruct's own cache
    ``OUT/features/<name>.npz``, then where ``lburst extract --out EXTRACTED`` puts them
    (``EXTRACTED/<name>.npz``; a recording's keyframe: ``EXTRACTED/<recording>/<name>.npz``)."""
    folder = out if extracted is None else Path(extracted)
    own = [out / "features" / f"{_safe_name(name)}.npz"]
    if recording is not None:
        recording = Path(os.path.abspath(recording))  # named as lburst extract names it
        stem = recording.stem if recording.is_file() else recording.name
        return own + [folder / stem / f"{name}.npz"]
    return own + [folder / f"{name}.npz"]


def scene_features(
    scene: Scene, spec: str, out: Path, progress: bool = True, extractor=None, extracted: Path | None = None
) -> list[Features]:
    """Features of each item's common frame (with their ``image_size`` (W, H)); writes
    ``out/images/<name>.png`` too.  Stored features under the same key
    (:func:`stored_paths`) are used, not computed again."""
    features = []
    method = store.method_key(spec)
    for item in tqdm(scene.items, desc=f"features {spec}", disable=not progress, leave=False):
        paths = stored_paths(out, item.name, extracted)
        cache = paths[0]
        image_path = out / IMAGES / f"{item.name}.png"
        key = store.key(method, item.path)  # the burst's content and the weights: no stale features
        cached = store.load(cache, key)
        if cached is not None and image_path.is_file() and cached[2].get("image_sha1") == file_sha1(image_path):
            features.append(cached[0])
            continue
        burst = load_item(item)
        write_common_frame(image_path, burst)
        found = cached or store.find(paths[1:], key)
        if found is None:
            if extractor is None:
                from lburst.methods import create

                extractor = create(spec)
            feats = check_features(extractor(burst))
        else:
            feats = found[0]
        store.save(cache, feats, (burst.shape[2], burst.shape[1]), key, image_sha1=file_sha1(image_path))
        features.append(store.load(cache, key)[0])  # as stored, so a rerun gives the same
    return features


def recording_features(
    path: str | Path, spec: str, out: Path, opts: ReconstructOptions, extractor=None
) -> tuple[Scene, list[Features], str | None]:
    """The keyframe scene of a recording (:mod:`lburst.sfm.recording`), the features of each
    keyframe (with their ``image_size`` (W, H)), and why reading stopped early (or ``None``).
    Features are stored as for bursts, under the store's key of the keyframe (the method,
    the recording's content and options, the keyframe's name: :func:`lburst.store.key`), the
    key ``lburst extract`` gives them too, so those it stored are used (:func:`stored_paths`)."""
    from lburst.io import BurstError
    from lburst.sfm import recording as rec
    from lburst.sources import RecordingOptions, open_recording

    try:
        recording = open_recording(path, opts.recording or RecordingOptions())
    except BurstError as err:
        raise ReconstructionError(str(err)) from err
    method, content = store.method_key(spec), store.recording_content(recording)

    def key(name: str) -> dict:
        return store.key(method, path, content, keyframe=name)

    def paths(name: str) -> list[Path]:
        return stored_paths(out, name, opts.features, Path(path))

    def cached(name: str) -> bool:
        return store.load(paths(name)[0], key(name)) is not None and (out / IMAGES / f"{name}.png").is_file()

    keyframes = rec.load_keyframes(out, store.key(method, path, content))
    error = None
    if keyframes is None or not all(cached(k.name) for k in keyframes):
        keyframes = []
        stream = rec.stream_keyframes(recording, cached, keyframes)
        try:
            for keyframe, burst in tqdm(stream, desc=f"keyframes {spec}", disable=not opts.progress, leave=False):
                if burst is None:
                    continue
                write_common_frame(out / IMAGES / f"{keyframe.name}.png", burst)
                found = store.find(paths(keyframe.name), key(keyframe.name))
                if found is None:
                    if extractor is None:
                        from lburst.methods import create

                        extractor = create(spec)
                    feats = check_features(extractor(burst))
                else:
                    feats = found[0]
                store.save(paths(keyframe.name)[0], feats, (burst.shape[2], burst.shape[1]), key(keyframe.name))
        except BurstError as err:
            error = str(err)
        rec.save_keyframes(out, store.key(method, path, content), recording, keyframes, error)
    features = [store.load(paths(k.name)[0], key(k.name))[0] for k in keyframes]
    return rec.keyframe_scene(recording, keyframes, out), features, error


def copy_reference(reference: Path | None, path: Path) -> None:
    """A scene's ``reference.json`` copied to ``path`` (``OUT/reference.json``, where a
    recording's is written), or none there when the scene has none."""
    if reference is None:
        path.unlink(missing_ok=True)
        return
    with atomic_path(path) as tmp:
        tmp.write_bytes(Path(reference).read_bytes())


def check_reference(path: Path) -> dict[str, dict]:
    """The cameras of a scene's ``reference.json`` after checking the whole file (poses and
    every camera against its COLMAP model), so that a bad one fails before COLMAP runs;
    ``ReconstructionError`` naming the file and the problem."""
    from lburst.sfm.colmap import check_camera
    from lburst.sfm.reference import Reference

    try:
        Reference.load(path)
        cameras = reference_cameras(path)
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        raise ReconstructionError(f"{path}: malformed reference file ({err})") from err
    for name, camera in cameras.items():
        try:
            check_camera(camera)
        except ValueError as err:
            raise ReconstructionError(f"{path}: camera of image {name!r}: {err}") from err
    return cameras


def calibrated_reference(scene: Scene) -> bool:
    """Whether the scene's ``reference.json`` cameras are a calibration (:class:`lburst.sfm.reference.Reference`)."""
    reference = scene.reference()
    return reference is not None and reference.is_calibration


def scene_cameras(
    scene: Scene, sizes: list[tuple[int, int]], options: ReconstructOptions
) -> tuple[list[dict], list[int]]:
    """COLMAP camera priors (distinct dicts) and the camera index of every image of size (W, H)
    ``sizes`` (module docstring)."""
    from lburst.sfm.colmap import default_camera, exif_camera

    if options.camera not in ("auto", "default", "reference"):
        raise ReconstructionError(f"unknown camera option {options.camera!r}: expected auto, default or reference")
    if options.camera == "reference" and scene.reference_path is None:
        raise ReconstructionError(f"{scene.root}: camera='reference' but the scene has no reference.json")
    ref_cams = None if scene.reference_path is None else check_reference(scene.reference_path)
    if options.camera == "default" or (options.camera == "auto" and not calibrated_reference(scene)):
        ref_cams = None
    priors = []
    for item, (w, h) in zip(scene.items, sizes):
        camera = None
        if ref_cams is not None:
            if item.name not in ref_cams:
                raise ReconstructionError(f"{scene.reference_path}: no camera for image {item.name!r}")
            camera = {**ref_cams[item.name], "prior_focal": True}
        elif options.camera == "auto" and scene.camera is not None:
            camera = {**scene.camera, "prior_focal": True}
        elif options.camera == "auto" and exif_source(item) is not None:
            camera = exif_camera(exif_source(item), options.camera_model)
        priors.append(camera or default_camera(w, h, options.camera_model))
    if options.single_camera and all(prior == priors[0] for prior in priors):
        return [priors[0]], [0] * len(priors)
    return priors, list(range(len(priors)))


def report_stage(line: str) -> None:
    """Print a stage line of ``lburst reconstruct`` on stderr, above any tqdm bar."""
    tqdm.write(line, file=sys.stderr)


def match_pairs_with_scores(
    features: list[Features], pairs: list[tuple[int, int]], progress: bool = True, matcher: str = "mnn"
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Matches (M, 2) of each pair and their scores (M,) (:func:`lburst.matching.match_with_scores`:
    descriptor similarity in [-1, 1]), by the matcher spec ``matcher``; with ``progress`` a
    bar, then a line with the seconds it took."""
    from lburst.matching import create, match_with_scores

    match = create(matcher)
    start = time.perf_counter()
    found = [
        match_with_scores(match, features[a], features[b])
        for a, b in tqdm(pairs, desc="matching", disable=not progress, leave=False)
    ]
    if progress:
        report_stage(f"matching ({len(pairs)} pairs, {matcher}): {time.perf_counter() - start:.1f} s")
    return [m for m, _ in found], [s for _, s in found]


def match_pairs(
    features: list[Features], pairs: list[tuple[int, int]], progress: bool = True, matcher: str = "mnn"
) -> list[np.ndarray]:
    """Matches (M, 2) of each pair, by the matcher spec ``matcher`` (mutual nearest neighbours by default)."""
    return match_pairs_with_scores(features, pairs, progress, matcher)[0]


@dataclass(frozen=True)
class PairPlan:
    """Which pairs to match and verify (:func:`pair_plan`)."""

    mode: str  # 'exhaustive' or 'sequential'
    overlap: int  # sequential pairs: images at most this far apart
    retrieval: int  # loop candidates per image (sequential only)
    near: int  # pairs farther apart than this must pass the loop test; 0: no test
    abs_pose_inliers: int  # incremental mapper: fewest 2D-3D inliers to register an image
    two_view_tracks: bool = False  # incremental mapper: triangulate tracks of two images too
    mapper_threads: int | None = None  # None: num_threads


def pair_plan(n: int, opts: ReconstructOptions, recording: bool) -> PairPlan:
    """The pairs of ``n`` images by ``opts``, with the defaults of a scene or a recording.

    A recording's keyframes are ordered in time, so ``pairs='auto'`` never means exhaustive
    for one: every pair of a short recording (15 keyframes) would be matched, and on dark
    noisy frames COLMAP verifies pairs of keyframes that share little of the view with as
    many inliers as the true ones (docs/recordings.md).  It gets sequential pairs
    (``RECORDING_OVERLAP``), ``RECORDING_RETRIEVAL`` retrieval candidates per keyframe,
    the loop test for every pair more than ``RECORDING_NEAR`` apart (the retrieval
    candidates, the far pairs of a larger ``overlap`` or of an explicit
    ``pairs='exhaustive'``), registration from ``RECORDING_ABS_POSE_INLIERS`` inliers, and
    triangulation of the tracks seen by two keyframes only (COLMAP ignores them; with
    sequential pairs most tracks of a dark recording are such, and without them the
    scale can drift along the chain), mapped with one thread (repeatable).  A scene keeps exhaustive pairs up to
    ``AUTO_EXHAUSTIVE_MAX`` images, sequential with overlap 10 beyond, no retrieval, no
    loop test, COLMAP's 30 and COLMAP's triangulation, unless the options say otherwise.
    """
    if opts.pairs not in ("auto", "exhaustive", "sequential"):
        raise LBurstValueError(f"unknown pairing {opts.pairs!r}: expected 'auto', 'exhaustive' or 'sequential'")
    if recording:
        mode = "sequential" if opts.pairs == "auto" else opts.pairs
        overlap = RECORDING_OVERLAP if opts.overlap is None else opts.overlap
        retrieval = RECORDING_RETRIEVAL if opts.retrieval is None else opts.retrieval
        near = min(RECORDING_NEAR, overlap) if opts.near is None else opts.near
    else:
        mode = opts.pairs if opts.pairs != "auto" else ("exhaustive" if n <= AUTO_EXHAUSTIVE_MAX else "sequential")
        overlap = SCENE_OVERLAP if opts.overlap is None else opts.overlap
        retrieval = opts.retrieval or 0
        near = opts.near or 0
    if overlap < 1:
        raise LBurstValueError(f"overlap must be at least 1, got {overlap}")
    default_abs = RECORDING_ABS_POSE_INLIERS if recording else 30
    abs_pose = default_abs if opts.abs_pose_inliers is None else opts.abs_pose_inliers
    mapper_threads = opts.mapper_threads if opts.mapper_threads is not None else (1 if recording else None)
    return PairPlan(
        mode, overlap, retrieval if mode == "sequential" else 0, max(near, 0), abs_pose, recording, mapper_threads
    )


def reconstruct_scene(
    scene_dir: str | Path, method_spec: str, out_dir: str | Path, extractor=None, **options: Any
) -> ReconstructionResult:
    """Reconstruct ``scene_dir`` with features ``method_spec``; files and ``result.json`` go to ``out_dir``.

    ``options`` are :class:`ReconstructOptions` fields.  ``extractor`` (optional) is used
    instead of creating one from the spec.  Raises :class:`ReconstructionError` for a
    scene that cannot be used (not a folder, no images, a single image, an unreadable
    burst); a COLMAP failure is returned as a result with ``error`` set.
    """
    from lburst.sfm.colmap import ColmapError, ColmapJob, ColmapOptions, run_job_subprocess
    from lburst.sfm.metrics import evaluate_against_reference, scene_metrics

    opts = ReconstructOptions(**options)
    if opts.single_camera is None:  # one camera shot a recording; a scene's photos may come from several
        opts = replace(opts, single_camera=is_recording(scene_dir, opts.recording))
    out = Path(out_dir)
    try:
        check_output_outside(out, [scene_dir])
    except ValueError as err:
        raise ReconstructionError(str(err)) from None
    if not _utf8(str(out.resolve())):
        raise ReconstructionError(f"{out!s}: the output path is not valid UTF-8, which COLMAP cannot use")
    source_error = None
    try:
        if is_recording(scene_dir, opts.recording):
            scene, features, source_error = recording_features(scene_dir, method_spec, out, opts, extractor)
            if source_error and len(scene.items) < 2:  # nothing to reconstruct: say why in result.json too
                out.mkdir(parents=True, exist_ok=True)
                ReconstructionResult(
                    str(scene_dir),
                    method_spec,
                    str(out),
                    scene.names,
                    error=f"{len(scene.items)} keyframe(s) read before the recording stopped; no model",
                    source_error=source_error,
                ).save()
                raise ReconstructionError(source_error)
        else:
            scene = list_scene(scene_dir)
        if len(scene.items) < 2:
            raise ReconstructionError(
                f"{scene_dir}: a reconstruction needs at least 2 images, found {len(scene.items)}"
            )
        if not is_recording(scene_dir, opts.recording):
            features = scene_features(scene, method_spec, out, opts.progress, extractor, opts.features)
            write_scene_times(out, str(scene_dir), scene.names)
            copy_reference(scene.reference_path, out / "reference.json")
        sizes = [(int(f["image_size"][0]), int(f["image_size"][1])) for f in features]
        cameras, camera_of_image = scene_cameras(scene, sizes, opts)
    except SceneError as err:
        raise ReconstructionError(str(err)) from err
    n = len(scene.items)
    plan = pair_plan(n, opts, is_recording(scene_dir, opts.recording))
    mode = plan.mode
    pairs = make_pairs(n, mode, plan.overlap)
    loop_candidates: set[tuple[int, int]] = set()
    if plan.retrieval and mode == "sequential":
        from lburst.sfm.retrieval import retrieval_pairs, vlad

        loops = retrieval_pairs(
            vlad([f["descriptors"] for f in features], seed=opts.seed), plan.retrieval, plan.overlap
        )
        loop_candidates = set(loops) - set(pairs)
        pairs = sorted(set(pairs) | loop_candidates)
    matches, scores = match_pairs_with_scores(features, pairs, opts.progress, opts.matcher)
    # a recording's meta.json camera, or a reference.json that is a calibration, is the
    # calibration: one camera, held fixed (refining it from dark frames moved the simulated
    # flight's ATE from 0.133 to 1.17 m, docs/recordings.md)
    calibrated = opts.camera == "auto" and (scene.camera is not None or calibrated_reference(scene))
    if calibrated and all(cam == cameras[0] for cam in cameras):
        cameras, camera_of_image = cameras[:1], [0] * n
    fixed = opts.fix_intrinsics or calibrated
    colmap_options = ColmapOptions(
        mapper=opts.mapper,
        num_threads=opts.num_threads,
        seed=opts.seed,
        refine_focal_length=not fixed,
        refine_extra_params=not fixed,
        **{
            "near": plan.near,
            "loop_inlier_fraction": opts.loop_fraction,
            "abs_pose_min_num_inliers": plan.abs_pose_inliers,
            "two_view_tracks": plan.two_view_tracks,
            "mapper_threads": plan.mapper_threads,
            **opts.extra,
        },
    )
    job = ColmapJob(scene.names, str((out / "images").resolve()), cameras, camera_of_image, colmap_options)
    job_dir = out / "colmap"
    job_dir.mkdir(parents=True, exist_ok=True)
    result = ReconstructionResult(str(scene.root), method_spec, str(out), scene.names, source_error=source_error)
    summary: dict = {"converged": False, "registered": {}, "num_points3D": 0}
    for attempt in range(2):
        job.save(job_dir / "job.json")
        with atomic_path(job_dir / "input.npz") as tmp:
            np.savez(
                tmp,
                pairs=np.array(pairs, dtype=np.int64).reshape(-1, 2),
                **{f"kp_{i}": f["keypoints"] for i, f in enumerate(features)},
                **{f"m_{p}": m for p, m in enumerate(matches)},
            )
        try:
            summary = run_job_subprocess(job_dir, report=report_stage if opts.progress else None)
            result.error = None
        except ColmapError as err:
            result.error = str(err)
        done = len(summary.get("registered", {})) == n
        if attempt or done or not opts.fallback_exhaustive or mode == "exhaustive":
            break
        extra = [p for p in exhaustive_pairs(n) if p not in set(pairs)]
        extra_matches, extra_scores = match_pairs_with_scores(features, extra, opts.progress, opts.matcher)
        pairs, matches, scores = pairs + extra, matches + extra_matches, scores + extra_scores
    verified = np.load(job_dir / "verified.npz") if (job_dir / "verified.npz").is_file() and not result.error else None
    inlier_counts = [len(verified[k]) for k in verified.files if k.startswith("inl_")] if verified is not None else []
    result.metrics = scene_metrics(
        n,
        [len(f["keypoints"]) for f in features],
        [len(m) for m in matches],
        inlier_counts,
        summary if not result.error else {},
    )
    result.metrics.update(
        pairs=len(pairs),
        pairing=mode if len(pairs) < n * (n - 1) // 2 else "exhaustive",
        overlap=plan.overlap if mode == "sequential" else None,
        loop_candidates=len(loop_candidates),
        matcher=opts.matcher,
    )
    if is_recording(scene_dir, opts.recording):  # where the intrinsics came from (result.json, report.md)
        result.metrics["camera"] = (
            "meta.json, held fixed"
            if calibrated
            else f"default prior held fixed ({'no meta.json camera' if scene.camera is None else '--camera'})"
            if fixed
            else f"estimated, {'one for all keyframes' if opts.single_camera else 'one per keyframe'} (no meta.json camera)"
            if scene.camera is None
            else f"estimated (meta.json camera not used: --camera {opts.camera})"
        )
    if plan.near and not result.error:
        result.metrics.update(
            near=plan.near,
            loop_threshold=summary.get("loop_threshold"),
            refused_pairs=len(summary.get("refused_pairs", [])),
            first_last_points3D=summary.get("first_last_points3D"),
        )
    for name, image in summary.get("registered", {}).items():
        result.registered.append(name)
        result.poses[name] = (np.array(image["R"]), np.array(image["t"]))
        result.cameras[name] = image["camera"]
    result.registered.sort(key=scene.names.index)
    if scene.reference_path is not None and not result.error:
        result.metrics.update(evaluate_against_reference(result, scene.reference_path))
    result.save()
    write_outputs(result, features, pairs, matches, scores)
    return result
