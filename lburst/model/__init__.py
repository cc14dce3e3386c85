"""The LBurst network and everything that runs it.

- :mod:`lburst.model.network`: :class:`LBurstNet`, its configuration and checkpoints
  (the published layout), input normalisation, precision and device checks;
- :mod:`lburst.model.fast`: :class:`FastLBurstNet`, the inference-only form with the
  same outputs; :mod:`lburst.model.lite`: the light network;
- :mod:`lburst.model.runtimes`: the typed runtime (torch, ONNX Runtime, OpenVINO and their
  precisions), chosen per CPU; :mod:`lburst.model.backend`: the backend that runs the network
  on it; :mod:`lburst.model.onnx`, :mod:`lburst.model.openvino`: export, runners, int8;
- :mod:`lburst.model.detector`: multi-scale keypoints and descriptors over a backend;
- :mod:`lburst.model.extractor`: :class:`LBurst`, the two together
  (``LBurst.pretrained(...)``, ``model.extract(burst)``).

The int8 runtimes are calibrated on bursts their caller gives (:mod:`lburst.calibration`):
nothing here imports the simulator.
"""

from __future__ import annotations

from lburst.model.extractor import LBurst, MultiScaleConfig, frame_permutation
from lburst.model.fast import FastLBurstNet
from lburst.model.network import (
    AUTOCAST_DTYPES,
    IMAGENET_MEAN,
    IMAGENET_STD,
    CheckpointError,
    LBurstNet,
    NetConfig,
    autocast_dtype,
    check_device,
    check_precision,
    config_from_net_string,
    load_checkpoint,
    normalize_burst,
    replicate_frames,
    save_checkpoint,
    training_memory_format,
)
from lburst.model.onnx import OnnxRunner, export_onnx

__all__ = [
    "AUTOCAST_DTYPES",
    "IMAGENET_MEAN",
    "IMAGENET_STD",
    "CheckpointError",
    "FastLBurstNet",
    "LBurst",
    "LBurstNet",
    "MultiScaleConfig",
    "NetConfig",
    "OnnxRunner",
    "autocast_dtype",
    "check_device",
    "check_precision",
    "config_from_net_string",
    "export_onnx",
    "frame_permutation",
    "load_checkpoint",
    "normalize_burst",
    "replicate_frames",
    "save_checkpoint",
    "training_memory_format",
]
