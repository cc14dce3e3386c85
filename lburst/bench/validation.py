"""``lburst simulate sequences``: HPatches-style homography sequences from photos.

Made to choose weights on: from the held-out tenth of the training photos
(:func:`lburst.train.data.is_validation_photo`, never trained on) it writes one
six-image sequence per photo in the Oxford layout (``img1.png .. img6.png`` and
``H1to2p .. H1to6p``, 3x3 maps from image 1 to image K, pixel centres at integers),
which ``lburst bench homography`` reads like any other.

- ``v_<photo>`` (viewpoint, even photo indices): image 1 is the central 80% of the
  photo; image K shows the photo through a random homography about the crop centre:
  rotation uniform in +-25 degrees, scale log-uniform in 0.7-1.4, a perspective tilt
  up to 20% of the half-size and a shift up to 5% of the size; pixels that fall
  outside the photo are black.
- ``i_<photo>`` (illumination, odd indices): identity homographies; image K is image 1
  with a gain (0.4-1.5), a gamma (0.6-1.7) and, for half of them, a darkening (0.15-0.5)
  with a smooth left-right or top-bottom falloff.

Every draw comes from ``numpy.random.default_rng([seed, photo index])``, so the set
is the same on every machine; ``manifest.json`` records the photos, the rule and the seed.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from lburst.burst.io import atomic_path, read_image, write_image

CROP = 0.8


def _about_centre(m: np.ndarray, c: tuple[float, float]) -> np.ndarray:
    t = np.array([[1, 0, c[0]], [0, 1, c[1]], [0, 0, 1]], np.float64)
    return t @ m @ np.linalg.inv(t)


def viewpoint_homography(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """A random map of an image of ``size`` (w, h) onto itself (see the module docstring)."""
    w, h = size
    angle = np.deg2rad(rng.uniform(-25, 25))
    s = np.exp(rng.uniform(np.log(0.7), np.log(1.4)))
    sim = np.array([[s * np.cos(angle), -s * np.sin(angle), 0], [s * np.sin(angle), s * np.cos(angle), 0], [0, 0, 1]])
    half = np.array([w / 2, h / 2])
    src = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float32) * half.astype(np.float32)
    dst = src * (1 + rng.uniform(-0.2, 0.2, (4, 2)).astype(np.float32))
    tilt = cv2.getPerspectiveTransform(src, dst).astype(np.float64)
    shift = np.eye(3)
    shift[:2, 2] = rng.uniform(-0.05, 0.05, 2) * np.array([w, h])
    m = shift @ _about_centre(tilt @ sim, ((w - 1) / 2, (h - 1) / 2))
    return m / m[2, 2]


def illumination_change(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``image`` (uint8 RGB) under another gain, gamma and (half the time) a darkening falloff."""
    x = image.astype(np.float32) / 255.0
    x = np.clip(x * rng.uniform(0.4, 1.5), 0, 1) ** rng.uniform(0.6, 1.7)
    if rng.random() < 0.5:
        h, w = x.shape[:2]
        ramp = np.linspace(0, 1, w if rng.random() < 0.5 else h, dtype=np.float32)
        ramp = ramp if rng.random() < 0.5 else ramp[::-1]
        lo = rng.uniform(0.15, 0.5)
        falloff = lo + (1 - lo) * ramp
        x = x * (falloff[None, :, None] if len(ramp) == w else falloff[:, None, None])
    return np.clip(np.round(x * 255), 0, 255).astype(np.uint8)


def make_sequence(photo: np.ndarray, kind: str, rng: np.random.Generator) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Six images and the five homographies H1toK of one sequence of ``kind``."""
    ph, pw = photo.shape[:2]
    w, h = round(pw * CROP), round(ph * CROP)
    ox, oy = (pw - w) / 2, (ph - h) / 2
    to_photo = np.array([[1, 0, ox], [0, 1, oy], [0, 0, 1]], np.float64)
    first = cv2.warpPerspective(photo, to_photo, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    images, homographies = [first], []
    for _ in range(5):
        if kind == "v":
            hk = viewpoint_homography(rng, (w, h))
            # image K at q shows the photo at to_photo @ inv(hk) @ q
            img = cv2.warpPerspective(
                photo,
                to_photo @ np.linalg.inv(hk),
                (w, h),
                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_CONSTANT,
            )
        else:
            hk = np.eye(3)
            img = illumination_change(first, rng)
        images.append(img)
        homographies.append(hk)
    return images, homographies


def make_validation_sequences(photos: list[Path], out: str | Path, seed: int = 0, progress: bool = True) -> list[Path]:
    """Write one sequence per photo under ``out`` (skipping finished ones); returns the folders."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    folders = []
    for index, path in enumerate(tqdm(photos, desc="sequences", disable=not progress)):
        kind = "v" if index % 2 == 0 else "i"
        folder = out / f"{kind}_{path.parent.name}_{path.stem}"
        folders.append(folder)
        if (folder / "H1to6p").is_file():
            continue
        rng = np.random.default_rng([seed, index])
        images, homographies = make_sequence(read_image(path), kind, rng)
        folder.mkdir(exist_ok=True)
        for k, img in enumerate(images, 1):
            write_image(folder / f"img{k}.png", img)
        for k, hk in enumerate(homographies, 2):  # written last: a sequence with H1to6p is complete
            with atomic_path(folder / f"H1to{k}p") as tmp:
                np.savetxt(tmp, hk, fmt="%.10g")
    manifest = {
        "photos": [str(p) for p in photos],
        "seed": seed,
        "rule": "lburst.train.data.is_validation_photo: CRC-32 of the file stem divisible by 10",
    }
    with atomic_path(out / "manifest.json") as tmp:
        tmp.write_text(json.dumps(manifest, indent=1))
    return folders
