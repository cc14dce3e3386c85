"""The last stages of a reconstruction (:mod:`lburst.sfm.reconstruct`): COLMAP's verification
and mapping of the matched pairs (:func:`colmap_job`, :func:`verify_and_map`, in COLMAP's child
process: :mod:`lburst.sfm.colmap`), and the :class:`lburst.sfm.result.ReconstructionResult` of
what they gave (:func:`mapping_result`): metrics, registered images and poses, the fit to the
position priors, the model's checks and its precision against a reference."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lburst.burst.io import atomic_path
from lburst.cluster.runner import Runner
from lburst.extras import MissingExtra
from lburst.features import Features
from lburst.geo.frame import GeoOrigin
from lburst.geo.outputs import write_georeferenced
from lburst.sfm.cameras import CameraPlan
from lburst.sfm.colmap import ColmapError, ColmapJob, ColmapOptions, run_job_subprocess
from lburst.sfm.match import match_pairs_with_scores, report_stage
from lburst.sfm.metrics import camera_metrics, evaluate_against_reference, scene_metrics
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.pairs import PairPlan, exhaustive_pairs
from lburst.sfm.positions import Priors, prior_fit
from lburst.sfm.result import ReconstructionResult
from lburst.sfm.scene import Scene
from lburst.sfm.trust import assess


@dataclass
class Matched:
    """The pairs to verify, their matches (M, 2) and scores (M,), and the retrieval loop candidates among them."""

    pairs: list[tuple[int, int]]
    matches: list[np.ndarray]
    scores: list[np.ndarray]
    loop_candidates: set[tuple[int, int]]


@dataclass
class Mapped:
    """What COLMAP's verification and mapping gave: its summary (of the last run that did not
    fail), its error, and the pairs it verified (the exhaustive fallback adds pairs)."""

    summary: dict
    error: str | None
    matched: Matched


def colmap_job(
    scene: Scene,
    cams: CameraPlan,
    plan: PairPlan,
    priors: Priors | None,
    out: Path,
    opts: ReconstructOptions,
) -> tuple[ColmapJob, bool]:
    """COLMAP's job: the images, their cameras, the verification and mapping settings, and the
    position priors unless the global mapper, which takes none, maps; and whether it holds them."""
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
    job = ColmapJob(
        scene.names,
        str((out / "images").resolve()),
        cams.cameras,
        cams.camera_of_image,
        colmap_options,
    )
    use_priors = priors is not None and priors.count > 0 and plan.mapper != "global"
    if priors is not None and priors.count and not use_priors:
        priors.notes.append("COLMAP's global mapper takes no priors (--mapper incremental does)")
    if use_priors:
        job.positions = priors.job_positions()
        job.position_std = opts.position_std
    return job, use_priors


def verify_and_map(
    job: ColmapJob,
    job_dir: Path,
    features: list[Features],
    matched: Matched,
    mode: str,
    opts: ReconstructOptions,
    runner: Runner,
) -> Mapped:
    """Verification and mapping in COLMAP's child process (:func:`lburst.sfm.colmap.run_job_subprocess`);
    with ``opts.fallback_exhaustive``, once more with every pair when some images stay unregistered."""
    job_dir.mkdir(parents=True, exist_ok=True)
    pairs, matches, scores = matched.pairs, matched.matches, matched.scores
    n = len(job.names)
    summary: dict = {"converged": False, "registered": {}, "num_points3D": 0}
    for attempt in range(2):
        summary, colmap_error = _run_colmap(job, job_dir, features, pairs, matches, opts.progress, summary)
        done = len(summary.get("registered", {})) == n
        if attempt or done or not opts.fallback_exhaustive or mode == "exhaustive":
            break
        extra = [p for p in exhaustive_pairs(n) if p not in set(pairs)]
        extra_matches, extra_scores = match_pairs_with_scores(features, extra, opts.progress, opts.matcher, runner)
        pairs, matches, scores = (
            pairs + extra,
            matches + extra_matches,
            scores + extra_scores,
        )
    return Mapped(summary, colmap_error, Matched(pairs, matches, scores, matched.loop_candidates))


def _run_colmap(
    job: ColmapJob,
    job_dir: Path,
    features: list[Features],
    pairs,
    matches,
    progress: bool,
    previous: dict,
) -> tuple[dict, str | None]:
    """One run of COLMAP's child on ``job`` with these pairs and matches: its summary and no
    error, or the ``previous`` summary and its error."""
    job.save(job_dir / "job.json")
    with atomic_path(job_dir / "input.npz") as tmp:
        np.savez(
            tmp,
            pairs=np.array(pairs, dtype=np.int64).reshape(-1, 2),
            **{f"kp_{i}": f["keypoints"] for i, f in enumerate(features)},
            **{f"m_{p}": m for p, m in enumerate(matches)},
        )
    try:
        return run_job_subprocess(job_dir, report=report_stage if progress else None), None
    except ColmapError as err:
        return previous, str(err)


@dataclass(frozen=True)
class Placed:
    """How the images were placed before mapping: the pair plan, where the intrinsics came from
    (``camera``, ``None``: no line), the position priors and whether COLMAP held them, and what
    the positions showed of turned views (``turns``)."""

    plan: PairPlan
    camera: str | None
    priors: Priors | None
    used_priors: bool
    ordered: bool
    turns: dict | None = None


def mapping_result(
    result: ReconstructionResult,
    features: list[Features],
    mapped: Mapped,
    placed: Placed,
    scene: Scene,
    opts: ReconstructOptions,
) -> ReconstructionResult:
    """``result`` filled from what the mapping gave: metrics, registered images, poses and cameras,
    the fit to the position priors (and the georeferenced outputs), the model's checks and its
    precision against the scene's reference."""
    out = Path(result.out_dir)
    result.metrics = _metrics(features, mapped, placed, out / "colmap", opts)
    _registered(result, mapped.summary)
    if placed.priors is not None:
        _positions(result, placed, mapped, out, opts)
    result.metrics.update(camera_metrics(result.cameras))
    if result.converged and not mapped.error:
        result.checks = _checks(mapped.summary, result.names, placed, result, opts)
    if scene.reference_path is not None and not mapped.error:
        result.metrics.update(evaluate_against_reference(result, scene.reference_path))
    return result


def _metrics(features: list[Features], mapped: Mapped, placed: Placed, job_dir: Path, opts) -> dict:
    """The result's metrics (:func:`lburst.sfm.metrics.scene_metrics`), how the pairs were made,
    where the intrinsics came from and the loop test's figures."""
    n, pairs, summary, plan = (
        len(features),
        mapped.matched.pairs,
        mapped.summary,
        placed.plan,
    )
    verified_file = job_dir / "verified.npz"
    verified = np.load(verified_file) if verified_file.is_file() and not mapped.error else None
    inlier_counts = [len(verified[k]) for k in verified.files if k.startswith("inl_")] if verified is not None else []
    metrics = scene_metrics(
        n,
        [len(f["keypoints"]) for f in features],
        [len(m) for m in mapped.matched.matches],
        inlier_counts,
        summary if not mapped.error else {},
    )
    metrics.update(
        pairs=len(pairs),
        pairing=plan.mode if len(pairs) < n * (n - 1) // 2 else "exhaustive",
        overlap=plan.overlap if plan.mode == "sequential" else None,
        loop_candidates=len(mapped.matched.loop_candidates),
        matcher=opts.matcher,
        mapper=plan.mapper,
    )
    if plan.mode == "positions":
        metrics["neighbours"] = plan.neighbours
    if placed.camera is not None:
        metrics["camera"] = placed.camera
    if plan.near and not mapped.error:
        metrics.update(
            near=plan.near,
            loop_threshold=summary.get("loop_threshold"),
            refused_pairs=len(summary.get("refused_pairs", [])),
            first_last_points3D=summary.get("first_last_points3D"),
        )
    return metrics


def _registered(result: ReconstructionResult, summary: dict) -> None:
    """The registered images of COLMAP's ``summary``, their poses and cameras, into ``result``."""
    for name, image in summary.get("registered", {}).items():
        result.registered.append(name)
        result.poses[name] = (np.array(image["R"]), np.array(image["t"]))
        result.cameras[name] = image["camera"]
    result.registered.sort(key=result.names.index)


def _positions(result: ReconstructionResult, placed: Placed, mapped: Mapped, out: Path, opts) -> None:
    """How the model fits the position priors (``result.positions``), and the georeferenced
    outputs of a model placed in their GNSS frame."""
    priors = placed.priors
    centres = {name: -R.T @ t for name, (R, t) in result.poses.items()}
    alignment = mapped.summary.get("prior_alignment") if not mapped.error else None
    result.positions = prior_fit(priors, result.names, centres, placed.used_priors, opts.position_std, alignment)
    result.positions["turns"] = placed.turns
    if result.positions["in_frame"] and priors.origin is not None and not mapped.error:
        result.positions["georeferenced"] = _georeferenced(out, priors.origin, result)


def _georeferenced(out: Path, origin: GeoOrigin, result: ReconstructionResult) -> dict | None:
    """``OUT/model.las`` and ``OUT/cameras.geojson`` of a model in a GNSS frame
    (:mod:`lburst.geo.outputs`); ``None``, with a note, without the ``geo`` extra."""
    try:
        poses = {name: result.poses[name] for name in result.registered}  # in the scene's order
        return write_georeferenced(out, origin, out / "colmap" / "model", poses)
    except MissingExtra as err:
        result.positions["notes"].append(f"no LAS point cloud or GeoJSON cameras: {err}")
        return None


def _checks(summary: dict, names: list[str], placed: Placed, result, opts: ReconstructOptions) -> dict:
    """Whether the model can be trusted (:func:`lburst.sfm.trust.assess`); the positions count
    where they placed the model."""
    ordered = placed.ordered or placed.plan.mode == "sequential"
    placed_at = None
    if placed.priors is not None and result.positions and result.positions.get("in_frame"):
        placed_at = {n: c for n, c in zip(names, placed.priors.centres) if not np.isnan(c).any()}
    return assess(summary, names, ordered, placed_at, opts.position_std)
