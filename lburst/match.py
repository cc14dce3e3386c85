"""Mutual nearest-neighbour matching of descriptors (L2 for float, Hamming for binary: on
the CPU by OpenCV's brute-force matcher with cross-check, which gives the same pairs)."""

from __future__ import annotations

import numpy as np
import torch

from lburst.errors import LBurstValueError


def check_descriptors(desc_a: np.ndarray, desc_b: np.ndarray) -> None:
    """``ValueError`` unless both are (K, D) arrays of one dtype and one width D, and float
    descriptors are finite (a NaN descriptor would match whatever comes first)."""
    for name, d in (("first", desc_a), ("second", desc_b)):
        if not isinstance(d, np.ndarray) or d.ndim != 2:
            raise LBurstValueError(
                f"{name} descriptors must be a (K, D) array, got {getattr(d, 'shape', type(d).__name__)}"
            )
    if desc_a.dtype != desc_b.dtype:
        raise LBurstValueError(f"descriptor types differ: {desc_a.dtype} vs {desc_b.dtype}")
    if desc_a.shape[1] != desc_b.shape[1]:
        raise LBurstValueError(f"descriptor sizes differ: {desc_a.shape[1]} vs {desc_b.shape[1]}")
    if np.issubdtype(desc_a.dtype, np.floating):
        for name, d in (("first", desc_a), ("second", desc_b)):
            bad = int((~np.isfinite(d)).any(1).sum())
            if bad:
                raise LBurstValueError(f"{bad} of the {name} set's {len(d)} descriptors hold NaN or inf")


def _distances(a: torch.Tensor, b: torch.Tensor, binary: bool) -> torch.Tensor:
    if binary:  # packed bits: Hamming distance through unpacked 0/1 vectors
        bits = torch.tensor([1 << i for i in range(8)], dtype=torch.uint8, device=a.device)
        ua = ((a.unsqueeze(-1) & bits) > 0).flatten(1).float()
        ub = ((b.unsqueeze(-1) & bits) > 0).flatten(1).float()
        return ua.sum(1, keepdim=True) + ub.sum(1)[None] - 2 * ua @ ub.t()
    return torch.cdist(a.float(), b.float())


#: rows of ``a @ b.T`` that :func:`nearest_both_ways` holds at once (8 MB against 8,000 columns)
CHUNK_ROWS = 256


def nearest_both_ways(a: torch.Tensor, b: torch.Tensor, chunk: int = CHUNK_ROWS) -> tuple[torch.Tensor, torch.Tensor]:
    """Each row's nearest row of the other set in L2 (the first of equally near ones):
    ``(nn_ab (Ka,), nn_ba (Kb,))`` for float ``a`` (Ka, D) and ``b`` (Kb, D), both non-empty.

    ``|a - b|^2 / 2 = |a|^2 / 2 + |b|^2 / 2 - a.b``, so a's nearest in b maximises
    ``a.b - |b|^2 / 2`` and b's nearest in a ``a.b - |a|^2 / 2``.  ``a @ b.T`` is formed
    ``chunk`` rows at a time, each block reduced along its rows and, into running maxima,
    along its columns: memory stays at ``chunk`` x Kb, and the column reduction runs on
    a block in cache instead of a strided pass over the whole matrix (which took most of
    the time)."""
    half_a, half_b = 0.5 * (a * a).sum(1), 0.5 * (b * b).sum(1)
    b_t = b.t().contiguous()
    nn_ab = torch.empty(len(a), dtype=torch.long, device=a.device)
    best = torch.full((len(b),), -torch.inf, device=a.device)
    nn_ba = torch.zeros(len(b), dtype=torch.long, device=a.device)
    for start in range(0, len(a), chunk):
        dot = a[start : start + chunk] @ b_t
        nn_ab[start : start + chunk] = (dot - half_b).argmax(1)
        value, index = (dot - half_a[start : start + chunk, None]).max(0)
        better = value > best  # strictly: an earlier block keeps a tie
        best = torch.where(better, value, best)
        nn_ba = torch.where(better, index + start, nn_ba)
    return nn_ab, nn_ba


def hamming_mutual_nearest_neighbours(
    desc_a: np.ndarray, desc_b: np.ndarray, max_distance: float | None = None
) -> np.ndarray:
    """:func:`mutual_nearest_neighbours` of packed binary descriptors (uint8, non-empty) by
    ``cv2.BFMatcher(NORM_HAMMING, crossCheck=True)``: each side's nearest is its first
    nearest, as ``argmin`` takes it, so the pairs are the same; sorted by ``i``."""
    import cv2

    found = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(
        np.ascontiguousarray(desc_a), np.ascontiguousarray(desc_b)
    )
    pairs = np.array([(m.queryIdx, m.trainIdx) for m in found], np.int64).reshape(-1, 2)
    if max_distance is not None:
        pairs = pairs[np.array([m.distance for m in found], np.float64).reshape(-1) <= max_distance]
    return pairs[np.argsort(pairs[:, 0], kind="stable")]


def mutual_nearest_neighbours(
    desc_a: np.ndarray, desc_b: np.ndarray, max_distance: float | None = None, device: str = "cpu"
) -> np.ndarray:
    """Indices ``(M, 2)`` of pairs (i, j) where ``b[j]`` is a's nearest and ``a[i]`` is b's
    nearest (the first one of equally near ones), sorted by ``i``.

    ``desc_a`` (Ka, D) and ``desc_b`` (Kb, D): float32 (L2) or uint8 packed bits (Hamming;
    on the CPU by :func:`hamming_mutual_nearest_neighbours`).  Optionally drop pairs farther
    apart than ``max_distance``.
    """
    check_descriptors(desc_a, desc_b)
    if len(desc_a) == 0 or len(desc_b) == 0:
        return np.zeros((0, 2), np.int64)
    binary = desc_a.dtype == np.uint8
    if binary and torch.device(device).type == "cpu":
        return hamming_mutual_nearest_neighbours(desc_a, desc_b, max_distance)
    a = torch.from_numpy(np.ascontiguousarray(desc_a)).to(device)
    b = torch.from_numpy(np.ascontiguousarray(desc_b)).to(device)
    ia = torch.arange(len(a), device=a.device)
    if binary:
        dist = _distances(a, b, binary)
        nn_ab, nn_ba = dist.argmin(1), dist.argmin(0)
    else:
        a, b = a.float(), b.float()
        nn_ab, nn_ba = nearest_both_ways(a, b)
    keep = nn_ba[nn_ab] == ia
    if max_distance is not None:  # Hamming bits or L2, as the nearest were found
        apart = dist[ia, nn_ab] if binary else torch.linalg.vector_norm(a - b[nn_ab], dim=1)
        keep &= apart <= max_distance
    return torch.stack([ia[keep], nn_ab[keep]], 1).cpu().numpy()
