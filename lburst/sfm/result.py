"""What a reconstruction gives: a :class:`ReconstructionResult` (saved as ``OUT/result.json``)
with one :class:`Status` and one ``error``, or a :class:`ReconstructionError` for an input
that cannot be reconstructed."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from lburst.burst.io import atomic_path, read_features_npz
from lburst.errors import LBurstError
from lburst.strenum import StrEnum

RESULT_FILE = "result.json"


class ReconstructionError(LBurstError, RuntimeError):
    """A scene that cannot be reconstructed (bad input); the message says which file and why."""


class Status(StrEnum):
    """How a reconstruction ended; ``error`` says why for every status but ``COMPLETE`` and
    ``NO_MODEL`` (where it is ``None`` unless the recording stopped early too)."""

    COMPLETE = "complete"  # a model, every image read
    PARTIAL = "partial"  # a model of the keyframes read before the recording stopped (error: why it stopped)
    NO_MODEL = "no_model"  # COLMAP ran and registered no model
    COLMAP_FAILED = "colmap_failed"  # COLMAP failed (error: its message)
    SOURCE_FAILED = "source_failed"  # the recording stopped before 2 keyframes were read; COLMAP did not run


@dataclass
class ReconstructionResult:
    """One method on one scene.

    Attributes:
        scene, method, out_dir: what was run and where its files are.
        names: all images of the scene in trajectory order.
        registered: names of the images in the largest model.
        poses: name -> ``(R (3, 3), t (3,))`` world-to-camera (COLMAP convention, model's frame).
        cameras: name -> COLMAP camera dict of the registered images (as refined).
        metrics: the table's columns (:mod:`lburst.sfm.metrics`), reference ones included
            when the scene has a reference.
        positions: what the position priors did (:func:`lburst.sfm.positions.prior_fit`:
            their source, count and origin, how far the model lies from them), ``None``
            without priors.
        checks: whether the model can be trusted without ground truth
            (:func:`lburst.sfm.trust.assess`: ``trusted``, the ``reasons`` when not, and the
            ``measures``), ``None`` without a model.
        status: how it ended (:class:`Status`).
        error: why COLMAP failed or the recording stopped early (both when both), or ``None``.
    """

    scene: str
    method: str
    out_dir: str
    names: list[str]
    registered: list[str] = field(default_factory=list)
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    cameras: dict[str, dict] = field(default_factory=dict)
    metrics: dict[str, float | int | str | None] = field(default_factory=dict)
    positions: dict | None = None
    checks: dict | None = None
    status: Status = Status.NO_MODEL
    error: str | None = None

    @property
    def converged(self) -> bool:
        return bool(self.metrics.get("converged"))

    @property
    def trusted(self) -> bool:
        """A model that passed its checks (:attr:`checks`); ``False`` without a model."""
        return bool(self.checks and self.checks.get("trusted"))

    @property
    def failed(self) -> bool:
        """COLMAP failed, or did not run: no metrics of a model to use."""
        return self.status in (Status.COLMAP_FAILED, Status.SOURCE_FAILED)

    def to_json(self) -> dict:
        data = asdict(self)
        data["status"] = str(self.status)
        data["poses"] = {
            n: {"R": np.asarray(R).tolist(), "t": np.asarray(t).tolist()} for n, (R, t) in self.poses.items()
        }
        return data

    def save(self, path: str | Path | None = None) -> Path:
        path = Path(path or Path(self.out_dir) / RESULT_FILE)
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(self.to_json(), indent=1))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "ReconstructionResult":
        data = json.loads(Path(path).read_text())
        data["poses"] = {n: (np.array(p["R"]), np.array(p["t"])) for n, p in data["poses"].items()}
        if "status" not in data:  # written before Status: error (COLMAP's) and source_error
            data.update(_legacy_status(data.get("error"), data.pop("source_error", None), data.get("metrics", {})))
        data["status"] = Status(data["status"])
        return cls(**data)

    def match_data(self) -> tuple[list[np.ndarray], np.ndarray, list[np.ndarray]] | None:
        """Keypoints (lburst convention) of every image, verified pairs (Q, 2) and their inliers, from ``out_dir``."""
        out = Path(self.out_dir)
        verified = out / "colmap" / "verified.npz"
        if not verified.is_file():
            return None
        keypoints = [read_features_npz(out / "features" / f"{name}.npz")["keypoints"] for name in self.names]
        data = np.load(verified)
        pairs = data["pairs"].reshape(-1, 2)
        return keypoints, pairs, [data[f"inl_{q}"] for q in range(len(pairs))]


def ended(colmap_error: str | None, source_error: str | None, converged: bool) -> tuple[Status, str | None]:
    """The status and error of a run whose COLMAP ended with ``colmap_error`` (or none) after
    reading its input up to ``source_error`` (or to the end)."""
    if colmap_error:
        return Status.COLMAP_FAILED, colmap_error + (
            f"; reading the recording stopped early: {source_error}" if source_error else ""
        )
    if not converged:
        return Status.NO_MODEL, source_error
    return (Status.PARTIAL, source_error) if source_error else (Status.COMPLETE, None)


def _legacy_status(error: str | None, source_error: str | None, metrics: dict) -> dict:
    if source_error and error and "before the recording stopped" in error:
        return {"status": Status.SOURCE_FAILED, "error": f"{source_error} ({error})"}
    status, message = ended(error, source_error, bool(metrics.get("converged")))
    return {"status": status, "error": message}
