"""Matching the planned pairs (:mod:`lburst.matching`), with a line on stderr per stage."""

from __future__ import annotations

import sys
import time

import numpy as np
from tqdm import tqdm

from lburst.features import Features
from lburst.matching import create, match_with_scores


def report_stage(line: str) -> None:
    """Print a stage line of ``lburst reconstruct`` on stderr, above any tqdm bar."""
    tqdm.write(line, file=sys.stderr)


def match_pairs_with_scores(
    features: list[Features], pairs: list[tuple[int, int]], progress: bool = True, matcher: str = "mnn"
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Matches (M, 2) of each pair and their scores (M,) (:func:`lburst.matching.match_with_scores`:
    descriptor similarity in [-1, 1]), by the matcher spec ``matcher``; with ``progress`` a
    bar, then a line with the seconds it took."""
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
