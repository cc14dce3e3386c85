"""``lburst reconstruct``: a scene of bursts to a 3D model with COLMAP, and its metrics.

Pipeline (:func:`reconstruct_scene`, options :class:`lburst.sfm.options.ReconstructOptions`),
in named stages (inputs, features, pairs, matches, verification and mapping, outputs):
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

from pathlib import Path

from lburst.cluster.runner import Runner, open_runner
from lburst.extras import check_installed
from lburst.features import Features
from lburst.methods import Method
from lburst.sfm.mapping import Mapped, Matched, Placed, colmap_job, mapping_result, verify_and_map
from lburst.sfm.match import feature_keys, match_or_reuse
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.outputs import write_outputs
from lburst.sfm.pairs import PairPlan
from lburst.sfm.read import Opened, Read, open_checked, planned_pairs, read_features
from lburst.sfm.result import RESULT_FILE, ReconstructionError, ReconstructionResult, Status, ended
from lburst.sfm.retrieval import retrieval_pairs, vlad

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


def _reconstruct(
    scene_dir: str | Path, method: Method, out_dir: str | Path, opts: ReconstructOptions, extractor, runner: Runner
) -> ReconstructionResult:
    """The stages in order: inputs, features, pairs, matches, verification and mapping, outputs."""
    opened = open_checked(scene_dir, method, out_dir, opts, extractor)
    read = read_features(opened, scene_dir, extractor, runner)
    opts, out = opened.opts, opened.out
    plan, planned = _pairs(read, opts, opened.source.time_ordered)
    matched = _matches(read.features, planned, read.scene.names, out, opts, runner)
    job, used_priors = colmap_job(read.scene, read.cams, plan, read.priors, out, opts)
    mapped = verify_and_map(job, out / "colmap", read.features, matched, plan.mode, opts, runner)
    return _outputs(opened, read, plan, used_priors, mapped)


def _pairs(read: Read, opts: ReconstructOptions, time_ordered: bool) -> tuple[PairPlan, Matched]:
    """The pair plan and its pairs, with the retrieval loop candidates of sequential pairs
    (:mod:`lburst.sfm.retrieval`) among them."""
    plan, pairs = planned_pairs(len(read.scene.items), opts, time_ordered, read.priors)
    loop_candidates: set[tuple[int, int]] = set()
    if plan.retrieval and plan.mode == "sequential":
        descriptors = [f["descriptors"] for f in read.features]
        loops = retrieval_pairs(vlad(descriptors, seed=opts.seed), plan.retrieval, plan.overlap)
        loop_candidates = set(loops) - set(pairs)
        pairs = sorted(set(pairs) | loop_candidates)
    return plan, Matched(pairs, [], [], loop_candidates)


def _matches(
    features: list[Features], planned: Matched, names: list[str], out: Path, opts: ReconstructOptions, runner: Runner
) -> Matched:
    """The matches and scores of the planned pairs, those of ``opts.matches``' finished run read from it."""
    reuse = None if opts.matches is None else (Path(opts.matches), names, feature_keys(out / "features", names))
    matches, scores = match_or_reuse(features, planned.pairs, opts.progress, opts.matcher, runner, reuse)
    return Matched(planned.pairs, matches, scores, planned.loop_candidates)


def _outputs(opened: Opened, read: Read, plan: PairPlan, used_priors: bool, mapped: Mapped) -> ReconstructionResult:
    """``result.json`` (:func:`lburst.sfm.mapping.mapping_result`) and the files every input
    leaves (:func:`lburst.sfm.outputs.write_outputs`)."""
    source, opts, scene = opened.source, opened.opts, read.scene
    result = ReconstructionResult(str(scene.root), str(read.method), str(opened.out), scene.names)
    camera = source.camera_origin(scene, read.cams, opts)
    placed = Placed(plan, camera, read.priors, used_priors, source.time_ordered, read.turns)
    mapping_result(result, read.features, mapped, placed, scene, opts)
    result.status, result.error = ended(mapped.error, read.error, result.converged)
    result.save()
    write_outputs(result, read.features, mapped.matched.pairs, mapped.matched.matches, mapped.matched.scores)
    return result
