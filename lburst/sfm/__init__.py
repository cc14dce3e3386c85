"""Bursts to a 3D model with COLMAP (pycolmap), and the paper's reconstruction metrics.

Public API: :func:`reconstruct_scene` (one scene, one feature method) returning a
:class:`ReconstructionResult`, and :func:`evaluate_against_reference` (trajectory
errors and match precision against a scene's ``reference.json``).
"""

from lburst.sfm.reconstruct import ReconstructionError, ReconstructionResult, reconstruct_scene
from lburst.sfm.metrics import evaluate_against_reference

__all__ = ["ReconstructionError", "ReconstructionResult", "reconstruct_scene", "evaluate_against_reference"]
