"""Which image pairs to match: all of them, or neighbours along a trajectory, and the plan of a
reconstruction's pairs (:func:`pair_plan`: a scene's defaults or a recording's).

Images are indexed ``0 .. n-1`` in scene (trajectory) order; a pair ``(i, j)`` always
has ``i < j``.
"""

from __future__ import annotations

from dataclasses import dataclass

from lburst.errors import LBurstValueError
from lburst.sfm.options import (
    AUTO_EXHAUSTIVE_MAX,
    GLOBAL_MAPPER_FROM,
    RECORDING_ABS_POSE_INLIERS,
    RECORDING_NEAR,
    RECORDING_OVERLAP,
    RECORDING_RETRIEVAL,
    SCENE_OVERLAP,
    Mapper,
    Pairs,
    ReconstructOptions,
)


def exhaustive_pairs(n: int) -> list[tuple[int, int]]:
    """Every pair ``(i, j)``, ``i < j``, of ``n`` images: ``n (n - 1) / 2`` pairs."""
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


def sequential_pairs(n: int, overlap: int) -> list[tuple[int, int]]:
    """Pairs of images at most ``overlap`` apart in trajectory order (``0 < j - i <= overlap``)."""
    if overlap < 1:
        raise LBurstValueError(f"overlap must be at least 1, got {overlap}")
    return [(i, j) for i in range(n) for j in range(i + 1, min(n, i + overlap + 1))]


def make_pairs(n: int, mode: str = "exhaustive", overlap: int = 10) -> list[tuple[int, int]]:
    """Pairs for ``mode`` ``'exhaustive'`` or ``'sequential'`` (with ``overlap``)."""
    if mode == "exhaustive":
        return exhaustive_pairs(n)
    if mode == "sequential":
        return sequential_pairs(n, overlap)
    raise LBurstValueError(f"unknown pairing {mode!r}: expected 'exhaustive' or 'sequential'")


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
    mapper: str = "incremental"  # 'incremental' or 'global' (opts.mapper, 'auto' resolved by the image count)


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
    ``mapper='auto'`` is the global mapper from ``GLOBAL_MAPPER_FROM`` images (``None``: never,
    the measured choice: docs/large_surveys.md) and else the incremental one, always the
    incremental one with position priors (``opts.positions``), which only it takes.
    """
    if recording:
        mode = Pairs.SEQUENTIAL if opts.pairs == Pairs.AUTO else opts.pairs
        overlap = RECORDING_OVERLAP if opts.overlap is None else opts.overlap
        retrieval = RECORDING_RETRIEVAL if opts.retrieval is None else opts.retrieval
        near = min(RECORDING_NEAR, overlap) if opts.near is None else opts.near
    else:
        auto = Pairs.EXHAUSTIVE if n <= AUTO_EXHAUSTIVE_MAX else Pairs.SEQUENTIAL
        mode = opts.pairs if opts.pairs != Pairs.AUTO else auto
        overlap = SCENE_OVERLAP if opts.overlap is None else opts.overlap
        retrieval = opts.retrieval or 0
        near = opts.near or 0
    if overlap < 1:
        raise LBurstValueError(f"overlap must be at least 1, got {overlap}")
    default_abs = RECORDING_ABS_POSE_INLIERS if recording else 30
    abs_pose = default_abs if opts.abs_pose_inliers is None else opts.abs_pose_inliers
    mapper_threads = opts.mapper_threads if opts.mapper_threads is not None else (1 if recording else None)
    mapper = opts.mapper
    if mapper == Mapper.AUTO:
        global_ = GLOBAL_MAPPER_FROM is not None and n >= GLOBAL_MAPPER_FROM and opts.positions is None
        mapper = Mapper.GLOBAL if global_ else Mapper.INCREMENTAL
    return PairPlan(
        str(mode),
        overlap,
        retrieval if mode == Pairs.SEQUENTIAL else 0,
        max(near, 0),
        abs_pose,
        recording,
        mapper_threads,
        str(mapper),
    )
