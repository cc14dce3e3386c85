"""Exact cameras of a photo set in Strecha's format (Strecha et al., CVPR 2008), as a calibrated reference.

A photo ``PHOTOS/<name>.jpg`` has its camera in ``gt_cameras/<name>.jpg.camera`` (the folder
beside ``PHOTOS``, :func:`cameras_folder`), a text file of 9 lines for the *original* image
size: lines 1-3 the intrinsic matrix K, line 4 the radial distortion (zero: the photos are
undistorted), lines 5-7 the rotation R from camera to world (a world point X projects as
``K R^T (X - C)``), line 8 the camera centre C, line 9 the original width and height.

A photo set may be the originals resized (``castle-P30``: 3072x2048 to 1024x683).  K is scaled
to the photo's size per axis, ``s = W'/W`` and ``H'/H``: ``f' = f s``, and the principal point in
OpenCV's pixel-centre convention (``(0, 0)`` the centre of the top-left pixel, as Strecha's
files have it) ``c' = (c + 0.5) s - 0.5``, which is ``(c + 0.5) s`` in COLMAP's convention
(:mod:`lburst.sfm.reference`).  Each photo gets its own ``PINHOLE`` camera, and the pose
world-to-camera ``R_wc = R^T``, ``t = -R^T C`` (metres).  The reference's ``source`` is
``'strecha'`` and it is ``calibrated``: the cameras are exact, so ``lburst reconstruct`` and
``lburst bench reconstruction`` can hold them fixed (``--camera reference --fix-intrinsics``) or
start from their focal length (``--camera reference-focal``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lburst.errors import LBurstValueError
from lburst.sfm.poses import path_length
from lburst.sfm.reference import Reference
from lburst.sfm.scene import save_reference

SOURCE = "strecha"
CAMERAS_DIR = "gt_cameras"
SUFFIX = ".camera"
ROTATION_TOL = 1e-3  # the files give 6 significant digits: |R R^T - I| stays far below this


class CameraFileError(LBurstValueError):
    """A Strecha camera file that cannot be read; the message names it."""


def cameras_folder(photos: str | Path) -> Path | None:
    """The ``gt_cameras/`` folder beside the photo folder ``photos`` (``SET/images`` ->
    ``SET/gt_cameras``), or ``None`` when there is none."""
    folder = Path(photos).resolve().parent / CAMERAS_DIR
    return folder if folder.is_dir() else None


def read_camera(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
    """``(K (3, 3), R camera-to-world (3, 3), C (3,), (W, H))`` of one camera file (module
    docstring); :class:`CameraFileError` naming the file when it is malformed."""
    path = Path(path)
    try:
        rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
    except (OSError, UnicodeDecodeError) as err:
        raise CameraFileError(f"{path}: cannot read the camera file ({err})") from None
    sizes = [len(r) for r in rows]
    if len(rows) != 9 or sizes[:3] != [3, 3, 3] or sizes[4:8] != [3, 3, 3, 3] or sizes[8] != 2:
        raise CameraFileError(
            f"{path}: a Strecha camera file has 9 lines (K, distortion, R, C, size), "
            f"got {len(rows)} with {sizes} numbers"
        )
    try:
        values = [[float(v) for v in r] for r in rows]
    except ValueError:
        raise CameraFileError(f"{path}: not a Strecha camera file (a value is not a number)") from None
    if not all(np.isfinite(v).all() for v in values):
        raise CameraFileError(f"{path}: a value is not finite")
    K, distortion, R, C = np.array(values[0:3]), np.array(values[3]), np.array(values[4:7]), np.array(values[7])
    size = values[8]
    if any(v != int(v) or v < 1 for v in size):
        raise CameraFileError(f"{path}: the image size (line 9) must be two positive integers, got {rows[8]}")
    if K[0, 0] <= 0 or K[1, 1] <= 0 or K[0, 1] != 0 or not np.array_equal(K[2], [0, 0, 1]) or K[1, 0] != 0:
        raise CameraFileError(f"{path}: K (lines 1-3) must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
    if np.any(distortion != 0):
        raise CameraFileError(f"{path}: non-zero distortion (line 4) is not supported: undistort the photos")
    if not np.allclose(R @ R.T, np.eye(3), atol=ROTATION_TOL) or np.linalg.det(R) < 0:
        raise CameraFileError(f"{path}: R (lines 5-7) is not a rotation")
    U, _, Vt = np.linalg.svd(R)  # the nearest exact rotation to the rounded one in the file
    return K, U @ Vt, C, (int(size[0]), int(size[1]))


def scaled_camera(K: np.ndarray, original: tuple[int, int], size: tuple[int, int]) -> dict:
    """The ``PINHOLE`` COLMAP camera dict of ``K`` (for an image of ``original`` (W, H), OpenCV's
    pixel centres) on the same image resized to ``size`` (W, H), in COLMAP's pixel convention."""
    sx, sy = size[0] / original[0], size[1] / original[1]
    return {
        "model": "PINHOLE",
        "width": int(size[0]),
        "height": int(size[1]),
        "params": [K[0, 0] * sx, K[1, 1] * sy, (K[0, 2] + 0.5) * sx, (K[1, 2] + 0.5) * sy],
    }


def camera_file(folder: Path, photo: Path) -> Path:
    """The camera file of ``photo`` in ``folder``: ``<photo file name>.camera``."""
    return folder / f"{photo.name}{SUFFIX}"


def strecha_reference(
    folder: str | Path, photos: Sequence[tuple[str, Path, tuple[int, int]]]
) -> tuple[Reference, dict]:
    """The calibrated reference and per-image cameras of ``photos`` ``(name, path, (W, H))``, in
    scene order, from their camera files in ``folder``; :class:`CameraFileError` naming a file
    that is missing or malformed."""
    folder = Path(folder)
    poses, cameras = {}, {}
    for name, photo, size in photos:
        path = camera_file(folder, photo)
        if not path.is_file():
            raise CameraFileError(f"{path}: no camera file for photo {photo.name}")
        K, R, C, original = read_camera(path)
        if abs(original[0] / original[1] - size[0] / size[1]) > 2 / min(size):
            raise CameraFileError(
                f"{path}: camera for {original[0]}x{original[1]} images, but {photo.name} is {size[0]}x{size[1]} "
                "(another aspect ratio)"
            )
        cameras[name] = scaled_camera(K, original, size)
        poses[name] = (R.T, -R.T @ C)
    centres = np.array([-R.T @ t for R, t in poses.values()])
    first = next(iter(cameras.values()))
    return Reference(SOURCE, first, poses, path_length(centres), calibrated=True), cameras


def save_strecha_reference(
    folder: str | Path, photos: Sequence[tuple[str, Path, tuple[int, int]]], path: str | Path
) -> Reference:
    """Write the reference of :func:`strecha_reference` to ``path`` (``reference.json``) and return it."""
    reference, cameras = strecha_reference(folder, photos)
    save_reference(reference, path, cameras)
    return reference
