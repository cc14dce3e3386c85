"""Which image pairs to match: all of them, or neighbours along a trajectory.

Images are indexed ``0 .. n-1`` in scene (trajectory) order; a pair ``(i, j)`` always
has ``i < j``.
"""

from __future__ import annotations

from lburst.errors import LBurstValueError


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
