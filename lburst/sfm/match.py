"""Matching the planned pairs (:mod:`lburst.matching`), with a line on stderr per stage; on a
cluster (:mod:`lburst.cluster.runner`) the features go to the workers once and the pairs are
tasks of :data:`CHUNK_PAIRS` at most."""

from __future__ import annotations

import sys
import time

import numpy as np
from tqdm import tqdm

from lburst.cluster.runner import Runner
from lburst.features import Features
from lburst.matching import create, match_with_scores

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


def match_pairs(
    features: list[Features], pairs: list[tuple[int, int]], progress: bool = True, matcher: str = "mnn"
) -> list[np.ndarray]:
    """Matches (M, 2) of each pair, by the matcher spec ``matcher`` (mutual nearest neighbours by default)."""
    return match_pairs_with_scores(features, pairs, progress, matcher)[0]
