"""Mutual nearest-neighbour matching of descriptors (L2 for float, Hamming for binary)."""

from __future__ import annotations

import numpy as np
import torch


def _distances(a: torch.Tensor, b: torch.Tensor, binary: bool) -> torch.Tensor:
    if binary:  # packed bits: Hamming distance through unpacked 0/1 vectors
        bits = torch.tensor([1 << i for i in range(8)], dtype=torch.uint8, device=a.device)
        ua = ((a.unsqueeze(-1) & bits) > 0).flatten(1).float()
        ub = ((b.unsqueeze(-1) & bits) > 0).flatten(1).float()
        return ua.sum(1, keepdim=True) + ub.sum(1)[None] - 2 * ua @ ub.t()
    return torch.cdist(a.float(), b.float())


def mutual_nearest_neighbours(
    desc_a: np.ndarray, desc_b: np.ndarray, max_distance: float | None = None, device: str = "cpu"
) -> np.ndarray:
    """Indices ``(M, 2)`` of pairs (i, j) where ``b[j]`` is a's nearest and ``a[i]`` is b's nearest.

    ``desc_a`` (Ka, D) and ``desc_b`` (Kb, D): float32 (L2) or uint8 packed bits (Hamming).
    Optionally drop pairs farther apart than ``max_distance``.
    """
    if desc_a.dtype != desc_b.dtype:
        raise ValueError(f"descriptor types differ: {desc_a.dtype} vs {desc_b.dtype}")
    if len(desc_a) == 0 or len(desc_b) == 0:
        return np.zeros((0, 2), np.int64)
    binary = desc_a.dtype == np.uint8
    a = torch.from_numpy(np.ascontiguousarray(desc_a)).to(device)
    b = torch.from_numpy(np.ascontiguousarray(desc_b)).to(device)
    dist = _distances(a, b, binary)
    nn_ab = dist.argmin(1)
    nn_ba = dist.argmin(0)
    ia = torch.arange(len(a), device=dist.device)
    keep = nn_ba[nn_ab] == ia
    if max_distance is not None:
        keep &= dist[ia, nn_ab] <= max_distance
    return torch.stack([ia[keep], nn_ab[keep]], 1).cpu().numpy()
