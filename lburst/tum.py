"""TUM trajectory text files: one pose per line, ``timestamp tx ty tz qx qy qz qw``.

The pose is camera-to-world (the camera centre ``t`` and the rotation ``q``, a unit
quaternion in scalar-last order, taking camera axes to world axes), as the TUM RGB-D
benchmark and ``evo`` read it.  Lines starting with ``#`` are comments.  lburst poses
elsewhere are world-to-camera ``(R, t)`` (COLMAP's); :func:`to_tum_row` and
:func:`from_tum_row` convert.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from lburst.burst.io import atomic_path
from lburst.errors import LBurstValueError

Pose = tuple[np.ndarray, np.ndarray]  # world-to-camera (R (3, 3), t (3,))


def to_tum_row(pose: Pose) -> np.ndarray:
    """``(tx, ty, tz, qx, qy, qz, qw)`` camera-to-world of a world-to-camera pose."""
    R, t = (np.asarray(a, np.float64) for a in pose)
    centre = -R.T @ t
    return np.concatenate([centre, Rotation.from_matrix(R.T).as_quat()])


def from_tum_row(row: np.ndarray) -> Pose:
    """World-to-camera ``(R, t)`` of a TUM row's last seven values."""
    row = np.asarray(row, np.float64)
    R_wc = Rotation.from_quat(row[3:7]).as_matrix()
    return R_wc.T, -R_wc.T @ row[:3]


def write_tum(path: str | Path, times: list[float] | np.ndarray, poses: list[Pose], header: str | None = None) -> Path:
    """Write poses (world-to-camera) at ``times`` (seconds) as a TUM file, atomically."""
    if len(times) != len(poses):
        raise LBurstValueError(f"{len(times)} timestamps for {len(poses)} poses")
    lines = [f"# {line}" for line in (header or "").splitlines()]
    lines.append("# timestamp tx ty tz qx qy qz qw")
    for time, pose in zip(times, poses):
        lines.append(f"{float(time):.6f} " + " ".join(f"{v:.9f}" for v in to_tum_row(pose)))
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return path


def read_tum(path: str | Path) -> tuple[np.ndarray, list[Pose]]:
    """Timestamps (N,) and world-to-camera poses of a TUM file; ``ValueError`` naming the file and line."""
    path = Path(path)
    times, poses = [], []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        values = line.replace(",", " ").split()
        if len(values) != 8:
            raise LBurstValueError(
                f"{path}:{number}: expected 8 values (timestamp tx ty tz qx qy qz qw), got {len(values)}"
            )
        row = np.array([float(v) for v in values])
        times.append(row[0])
        poses.append(from_tum_row(row[1:]))
    return np.array(times), poses


def lookup(times: np.ndarray, poses: list[Pose], time: float, tolerance: float = 1e-3) -> Pose | None:
    """The pose whose timestamp is within ``tolerance`` s of ``time``, else ``None``."""
    if len(times) == 0:
        return None
    i = int(np.argmin(np.abs(times - time)))
    return poses[i] if abs(times[i] - time) <= tolerance else None
