"""``lburst reconstruct``: a scene of bursts to a 3D model with COLMAP, and its metrics.

Pipeline (:func:`reconstruct_scene`, options :class:`lburst.sfm.options.ReconstructOptions`):
the input, a scene or a recording, opened once (:mod:`lburst.sfm.inputs`: no other stage
asks which it is), the features of each burst's common frame with any method spec, and the
common frames written as ``OUT/images/<name>.png`` for COLMAP (:mod:`lburst.sfm.feature_stage`), the cameras
(:mod:`lburst.sfm.cameras`), image pairs (exhaustive, or sequential with an overlap for
trajectories; a recording's keyframes, which are ordered in time, always sequential plus
retrieval loop candidates, see :func:`lburst.sfm.pairs.pair_plan`), matching
(:mod:`lburst.sfm.match`), then COLMAP in a child process (:mod:`lburst.sfm.colmap`):
database, geometric verification, mapping; with ``progress`` a line on stderr tells each
stage's seconds as it ends (matching, then COLMAP's,
:func:`lburst.sfm.colmap.run_job_subprocess`, with a line every
:data:`lburst.sfm.colmap.HEARTBEAT_SECONDS` while one runs long); the largest model is
written to ``OUT/colmap/model`` (binary) and ``OUT/colmap/model.ply``, and
``OUT/result.json`` (:class:`lburst.sfm.result.ReconstructionResult`) holds the status,
the metrics (:mod:`lburst.sfm.metrics`), the registered images and their poses.  Every
input then leaves the same files for other tools (:mod:`lburst.sfm.outputs`): hloc's
``features.h5``, ``matches.h5`` and ``pairs.txt``, ``trajectory.tum`` (and
``reference.tum``), ``report.md``.  With ``options.cluster`` the features and matching
stages run on a Dask cluster (:mod:`lburst.cluster`), started or joined for the run.

With positions (priors), pairs may be planned by them (``pairs='positions'``, the default for a
scene of more than 20 images with positions), and where they show images turned by more than 90
degrees against the images they are paired with (the lines of a survey, flown in alternating
directions), a method with rotation sets extracts with ``rotations=2`` unless its spec sets them
(:mod:`lburst.sfm.turns`); ``result.json``'s ``positions.turns`` says so.  A scene's images and
positions are known before its features are computed; a recording's keyframes only once read,
so a recording with turned pairs has its features computed again with the rotation sets.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from lburst.burst.io import atomic_path, check_output_outside
from lburst.cluster.runner import Runner, open_runner
from lburst.extras import MissingExtra, check_installed
from lburst.geo.frame import GeoOrigin
from lburst.geo.outputs import write_georeferenced
from lburst.methods import Method
from lburst.sfm.cameras import camera_plan
from lburst.sfm.colmap import ColmapError, ColmapJob, ColmapOptions, run_job_subprocess
from lburst.sfm.feature_stage import utf8
from lburst.sfm.inputs import InputSource, open_input
from lburst.sfm.match import feature_keys, match_or_reuse, match_pairs_with_scores, report_stage
from lburst.sfm.metrics import camera_metrics, evaluate_against_reference, scene_metrics
from lburst.sfm.options import Pairs, ReconstructOptions
from lburst.sfm.outputs import write_outputs
from lburst.sfm.pairs import exhaustive_pairs, make_pairs, pair_plan
from lburst.sfm.positions import Priors, file_priors, parse_positions, prior_fit
from lburst.sfm.result import RESULT_FILE, ReconstructionError, ReconstructionResult, Status, ended
from lburst.sfm.retrieval import retrieval_pairs, vlad
from lburst.sfm.scene import SceneError
from lburst.sfm.trust import assess
from lburst.sfm.turns import TURN_ROTATIONS, describe_turns, find_turns, switch_on

__all__ = [
    "RESULT_FILE",
    "ReconstructOptions",
    "ReconstructionError",
    "ReconstructionResult",
    "Status",
    "reconstruct_scene",
]


def reconstruct_scene(
    scene_dir: str | Path,
    method: str | Method,
    out_dir: str | Path,
    options: ReconstructOptions | None = None,
    extractor=None,
) -> ReconstructionResult:
    """Reconstruct ``scene_dir`` with features of ``method`` (a :class:`lburst.methods.Method` or its
    spec); files and ``result.json`` go to ``out_dir``.

    ``options``: how (``None``: the defaults).  ``extractor`` (optional) is used instead of
    creating one from the method.  Raises :class:`ReconstructionError` for a scene that cannot
    be used (not a folder, no images, a single image, an unreadable burst); a COLMAP failure
    is returned as a result with ``status`` :attr:`Status.COLMAP_FAILED` and ``error`` set.
    """
    opts = options or ReconstructOptions()
    check_installed("pycolmap", "reconstruction")  # without lburst[sfm]: one line before any work
    with open_runner(opts.cluster) as runner:
        return _reconstruct(scene_dir, Method.of(method), out_dir, opts, extractor, runner)


def _priors(source: InputSource, scene, opts: ReconstructOptions) -> Priors | None:
    """The position priors of the scene's images: the positions file's, else, unless
    ``opts.input_positions`` is off, those the input carries (:mod:`lburst.geo`); ``None``: none."""
    if opts.positions is not None:
        return file_priors(opts.positions, scene.names, opts.position_std)
    return source.gnss_priors(scene, opts.position_std) if opts.input_positions else None


def _known(priors: Priors | None) -> np.ndarray | None:
    """The centres of ``priors`` when at least 2 images have one (pairs by position), else ``None``."""
    return priors.centres if priors is not None and priors.count >= 2 else None


def _planned_pairs(n: int, opts: ReconstructOptions, time_ordered: bool, priors: Priors | None):
    """The pair plan of ``n`` images and its pairs before retrieval (:func:`lburst.sfm.pairs.make_pairs`)."""
    centres = _known(priors)
    plan = pair_plan(n, opts, time_ordered, positions=centres is not None)
    return plan, make_pairs(n, plan.mode, plan.overlap, centres, plan)


def _turns(method: Method, priors: Priors | None, n: int, opts: ReconstructOptions, time_ordered: bool, progress: bool):
    """``method`` with rotation sets where the positions show the planned pairs turned
    (:mod:`lburst.sfm.turns`), and what was found (``None``: nothing turned, or no positions)."""
    centres = _known(priors)
    found = (
        None
        if centres is None
        else find_turns(centres, _planned_pairs(n, opts, time_ordered, priors)[1], opts.position_std)
    )
    if found is None:
        return method, None
    rotated = method.with_default("rotations", TURN_ROTATIONS)
    found = switch_on(found, str(method), rotated != method, method.accepts("rotations"))
    if progress:
        report_stage(f"positions: {describe_turns(found)}")
    return rotated, found


def _georeferenced(out: Path, origin: GeoOrigin, result: ReconstructionResult) -> dict | None:
    """``OUT/model.las`` and ``OUT/cameras.geojson`` of a model in a GNSS frame
    (:mod:`lburst.geo.outputs`); ``None``, with a note, without the ``geo`` extra."""
    try:
        poses = {name: result.poses[name] for name in result.registered}  # in the scene's order
        return write_georeferenced(out, origin, out / "colmap" / "model", poses)
    except MissingExtra as err:
        result.positions["notes"].append(f"no LAS point cloud or GeoJSON cameras: {err}")
        return None


def _checks(summary: dict, names: list[str], ordered: bool, priors, result, opts: ReconstructOptions) -> dict:
    """Whether the model can be trusted (:func:`lburst.sfm.trust.assess`); the positions count
    where they placed the model."""
    placed = None
    if priors is not None and result.positions and result.positions.get("in_frame"):
        placed = {n: c for n, c in zip(names, priors.centres) if not np.isnan(c).any()}
    return assess(summary, names, ordered, placed, opts.position_std)


def _reconstruct(
    scene_dir: str | Path, method: Method, out_dir: str | Path, opts: ReconstructOptions, extractor, runner: Runner
) -> ReconstructionResult:
    source = open_input(scene_dir, opts.recording)  # the one question about the kind of input
    if extractor is None:  # a given extractor keeps its own top_k
        method = method.with_default("top_k", source.keypoints)
    if opts.positions is not None:  # a bad file, or one naming no image, is refused before the features are computed
        parse_positions(opts.positions)
        try:
            known = source.known_names()
        except SceneError as err:
            raise ReconstructionError(str(err)) from err
        if known is not None:
            file_priors(opts.positions, known, opts.position_std)
    early_priors, turns = None, None
    try:
        known_scene = source.known_scene()
    except SceneError as err:
        raise ReconstructionError(str(err)) from err
    if known_scene is not None and len(known_scene.items) >= 2:  # a scene: priors and turns before the features
        early_priors = _priors(source, known_scene, opts)
        if opts.pairs == Pairs.POSITIONS and _known(early_priors) is None:
            make_pairs(len(known_scene.items), Pairs.POSITIONS, 1)  # refused before any feature is computed
        if extractor is None:
            method, turns = _turns(method, early_priors, len(known_scene.items), opts, False, opts.progress)
    if opts.single_camera is None:  # one camera shot a recording; a scene's photos may come from several
        opts = replace(opts, single_camera=source.one_camera)
    out = Path(out_dir)
    try:
        check_output_outside(out, [scene_dir])
    except ValueError as err:
        raise ReconstructionError(str(err)) from None
    if not utf8(str(out.resolve())):
        raise ReconstructionError(f"{out!s}: the output path is not valid UTF-8, which COLMAP cannot use")
    try:
        scene, features, source_error = source.read(method, out, opts, extractor, runner).unpack()
        if source_error and len(scene.items) < 2:  # nothing to reconstruct: say why in result.json too
            out.mkdir(parents=True, exist_ok=True)
            read = f"{len(scene.items)} keyframe(s) read before the recording stopped; no model"
            ReconstructionResult(
                str(scene_dir),
                str(method),
                str(out),
                scene.names,
                status=Status.SOURCE_FAILED,
                error=f"{source_error} ({read})",
            ).save()
            raise ReconstructionError(source_error)
        if len(scene.items) < 2:
            raise ReconstructionError(
                f"{scene_dir}: a reconstruction needs at least 2 images, found {len(scene.items)}"
            )
        if known_scene is None:  # a recording: its keyframes and their positions are known once read
            early_priors = _priors(source, scene, opts)
            if extractor is None:
                rotated, turns = _turns(method, early_priors, len(scene.items), opts, True, opts.progress)
                if rotated != method:  # its features again, with the rotation sets
                    method = rotated
                    scene, features, source_error = source.read(method, out, opts, extractor, runner).unpack()
        sizes = [(int(f["image_size"][0]), int(f["image_size"][1])) for f in features]
        cams = camera_plan(scene, sizes, opts)
    except SceneError as err:
        raise ReconstructionError(str(err)) from err
    n = len(scene.items)
    priors = early_priors
    plan, pairs = _planned_pairs(n, opts, source.time_ordered, priors)
    mode = plan.mode
    loop_candidates: set[tuple[int, int]] = set()
    if plan.retrieval and mode == "sequential":
        loops = retrieval_pairs(
            vlad([f["descriptors"] for f in features], seed=opts.seed), plan.retrieval, plan.overlap
        )
        loop_candidates = set(loops) - set(pairs)
        pairs = sorted(set(pairs) | loop_candidates)
    reuse = (
        None if opts.matches is None else (Path(opts.matches), scene.names, feature_keys(out / "features", scene.names))
    )
    matches, scores = match_or_reuse(features, pairs, opts.progress, opts.matcher, runner, reuse)
    colmap_options = ColmapOptions(
        mapper=plan.mapper,
        num_threads=opts.num_threads,
        seed=opts.seed,
        refine_focal_length=not cams.fixed,
        refine_extra_params=not cams.fixed,
        **{
            "near": plan.near,
            "loop_inlier_fraction": opts.loop_fraction,
            "abs_pose_min_num_inliers": plan.abs_pose_inliers,
            "two_view_tracks": plan.two_view_tracks,
            "mapper_threads": plan.mapper_threads,
            **opts.extra,
        },
    )
    job = ColmapJob(scene.names, str((out / "images").resolve()), cams.cameras, cams.camera_of_image, colmap_options)
    use_priors = priors is not None and priors.count > 0 and plan.mapper != "global"
    if priors is not None and priors.count and not use_priors:
        priors.notes.append("COLMAP's global mapper takes no priors (--mapper incremental does)")
    if use_priors:
        job.positions = priors.job_positions()
        job.position_std = opts.position_std
    job_dir = out / "colmap"
    job_dir.mkdir(parents=True, exist_ok=True)
    result = ReconstructionResult(str(scene.root), str(method), str(out), scene.names)
    summary: dict = {"converged": False, "registered": {}, "num_points3D": 0}
    colmap_error = None
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
            colmap_error = None
        except ColmapError as err:
            colmap_error = str(err)
        done = len(summary.get("registered", {})) == n
        if attempt or done or not opts.fallback_exhaustive or mode == "exhaustive":
            break
        extra = [p for p in exhaustive_pairs(n) if p not in set(pairs)]
        extra_matches, extra_scores = match_pairs_with_scores(features, extra, opts.progress, opts.matcher, runner)
        pairs, matches, scores = pairs + extra, matches + extra_matches, scores + extra_scores
    verified = np.load(job_dir / "verified.npz") if (job_dir / "verified.npz").is_file() and not colmap_error else None
    inlier_counts = [len(verified[k]) for k in verified.files if k.startswith("inl_")] if verified is not None else []
    result.metrics = scene_metrics(
        n,
        [len(f["keypoints"]) for f in features],
        [len(m) for m in matches],
        inlier_counts,
        summary if not colmap_error else {},
    )
    result.metrics.update(
        pairs=len(pairs),
        pairing=mode if len(pairs) < n * (n - 1) // 2 else "exhaustive",
        overlap=plan.overlap if mode == "sequential" else None,
        neighbours=plan.neighbours if mode == "positions" else None,
        loop_candidates=len(loop_candidates),
        matcher=opts.matcher,
        mapper=plan.mapper,
    )
    if (origin := source.camera_origin(scene, cams, opts)) is not None:
        result.metrics["camera"] = origin
    if plan.near and not colmap_error:
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
    if priors is not None:
        centres = {name: -R.T @ t for name, (R, t) in result.poses.items()}
        alignment = summary.get("prior_alignment") if not colmap_error else None
        result.positions = prior_fit(priors, scene.names, centres, use_priors, opts.position_std, alignment)
        result.positions["turns"] = turns
        if result.positions["in_frame"] and priors.origin is not None and not colmap_error:
            result.positions["georeferenced"] = _georeferenced(out, priors.origin, result)
    result.metrics.update(camera_metrics(result.cameras))
    if result.converged and not colmap_error:
        result.checks = _checks(summary, scene.names, source.time_ordered or mode == "sequential", priors, result, opts)
    if scene.reference_path is not None and not colmap_error:
        result.metrics.update(evaluate_against_reference(result, scene.reference_path))
    result.status, result.error = ended(colmap_error, source_error, result.converged)
    result.save()
    write_outputs(result, features, pairs, matches, scores)
    return result
