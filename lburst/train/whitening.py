"""Descriptor whitening: statistics of a model's descriptors, stored with its weights.

A network trained on noisy bursts gives its descriptors a large common component (the
mean keypoint descriptor of lburst-b5 has a norm of about 0.55) and spends most of their
variance in a few directions. Under cosine similarity the common component makes
descriptors near the mean the nearest neighbour of many others, and the dominant
directions drown the rest, which loses mutual matches. The remedy is PCA whitening, as in
image retrieval (Jegou and Chum 2012): ``normalize(W (d - mean))`` with
``W = V diag(lambda + eps)^(-power / 2) V^T`` from the eigen-decomposition of the
descriptors' covariance, ``eps`` a small fraction of the mean eigenvalue.

The statistics are measured once on training photos (never the validation tenth), over
the keypoint descriptors of one synthetic burst per photo: a random shift of up to
``max_shift`` px per frame and Gaussian noise of a standard deviation drawn from
``noise_std`` (0..255), so that they cover clean and noisy input alike. They are kept in
the checkpoint's ``meta`` (``descriptor_mean``, ``descriptor_whitening``) and applied by
:class:`lburst.model.extractor.LBurst` when asked (``whiten=True``; the method option
``lburst,whiten=true``). It is not the default: it raises the mutual matches and the
correct ones, but lowers the share of correct ones (docs/training.md).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from lburst.burst.io import read_image
from lburst.errors import LBurstValueError
from lburst.model.extractor import LBurst
from lburst.model.network import load_checkpoint, save_checkpoint
from lburst.noise import GaussianNoise
from lburst.simulate import simulate_burst
from lburst.train.data import list_photos

EPS = 0.01  # eigenvalue floor, as a fraction of the mean eigenvalue


def sample_photos(folders: Sequence[str | Path], count: int, seed: int = 0) -> list[Path]:
    """``count`` training photos of ``folders`` (never the validation tenth), drawn by ``seed``, sorted."""
    if count < 1:
        raise LBurstValueError(f"count must be at least 1, got {count}")
    photos = list_photos(list(folders), split="train")
    pick = np.random.default_rng(seed).choice(len(photos), min(count, len(photos)), replace=False)
    return [photos[i] for i in sorted(pick)]


def descriptor_statistics(
    model: LBurst,
    photos: Sequence[str | Path],
    rng: np.random.Generator,
    noise_std: tuple[float, float] = (0.0, 120.0),
    max_shift: float = 3.0,
    top_k: int = 2000,
    progress: bool = True,
    extract_options: Mapping[str, Any] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean (D,) and covariance (D, D) of ``model``'s raw (never whitened) keypoint descriptors over one
    synthetic burst per photo (``extract_options``: :class:`lburst.model.extractor.MultiScaleConfig` fields)."""
    if not photos:
        raise LBurstValueError("no photos to measure descriptor statistics on")
    total = outer = None
    count = 0
    for photo in tqdm(photos, desc="descriptor statistics", disable=not progress, leave=False):
        shift = rng.uniform(-max_shift, max_shift, size=2)
        noise = GaussianNoise(float(rng.uniform(*noise_std)))
        burst = simulate_burst(read_image(photo), model.frames, tuple(shift), noise, rng)
        desc = model.extract(burst, top_k=top_k, **{**(extract_options or {}), "whiten": False})["descriptors"].astype(
            np.float64
        )
        total = desc.sum(0) if total is None else total + desc.sum(0)
        outer = desc.T @ desc if outer is None else outer + desc.T @ desc
        count += len(desc)
    if count < 2:
        raise LBurstValueError("the model found fewer than 2 keypoints on the photos")
    mean = total / count
    cov = (outer - count * np.outer(mean, mean)) / (count - 1)
    return mean.astype(np.float32), cov


def whitening_matrix(cov: np.ndarray, power: float = 1.0, eps: float = EPS) -> np.ndarray:
    """Symmetric (D, D) ``V diag(lambda + eps * mean(lambda))^(-power / 2) V^T`` of ``cov``."""
    cov = np.asarray(cov, np.float64)
    if cov.ndim != 2 or cov.shape[0] != cov.shape[1] or not np.isfinite(cov).all():
        raise LBurstValueError(f"expected a finite square covariance, got shape {cov.shape}")
    lam, vec = np.linalg.eigh((cov + cov.T) / 2)
    lam = np.clip(lam, 0, None)
    scale = (lam + eps * max(lam.mean(), 1e-12)) ** (-power / 2)
    return ((vec * scale) @ vec.T).astype(np.float32)


def whiten_checkpoint(
    checkpoint: str | Path,
    out: str | Path,
    photos: Sequence[str | Path],
    seed: int = 0,
    power: float = 1.0,
    **options: Any,
) -> tuple[np.ndarray, np.ndarray]:
    """Write ``checkpoint`` to ``out`` with ``meta['descriptor_mean']`` and
    ``meta['descriptor_whitening']`` measured on ``photos`` (:func:`descriptor_statistics`,
    ``options`` passed on); returns the mean and the whitening matrix."""
    net, extra = load_checkpoint(checkpoint)
    meta = {k: v for k, v in (extra.get("meta") or {}).items() if not k.startswith("descriptor_")}
    model = LBurst(net, "cpu", align=meta.get("input") == "aligned")
    with torch.inference_mode():
        mean, cov = descriptor_statistics(model, photos, np.random.default_rng(seed), **options)
    matrix = whitening_matrix(cov, power)
    meta.update(
        descriptor_mean=torch.from_numpy(mean),
        descriptor_whitening=torch.from_numpy(matrix),
        descriptor_statistics={"photos": len(photos), "seed": seed, "power": power, "eps": EPS},
    )
    save_checkpoint(net, out, meta=meta)
    return mean, matrix
