"""Which image pairs to match: all of them, neighbours along a trajectory, or the nearest images
by position (:func:`position_pairs`), and the plan of a reconstruction's pairs (:func:`pair_plan`:
a scene's defaults or a recording's).

Images are indexed ``0 .. n-1`` in scene (trajectory) order; a pair ``(i, j)`` always
has ``i < j``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from lburst.errors import LBurstValueError
from lburst.sfm.options import (
    AUTO_EXHAUSTIVE_MAX,
    GLOBAL_MAPPER_FROM,
    POSITION_NEIGHBOURS,
    POSITION_RADIUS_M,
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


def position_pairs(centres: np.ndarray, neighbours: int, radius: float, overlap: int = 0) -> list[tuple[int, int]]:
    """Each image with its ``neighbours`` nearest images by position within ``radius`` (m), as
    hloc's ``pairs_from_poses`` pairs images by their poses: sorted pairs ``(i, j)``, ``i < j``.

    ``centres`` (N, 3) are the images' positions in a metric frame, NaN rows for images without
    one; those are paired with the images at most ``overlap`` apart in the scene's order instead
    (0: not paired).  Ties in distance go to the lower index, so the pairs depend only on the
    positions and their order."""
    centres = np.asarray(centres, np.float64)
    if neighbours < 1:
        raise LBurstValueError(f"--pair-neighbours must be at least 1, got {neighbours}")
    if not radius > 0:
        raise LBurstValueError(f"--pair-radius must be above 0 m, got {radius}")
    known = np.flatnonzero(~np.isnan(centres).any(axis=1))
    pairs: set[tuple[int, int]] = set()
    if len(known) >= 2:
        points = centres[known]
        tree = cKDTree(points)
        for a, near in enumerate(tree.query_ball_point(points, radius)):
            near = np.array([b for b in near if b != a], dtype=np.int64)
            if not len(near):
                continue
            distance = np.linalg.norm(points[near] - points[a], axis=1)
            for b in near[np.lexsort((near, distance))][:neighbours]:  # by distance, then index
                i, j = int(known[a]), int(known[b])
                pairs.add((min(i, j), max(i, j)))
    n = len(centres)
    for i in np.flatnonzero(np.isnan(centres).any(axis=1)):
        for j in range(max(0, i - overlap), min(n, i + overlap + 1)):
            if j != i:
                pairs.add((min(int(i), j), max(int(i), j)))
    return sorted(pairs)


def make_pairs(
    n: int, mode: str = "exhaustive", overlap: int = 10, centres: np.ndarray | None = None, plan: PairPlan | None = None
) -> list[tuple[int, int]]:
    """Pairs for ``mode`` ``'exhaustive'``, ``'sequential'`` (with ``overlap``) or ``'positions'``
    (the images' ``centres`` (N, 3), with the ``plan``'s neighbours and radius)."""
    if mode == "exhaustive":
        return exhaustive_pairs(n)
    if mode == "sequential":
        return sequential_pairs(n, overlap)
    if mode == "positions":
        if centres is None or int((~np.isnan(np.asarray(centres)).any(axis=1)).sum()) < 2:
            raise LBurstValueError(
                "--pairs positions needs the images' positions (--positions FILE, or an input that carries them: "
                "EXIF GPS, a DJI .SRT, a bag's NavSatFix), and at least 2 images have one"
            )
        neighbours = plan.neighbours if plan is not None else POSITION_NEIGHBOURS
        radius = plan.radius if plan is not None else POSITION_RADIUS_M
        return position_pairs(centres, neighbours, radius, overlap)
    raise LBurstValueError(f"unknown pairing {mode!r}: expected 'exhaustive', 'sequential' or 'positions'")


@dataclass(frozen=True)
class PairPlan:
    """Which pairs to match and verify (:func:`pair_plan`)."""

    mode: str  # 'exhaustive', 'sequential' or 'positions'
    overlap: int  # sequential pairs: images at most this far apart
    retrieval: int  # loop candidates per image (sequential only)
    near: int  # pairs farther apart than this must pass the loop test; 0: no test
    abs_pose_inliers: int  # incremental mapper: fewest 2D-3D inliers to register an image
    two_view_tracks: bool = False  # incremental mapper: triangulate tracks of two images too
    mapper_threads: int | None = None  # None: num_threads
    mapper: str = "incremental"  # 'incremental' or 'global' (opts.mapper, 'auto' resolved by the image count)
    neighbours: int = POSITION_NEIGHBOURS  # positions: nearest images of each
    radius: float = POSITION_RADIUS_M  # positions: within this many metres


def pair_plan(n: int, opts: ReconstructOptions, recording: bool, positions: bool = False) -> PairPlan:
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
    loop test, COLMAP's 30 and COLMAP's triangulation, unless the options say otherwise; with
    ``positions`` (at least 2 of its images have one) a scene of more than ``AUTO_EXHAUSTIVE_MAX``
    gets pairs by position instead (:func:`position_pairs`: each image's ``POSITION_NEIGHBOURS``
    nearest within ``POSITION_RADIUS_M``), which close loops and tie neighbouring survey lines
    that sequential pairs never pair (docs/large_surveys.md).
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
        auto = Pairs.POSITIONS if positions else Pairs.SEQUENTIAL
        auto = Pairs.EXHAUSTIVE if n <= AUTO_EXHAUSTIVE_MAX else auto
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
        POSITION_NEIGHBOURS if opts.neighbours is None else opts.neighbours,
        POSITION_RADIUS_M if opts.radius is None else opts.radius,
    )
