"""Calibration bursts for the int8 runtimes (``onnxruntime-int8``, ``openvino-int8``).

Post-training quantisation needs inputs that look like what the network will see: photos of
the training split (``$LBURST_SHARED/data/train``) at a random size of the pyramid's range,
made into noisy low-light bursts by :func:`lburst.simulate.simulate_burst` (random motion,
Gaussian or photon noise, seeded), aligned by :func:`lburst.burst.align.align_burst` as the
light weights' input is, and normalised by :func:`lburst.model.normalize_burst`.

:mod:`lburst.model` takes these from its caller (``LBurst.from_checkpoint(..., calibration=...)``)
and never imports the simulator; :func:`training_calibration` is the default that the learned
methods pass.
"""

from __future__ import annotations

import zlib
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from lburst.burst.align import align_burst
from lburst.burst.io import IMAGE_SUFFIXES, decode_file
from lburst.errors import LBurstFileNotFoundError, LBurstOSError, LBurstValueError
from lburst.model.network import normalize_burst
from lburst.noise import GaussianNoise, LowLightNoise
from lburst.paths import shared_dir
from lburst.simulate import random_motion, simulate_burst


def default_photo_folder() -> Path:
    """``$LBURST_SHARED/data/train`` (default ``../shared/data/train``), the training photos."""
    return shared_dir() / "data" / "train"


def training_photos(folder: str | Path | None = None) -> list[Path]:
    """The training split's photos under ``folder`` (default :func:`default_photo_folder`), sorted:
    the validation tenth is left out by the rule of :func:`lburst.train.data.is_validation_photo`
    (CRC-32 of the file stem divisible by 10; repeated here so that calibration does not load
    the training code)."""
    folder = Path(folder) if folder is not None else default_photo_folder()
    if not folder.is_dir():
        raise LBurstFileNotFoundError(f"{folder}: calibration photo folder not found (set LBURST_SHARED)")
    photos = sorted(
        p for p in folder.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES and zlib.crc32(p.stem.encode()) % 10
    )
    if not photos:
        raise LBurstFileNotFoundError(f"no training photos under {folder}")
    return photos


def calibration_bursts(
    photos: str | Path | Sequence[str | Path | np.ndarray] | None = None,
    count: int = 24,
    frames: int = 5,
    long_side: tuple[int, int] = (256, 768),
    seed: int = 0,
    align: bool = True,
) -> list[torch.Tensor]:
    """``count`` normalised bursts ``(1, 3 frames, H, W)`` for post-training quantisation.

    ``photos``: a folder (default :func:`default_photo_folder`, its training split), or a list
    of image files or RGB uint8 arrays.  Burst ``i`` is drawn with ``numpy.random.default_rng([seed, i])``:
    a photo, a long side uniform in ``long_side`` (the pyramid's range of sizes), a per-frame
    motion of up to 3 px, a darkening (exposure 0.15-1, probability 0.3) and either photon noise
    (3-60 photons at white, probability 1/3) or Gaussian noise of std 25-120 (the light
    network's training recipe, ``lburst train --preset lite``); it is then aligned (``align``,
    as the light weights read their input) and normalised."""
    import cv2

    if photos is None or isinstance(photos, (str, Path)):
        photos = training_photos(photos)
    if not len(photos):
        raise LBurstValueError("no calibration photos")
    out = []
    for i in range(count):
        rng = np.random.default_rng([seed, i])
        item = photos[int(rng.integers(len(photos)))]
        if isinstance(item, np.ndarray):
            photo = item
        else:
            bgr = decode_file(item, cv2.IMREAD_COLOR)
            if bgr is None:
                raise LBurstOSError(f"{item}: not a readable image")
            photo = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        target = rng.uniform(*long_side)
        scale = target / max(photo.shape[:2])
        size = (max(32, round(photo.shape[1] * scale)), max(32, round(photo.shape[0] * scale)))
        photo = cv2.resize(photo, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
        if rng.random() < 0.3:
            photo = np.clip(np.round(photo * rng.uniform(0.15, 1.0)), 0, 255).astype(np.uint8)
        if rng.random() < 1 / 3:
            noise = LowLightNoise(float(np.exp(rng.uniform(np.log(3.0), np.log(60.0)))))
        else:
            noise = GaussianNoise(float(rng.uniform(25.0, 120.0)))
        burst = simulate_burst(photo, frames, random_motion(rng, 3.0), noise, rng=rng)
        if align and frames > 1:
            burst = align_burst(burst)
        out.append(normalize_burst(burst))
    return out


def training_calibration(frames: int) -> list[torch.Tensor]:
    """The default calibration set of a ``frames``-frame network: :func:`calibration_bursts` of
    the training photos (24 bursts, seed 0)."""
    return calibration_bursts(frames=frames)
