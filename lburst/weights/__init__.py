"""Weights shipped with lburst, trained by this project's own code (see the model cards here)."""

from __future__ import annotations

from pathlib import Path

from lburst.errors import LBurstFileNotFoundError, LBurstValueError

HERE = Path(__file__).parent
NAMES = ("lburst-b5", "lburst-b1", "lburst-b5-lite")


def weights_path(name: str) -> Path:
    """Path of the shipped checkpoint ``name`` (one of :data:`NAMES`)."""
    if name not in NAMES:
        raise LBurstValueError(f"unknown weights {name!r}; shipped: {', '.join(NAMES)}")
    path = HERE / f"{name}.pt"
    if not path.is_file():
        raise LBurstFileNotFoundError(
            f"{name} weights are not shipped in this version ({path} missing; see lburst/weights/README.md): "
            "pass a checkpoint with --weights PATH or set LBURST_WEIGHTS"
        )
    return path


def resolve_weights(spec: str | Path) -> Path:
    """``spec`` as a checkpoint path: an existing file, or the name of shipped weights."""
    path = Path(spec)
    if path.is_file() or str(spec) not in NAMES:
        return path
    return weights_path(str(spec))
