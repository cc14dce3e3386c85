"""Bursts to a 3D model with COLMAP (pycolmap), and the paper's reconstruction metrics.

Public API: :func:`reconstruct_scene` (one scene, one feature method) returning a
:class:`ReconstructionResult` (its :class:`Status` and ``error``) and taking
:class:`ReconstructOptions`, and :func:`evaluate_against_reference` (trajectory
errors and match precision against a scene's ``reference.json``).  They are imported on
first use, so that the COLMAP child (``python -m lburst.cli.colmap_job``) and
:mod:`lburst.sfm.poses` import no torch.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "ReconstructOptions": "lburst.sfm.options",
    "ReconstructionError": "lburst.sfm.result",
    "ReconstructionResult": "lburst.sfm.result",
    "Status": "lburst.sfm.result",
    "reconstruct_scene": "lburst.sfm.reconstruct",
    "evaluate_against_reference": "lburst.sfm.metrics",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'lburst.sfm' has no attribute {name!r}")
