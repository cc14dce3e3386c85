"""lburst: learned features from low-light robotic bursts, and 3D reconstruction from them.

Each command's work is a function here, which its command line only parses arguments for:
``lburst.extract(bursts, out, method)`` (``lburst extract``, :mod:`lburst.extraction`) and
``lburst.reconstruct(scene, method, out, ReconstructOptions(...))`` (``lburst reconstruct``,
:func:`lburst.sfm.reconstruct.reconstruct_scene`); a ``method`` is a spec such as ``'lburst'`` or
``'merge+sift'``, or the :class:`lburst.Method` parsed from one (``lburst.Method.parse(spec)``).

The public names below are imported on first use, so ``import lburst`` (and the COLMAP
child processes, which import ``lburst.sfm``) do not pay for torch until it is needed.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_EXPORTS = {
    "LBurst": "lburst.model.extractor",
    "MultiScaleConfig": "lburst.model.extractor",
    "Features": "lburst.features",
    "LBurstNet": "lburst.model.network",
    "NetConfig": "lburst.model.network",
    "CheckpointError": "lburst.model.network",
    "load_checkpoint": "lburst.model.network",
    "save_checkpoint": "lburst.model.network",
    "LBurstError": "lburst.errors",
    "LBurstValueError": "lburst.errors",
    "BurstError": "lburst.burst.io",
    "load_burst": "lburst.burst.io",
    "save_burst": "lburst.burst.io",
    "simulate_burst": "lburst.simulate",
    "extract": "lburst.extraction",
    "ExtractReport": "lburst.extraction",
    "reconstruct": "lburst.sfm.reconstruct:reconstruct_scene",
    "ReconstructOptions": "lburst.sfm.options",
    "ReconstructionResult": "lburst.sfm.result",
    "Method": "lburst.methods",
}
_MODULES = ("methods", "matching", "noise", "simulate", "burst", "match", "model")

__all__ = sorted(_EXPORTS) + list(_MODULES)


def __getattr__(name: str):
    if name in _EXPORTS:  # "module" (the same name there) or "module:name"
        module, _, attr = _EXPORTS[name].partition(":")
        return getattr(importlib.import_module(module), attr or name)
    if name in _MODULES:
        return importlib.import_module(f"lburst.{name}")
    raise AttributeError(f"module 'lburst' has no attribute {name!r}")
