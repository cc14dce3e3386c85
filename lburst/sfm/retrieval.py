"""Loop-closure candidates by image retrieval from the features' own descriptors.

Each image gets one global descriptor, a VLAD vector (Jegou et al. 2010) of its local
descriptors over a small vocabulary: ``words`` k-means centres (seeded) of a sample of
all images' descriptors; residuals to the nearest centre are summed per centre, then
signed-square-rooted and L2-normalised (per centre and as a whole).  Binary descriptors
(packed bits) are unpacked to 0/1 floats first.  Two images are similar when the dot
product of their VLAD vectors is high; :func:`retrieval_pairs` keeps, for every image,
its ``num`` most similar images that are more than ``exclude`` apart in trajectory
order (the sequential pairs already cover the near ones), and returns them as pairs
``(i, j)``, ``i < j``, for geometric verification.
"""

from __future__ import annotations

import numpy as np
from scipy.cluster.vq import kmeans2


def _as_float(descriptors: np.ndarray) -> np.ndarray:
    if descriptors.dtype == np.uint8:
        return np.unpackbits(descriptors, axis=1).astype(np.float32)
    return np.asarray(descriptors, np.float32)


def vlad(descriptor_sets: list[np.ndarray], words: int = 32, sample: int = 50000, seed: int = 0) -> np.ndarray:
    """(n, words * D) L2-normalised VLAD vectors of ``n`` images' descriptors ``(K_i, D)`` (module docstring)."""
    rng = np.random.default_rng(seed)
    sets = [_as_float(d) for d in descriptor_sets]
    dim = next((d.shape[1] for d in sets if d.ndim == 2 and d.shape[1]), 1)
    pool = np.concatenate([d for d in sets if len(d)] or [np.zeros((0, dim), np.float32)])
    if len(pool) < words:
        return np.zeros((len(sets), words * dim), np.float32)
    if len(pool) > sample:
        pool = pool[rng.choice(len(pool), sample, replace=False)]
    centres, _ = kmeans2(pool.astype(np.float64), words, minit="++", seed=rng, iter=10)
    centres = centres.astype(np.float32)
    out = np.zeros((len(sets), words, dim), np.float32)
    for i, d in enumerate(sets):
        if not len(d):
            continue
        dist = (d**2).sum(1)[:, None] - 2 * d @ centres.T + (centres**2).sum(1)[None]
        nearest = np.argmin(dist, axis=1)
        np.add.at(out[i], nearest, d - centres[nearest])
    out = np.sign(out) * np.sqrt(np.abs(out))
    out /= np.maximum(np.linalg.norm(out, axis=2, keepdims=True), 1e-12)
    out = out.reshape(len(sets), -1)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)


def retrieval_pairs(global_descriptors: np.ndarray, num: int, exclude: int) -> list[tuple[int, int]]:
    """For each image its ``num`` most similar images more than ``exclude`` apart, as sorted pairs ``(i, j)``."""
    if num < 1:
        return []
    g = np.asarray(global_descriptors, np.float32)
    n = len(g)
    sim = g @ g.T
    idx = np.arange(n)
    sim[np.abs(idx[:, None] - idx[None]) <= exclude] = -np.inf
    pairs = set()
    for i in range(n):
        for j in np.argsort(-sim[i])[:num]:
            if np.isfinite(sim[i, j]):
                pairs.add((min(i, int(j)), max(i, int(j))))
    return sorted(pairs)
