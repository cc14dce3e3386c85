"""Reference cameras of a scene's common frames (``SCENE/reference.json``).

A scene folder holds one sub-folder per burst (``SCENE/<burst>/frame_000.png`` ...,
in trajectory order) and optionally ``reference.json``::

    {"source": "synthetic" | "sift-clean" | ...,
     "camera": {"model": "PINHOLE", "width": W, "height": H, "params": [fx, fy, cx, cy]},
     "images": {"<burst>": {"R": [[...], [...], [...]], "t": [tx, ty, tz]}, ...},
     "length": trajectory length in world units (or null),
     "calibrated": true | false}

``calibrated`` (optional; true by default for ``"synthetic"``, false otherwise) says that the
cameras are a calibration, not an estimate from these images: ``lburst reconstruct`` then
uses them as the cameras by default, held fixed, as it does a recording's ``meta.json`` camera.

Conventions are COLMAP's own: ``R`` (3x3) and ``t`` (3,) map world to camera,
``x_cam = R @ x_world + t``, the camera looks along +z with x right and y down, and a
camera point projects to pixel ``(fx * x / z + cx, fy * y / z + cy)`` where the centre
of the top-left pixel is ``(0.5, 0.5)`` (so a centred principal point is
``cx = W / 2, cy = H / 2``).  Subtract 0.5 for lburst keypoints (``(0, 0)`` centre).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lburst.burst.io import atomic_path
from lburst.errors import LBurstValueError


@dataclass
class Reference:
    """Reference cameras of a scene.

    Attributes:
        source: where the poses come from (``'synthetic'`` is exact ground truth).
        camera: COLMAP camera dict ``{"model": "PINHOLE", "width", "height", "params"}``.
        poses: burst name -> ``(R (3, 3), t (3,))`` world-to-camera, float64.
        length: trajectory length in world units, or ``None`` if unknown.
        calibrated: the cameras are a calibration (module docstring); ``None``: by ``source``.
    """

    source: str
    camera: dict
    poses: dict[str, tuple[np.ndarray, np.ndarray]]
    length: float | None = None
    calibrated: bool | None = None

    @property
    def is_calibration(self) -> bool:
        """Whether the cameras are a calibration (``calibrated``, else ``source == 'synthetic'``)."""
        return self.source == "synthetic" if self.calibrated is None else self.calibrated

    def centers(self) -> dict[str, np.ndarray]:
        """Camera centre ``C = -R^T t`` (3,) in world coordinates of every image."""
        return {name: -R.T @ t for name, (R, t) in self.poses.items()}

    def intrinsics(self) -> np.ndarray:
        """3x3 calibration matrix K (COLMAP pixel convention, see module docstring)."""
        fx, fy, cx, cy = (float(v) for v in self.camera["params"][:4])
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    def project(self, name: str, points: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) (COLMAP convention) of world points (N, 3) seen by image ``name``."""
        R, t = self.poses[name]
        cam = np.asarray(points, dtype=np.float64) @ R.T + t
        uvw = cam @ self.intrinsics().T
        return uvw[:, :2] / uvw[:, 2:3]

    def to_json(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "camera": {
                "model": str(self.camera["model"]),
                "width": int(self.camera["width"]),
                "height": int(self.camera["height"]),
                "params": [float(v) for v in self.camera["params"]],
            },
            "images": {
                name: {"R": np.asarray(R, dtype=float).tolist(), "t": np.asarray(t, dtype=float).tolist()}
                for name, (R, t) in self.poses.items()
            },
            "length": None if self.length is None else float(self.length),
            **({} if self.calibrated is None else {"calibrated": self.calibrated}),
        }

    def save(self, path: str | Path) -> None:
        """Write ``reference.json`` atomically."""
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(self.to_json(), indent=1))

    @classmethod
    def load(cls, path: str | Path) -> "Reference":
        """Read ``reference.json``; a malformed file raises ``ValueError`` naming it."""
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise LBurstValueError(f"{path}: not valid JSON ({err})") from err
        try:
            return cls._from_json(data)
        except (KeyError, TypeError, ValueError) as err:
            problem = f"no {err.args[0]}" if isinstance(err, KeyError) else str(err)
            raise LBurstValueError(f"{path}: malformed reference file: {problem}") from err

    @classmethod
    def _from_json(cls, data: Any) -> "Reference":
        if not isinstance(data, dict):
            raise TypeError("top level must be a JSON object")
        camera = data["camera"]
        for key in ("model", "width", "height", "params"):
            if key not in camera:
                raise KeyError(f"camera.{key}")
        if len(camera["params"]) < 4:
            raise LBurstValueError(f"camera.params needs at least 4 values, got {camera['params']}")
        for key in ("width", "height"):
            if isinstance(camera[key], bool) or not isinstance(camera[key], int) or camera[key] < 1:
                raise LBurstValueError(f"camera.{key} must be a positive integer, got {camera[key]!r}")
        params = np.asarray(camera["params"], dtype=np.float64)
        if not np.all(np.isfinite(params)) or params[0] <= 0:
            raise LBurstValueError(f"camera.params must be finite with a positive focal length, got {camera['params']}")
        poses: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for name, pose in data["images"].items():
            R = np.asarray(pose["R"], dtype=np.float64)
            t = np.asarray(pose["t"], dtype=np.float64)
            if R.shape != (3, 3) or t.shape != (3,):
                raise LBurstValueError(f"image {name!r}: R must be 3x3 and t length 3, got {R.shape} and {t.shape}")
            if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
                raise LBurstValueError(f"image {name!r}: R and t must be finite (no NaN or inf)")
            if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
                raise LBurstValueError(f"image {name!r}: R is not a rotation (orthonormal, determinant +1)")
            poses[name] = (R, t)
        length = data.get("length")
        if length is not None and (isinstance(length, bool) or not np.isfinite(float(length)) or float(length) <= 0):
            raise LBurstValueError(f"length must be a positive number of metres, got {length!r}")
        calibrated = data.get("calibrated")
        if calibrated is not None and not isinstance(calibrated, bool):
            raise LBurstValueError(f"calibrated must be true or false, got {calibrated!r}")
        return cls(
            source=str(data["source"]),
            camera=dict(camera),
            poses=poses,
            length=None if length is None else float(length),
            calibrated=calibrated,
        )
