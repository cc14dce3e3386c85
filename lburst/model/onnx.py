"""ONNX export of the fast network and an ONNX Runtime backend (``lburst export onnx``).

The exported graph is :meth:`lburst.model.fast.FastLBurstNet.core`: input ``burst``
``(1, 3N, H, W)`` (normalised, see :func:`lburst.model.normalize_burst`) with dynamic
height and width; outputs ``repeatability`` and ``reliability`` ``(1, 1, 2*(H//2),
2*(W//2))`` and ``half``, the raw half-resolution map.  :class:`OnnxRunner` pads odd
sizes exactly as the torch path does, so :class:`lburst.LBurst` runs either.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import torch

from lburst.extras import require
from lburst.io import atomic_path
from lburst.model.fast import CoreModule, FastLBurstNet, pad_maps
from lburst.model.network import WHITENING_KEYS, CheckpointError, load_checkpoint


def export_onnx(checkpoint: str | Path, out: str | Path, opset: int = 18) -> Path:
    """Export the checkpoint's fast network to ``out`` (atomically)."""
    for module in ("onnx", "onnxscript"):
        require(module, "lburst export onnx")
    net, extra = load_checkpoint(checkpoint, "cpu")
    core = CoreModule(FastLBurstNet(net, tiled=False).eval()).eval()  # one graph for any size
    example = torch.randn(1, net.config.in_channels, 96, 128)
    height, width = torch.export.Dim("height", min=32, max=8192), torch.export.Dim("width", min=32, max=8192)
    out = Path(out)
    with atomic_path(out) as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            core,
            (example,),
            str(tmp),
            dynamo=True,
            opset_version=opset,
            input_names=["burst"],
            output_names=["repeatability", "reliability", "half"],
            dynamic_shapes={"x": {2: height, 3: width}},
            external_data=False,
            verbose=False,
        )
        _store_meta(tmp, extra.get("meta") if isinstance(extra.get("meta"), dict) else {})
    return out


def _store_meta(path: Path, meta: dict) -> None:
    """Keep what extraction needs beside the graph (``metadata_props``): the weights' input
    (``aligned`` bursts or not) and their descriptor whitening."""
    import onnx

    model = onnx.load(str(path))
    entries = {"lburst.input": str(meta.get("input", "burst"))}
    for key in WHITENING_KEYS:
        if meta.get(key) is not None:
            entries[f"lburst.{key}"] = json.dumps(np.asarray(meta[key], np.float32).tolist())
    for key, value in entries.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.save(model, str(path))


class OnnxRunner:
    """An ONNX Runtime session with the interface of :meth:`FastLBurstNet.forward`."""

    def __init__(self, path: str | Path, threads: int | None = None) -> None:
        ort = require("onnxruntime", "LBurst.from_onnx")

        path = Path(path)
        if not path.is_file():
            raise CheckpointError(f"{path}: ONNX model not found")
        options = ort.SessionOptions()
        if threads:
            options.intra_op_num_threads = threads
        try:
            self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except Exception as exc:
            raise CheckpointError(f"{path}: not a readable ONNX model ({exc})") from exc
        channels = self.session.get_inputs()[0].shape[1]
        if not isinstance(channels, int) or channels % 3:
            raise CheckpointError(f"{path}: input has {channels} channels, not 3N")
        self.frames = channels // 3
        props = self.session.get_modelmeta().custom_metadata_map
        try:
            self.meta = {
                "input": props.get("lburst.input", "burst"),
                **{
                    k: np.asarray(json.loads(props[f"lburst.{k}"]), np.float32)
                    for k in WHITENING_KEYS
                    if f"lburst.{k}" in props
                },
            }
        except ValueError as exc:
            raise CheckpointError(f"{path}: unreadable lburst metadata ({exc})") from exc

    def __call__(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        arrays = self.session.run(None, {"burst": x.contiguous().cpu().numpy()})
        rep, rel, half = (torch.from_numpy(a) for a in arrays)
        return pad_maps(rep, rel, x.shape[-2:]) + (half,)
