"""Matching the planned pairs (:mod:`lburst.matching`), with a line on stderr per stage; on a
cluster (:mod:`lburst.cluster.runner`) the features go to the workers once and the pairs are
tasks of :data:`CHUNK_PAIRS` at most.  A finished run's matches (:func:`run_matches`: its
``matches.h5``) are taken for the pairs it matched with the same matcher between the same
features, which a matcher matches alike every time, so that runs of other COLMAP seeds or
camera options on the same features only map again (:func:`match_or_reuse`)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lburst import store
from lburst.cluster.runner import Runner
from lburst.features import Features
from lburst.matching import create, match_with_scores
from lburst.sfm.result import RESULT_FILE, ReconstructionResult

#: most pairs in one matching task on a cluster (a task costs tens of milliseconds; a pair a few)
CHUNK_PAIRS = 64


def report_stage(line: str) -> None:
    """Print a stage line of ``lburst reconstruct`` on stderr, above any tqdm bar."""
    tqdm.write(line, file=sys.stderr)


def match_chunk(job: tuple[str, list[tuple[int, int]], dict[int, Features]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Matches and scores of the pairs of one task: ``(matcher spec, pairs, features by image index)``."""
    matcher, pairs, features = job
    match = create(matcher)
    return [match_with_scores(match, features[a], features[b]) for a, b in pairs]


def match_pairs_with_scores(
    features: list[Features],
    pairs: list[tuple[int, int]],
    progress: bool = True,
    matcher: str = "mnn",
    runner: Runner | None = None,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Matches (M, 2) of each pair and their scores (M,) (:func:`lburst.matching.match_with_scores`:
    descriptor similarity in [-1, 1]), by the matcher spec ``matcher``, in this process or by
    ``runner`` on a cluster; with ``progress`` a bar, then a line with the seconds it took."""
    match = create(matcher)
    start = time.perf_counter()
    if runner is None or not runner.remote:
        found = [
            match_with_scores(match, features[a], features[b])
            for a, b in tqdm(pairs, desc="matching", disable=not progress, leave=False)
        ]
    else:
        shared = runner.share(list(features))
        chunks = [pairs[i : i + CHUNK_PAIRS] for i in range(0, len(pairs), CHUNK_PAIRS)]
        jobs = [
            (matcher, chunk, {i: shared[i] for i in sorted({i for pair in chunk for i in pair})}) for chunk in chunks
        ]
        results = {id(job): None for job in jobs}
        for job, result in runner.map(match_chunk, jobs, "matching", progress, total=len(jobs), unit="task"):
            results[id(job)] = result()
        found = [pair for job in jobs for pair in results[id(job)]]
    if progress:
        report_stage(f"matching ({len(pairs)} pairs, {matcher}): {time.perf_counter() - start:.1f} s")
    return [m for m, _ in found], [s for _, s in found]


def feature_keys(folder: Path, names: list[str]) -> list[dict | None]:
    """The store's key (:mod:`lburst.store`: what made the features) of each image's
    ``folder/<name>.npz`` (``None``: not there, or written without one)."""
    metas = [store.read_meta(folder / f"{name}.npz") for name in names]
    return [None if meta is None else meta.get("key") for meta in metas]


def run_matches(
    run: Path, names: list[str], pairs: list[tuple[int, int]], matcher: str, keys: list[dict | None]
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """The matches (M, 2) and scores (M,) of those ``pairs`` (indices into ``names``) that the
    finished run in ``run`` matched with ``matcher`` between images whose features have the store
    ``keys`` (:func:`feature_keys`) there too, by pair index; from its ``matches.h5`` (the scores
    as stored there, float16).  Empty when ``run`` is no finished run of that matcher."""
    import h5py

    try:
        done = ReconstructionResult.load(run / RESULT_FILE)
    except (OSError, ValueError):
        return {}
    if done.metrics.get("matcher", "mnn") != matcher or not (run / "matches.h5").is_file():
        return {}
    same = [k is not None and k == other for k, other in zip(keys, feature_keys(run / "features", names))]
    found = {}
    with h5py.File(run / "matches.h5", "r") as f:
        for p, (a, b) in enumerate(pairs):
            path = f"{names[a]}.png/{names[b]}.png"
            if not (same[a] and same[b]) or path not in f:
                continue
            m0, s0 = f[path]["matches0"][()], f[path]["matching_scores0"][()]
            i = np.flatnonzero(m0 >= 0)
            found[p] = (np.stack([i, m0[i]], 1).astype(np.int64).reshape(-1, 2), s0[i].astype(np.float32))
    return found


def match_or_reuse(
    features: list[Features],
    pairs: list[tuple[int, int]],
    progress: bool = True,
    matcher: str = "mnn",
    runner: Runner | None = None,
    reuse: tuple[Path, list[str], list[dict | None]] | None = None,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """:func:`match_pairs_with_scores`, but the pairs that a finished run matched alike are read
    from it: ``reuse`` is ``(run folder, image names, this run's feature keys)``
    (:func:`run_matches`)."""
    stored = run_matches(reuse[0], reuse[1], pairs, matcher, reuse[2]) if reuse is not None else {}
    todo = [p for p in range(len(pairs)) if p not in stored]
    if stored and progress:
        report_stage(f"matching: {len(stored)} of {len(pairs)} pairs read from {reuse[0]}")
    found, scores = match_pairs_with_scores(
        features, [pairs[p] for p in todo], progress and bool(todo), matcher, runner
    )
    computed = dict(zip(todo, zip(found, scores)))
    both = [stored[p] if p in stored else computed[p] for p in range(len(pairs))]
    return [m for m, _ in both], [s for _, s in both]
