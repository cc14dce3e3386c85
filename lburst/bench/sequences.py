"""Homography sequences: Oxford layout (``img1..img6`` + ``H1to2p..H1to6p``) or HPatches
layout (``1.ppm..6.ppm`` + ``H_1_2..H_1_6``).  ``H1toK`` maps pixel coordinates of image 1
to image K (pixel centres at integer coordinates, as lburst keypoints)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from lburst.burst.io import IMAGE_SUFFIXES, BurstError, read_image, to_uint8
from lburst.errors import LBurstFileNotFoundError, LBurstValueError
from lburst.photometric import color_jitter
from lburst.rotation import rotate_image
from lburst.simulate import stable_seed


@dataclass
class Sequence:
    """``images``: 6 RGB arrays (H, W, 3); ``homographies[k]``: 3x3 from image 1 to image k+2."""

    name: str
    images: list[np.ndarray]
    homographies: list[np.ndarray]

    @property
    def kind(self) -> str:
        """``viewpoint``/``illumination`` for HPatches names (``v_``/``i_``), else ``other``."""
        return {"v_": "viewpoint", "i_": "illumination"}.get(self.name[:2], "other")


def _find_image(folder: Path, stem: str) -> Path:
    hits = sorted(p for p in folder.glob(f"{stem}.*") if p.suffix.lower() in IMAGE_SUFFIXES)
    if not hits:
        raise LBurstFileNotFoundError(f"{folder}: no image {stem}.png/.ppm/...")
    return hits[0]


def _read_h(path: Path) -> np.ndarray:
    if not path.is_file():
        raise LBurstFileNotFoundError(f"{path}: homography file missing")
    try:
        h = np.loadtxt(path, dtype=np.float64)
    except ValueError as exc:
        raise LBurstValueError(f"{path}: not a 3x3 matrix of numbers ({exc})") from exc
    if h.shape != (3, 3):
        raise LBurstValueError(f"{path}: expected a 3x3 matrix, got shape {h.shape}")
    return check_homography(h, path)


def check_homography(h: np.ndarray, where: str | Path) -> np.ndarray:
    """``h`` if it is a usable ground-truth homography: finite and invertible (its smallest
    singular value above 1e-9 of its largest); else ``ValueError`` naming ``where``."""
    if not np.all(np.isfinite(h)):
        raise LBurstValueError(f"{where}: homography holds NaN or inf")
    singular = np.linalg.svd(h, compute_uv=False)
    if singular[0] == 0 or singular[-1] <= 1e-9 * singular[0]:
        raise LBurstValueError(f"{where}: homography is singular (rank {int(np.sum(singular > 1e-9 * singular[0]))})")
    return h


def resize_matrix(scale_x: float, scale_y: float) -> np.ndarray:
    """Pixel map of a resize by (sx, sy) with pixel centres at integer coordinates:
    ``x' = (x + 0.5) * sx - 0.5``."""
    return np.array([[scale_x, 0, 0.5 * (scale_x - 1)], [0, scale_y, 0.5 * (scale_y - 1)], [0, 0, 1]])


def read_sequence(folder: str | Path, max_side: int | None = None) -> Sequence:
    """Read one sequence; with ``max_side`` images larger than that are resized and the
    homographies composed with the resizes."""
    folder = Path(folder)
    if (folder / "H1to2p").exists() or list(folder.glob("img1.*")):
        stems, hfiles = [f"img{i}" for i in range(1, 7)], [f"H1to{k}p" for k in range(2, 7)]
    else:
        stems, hfiles = [str(i) for i in range(1, 7)], [f"H_1_{k}" for k in range(2, 7)]
    try:
        images = [read_image(_find_image(folder, s)) for s in stems]
    except BurstError as exc:
        raise LBurstValueError(str(exc)) from exc
    images = [to_uint8(im) for im in images]
    homographies = [_read_h(folder / f) for f in hfiles]
    if max_side:
        mats = []
        for i, im in enumerate(images):
            h, w = im.shape[:2]
            s = min(1.0, max_side / max(h, w))
            size = (max(1, round(w * s)), max(1, round(h * s)))
            if s < 1:
                images[i] = cv2.resize(im, size, interpolation=cv2.INTER_AREA)
            mats.append(resize_matrix(size[0] / w, size[1] / h))
        homographies = [mats[k + 1] @ h @ np.linalg.inv(mats[0]) for k, h in enumerate(homographies)]
    return Sequence(folder.name, images, homographies)


def rotate_sequence(seq: Sequence, deg: float) -> Sequence:
    """``seq`` with images 2-6 turned in-plane by ``deg`` about their centre
    (:func:`lburst.rotation.rotate_image`), and the homographies composed with the turn."""
    if float(deg) == 0:
        return seq
    turned = [rotate_image(im, deg) for im in seq.images[1:]]
    return Sequence(
        seq.name,
        [seq.images[0], *(im for im, _ in turned)],
        [m @ h for (_, m), h in zip(turned, seq.homographies)],
    )


def recolor_sequence(seq: Sequence, jitter: tuple[float, float, float, float]) -> Sequence:
    """``seq`` with images 2-6 each changed in colour (:func:`lburst.photometric.color_jitter`,
    seeded by the sequence's name and the image's number, the same in every run)."""
    if not any(jitter):
        return seq
    changed = []
    for k, image in enumerate(seq.images[1:], start=2):
        rng = np.random.default_rng(stable_seed(seq.name, k, "color", *jitter))
        changed.append(np.round(color_jitter(image, rng, jitter)).astype(np.uint8))
    return Sequence(seq.name, [seq.images[0], *changed], seq.homographies)


def list_sequences(data: str | Path) -> list[Path]:
    """Sequence folders under ``data`` (sorted); error if none."""
    data = Path(data)
    if not data.is_dir():
        raise LBurstFileNotFoundError(f"{data}: no such folder")
    folders = sorted(p for p in data.iterdir() if p.is_dir() and ((p / "H1to2p").exists() or (p / "H_1_2").exists()))
    if not folders:
        raise LBurstFileNotFoundError(f"{data}: no sequence folders (with H1to2p or H_1_2)")
    return folders
