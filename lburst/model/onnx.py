"""ONNX export of the fast or the light network and an ONNX Runtime backend (``lburst export onnx``).

The exported graph is the inference form's ``core`` with input ``burst`` ``(1, 3N, H, W)``
(normalised, see :func:`lburst.model.normalize_burst`) of dynamic height and width:

- Fast-Quad-L2-Net: :meth:`lburst.model.fast.FastLBurstNet.core`; outputs ``repeatability``
  and ``reliability`` ``(1, 1, 2*(H//2), 2*(W//2))`` and ``half``, the raw half-resolution map;
- light network (:mod:`lburst.model.lite`): :meth:`lburst.model.lite.LiteInference.core`;
  ``repeatability`` and ``reliability`` ``(1, 1, H, W)`` and ``half``, which is then the raw
  *quarter*-resolution map ``(1, D, ceil(H/4), ceil(W/4))`` (the extractor tells the two
  apart by its size, :func:`lburst.model.fast.descriptor_stride`).

:class:`OnnxRunner` pads odd sizes exactly as the torch path does, so :class:`lburst.LBurst`
runs either; :func:`quantize_onnx` makes its int8 form.  The OpenVINO runtime of the same graph:
:mod:`lburst.model.openvino`; how a runtime is chosen: :mod:`lburst.model.runtimes`.
"""

from __future__ import annotations

import json
import logging
import shutil
import tempfile
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np
import torch

from lburst.burst.io import atomic_path
from lburst.errors import LBurstValueError
from lburst.extras import require
from lburst.model.fast import CoreModule, FastLBurstNet, pad_maps
from lburst.model.lite import LiteNet
from lburst.model.network import (
    WHITENING_KEYS,
    CheckpointError,
    LBurstNet,
    check_finite_weights,
    check_pad,
    default_pad,
    load_checkpoint,
)

#: names of the exported graph's input and outputs
INPUT_NAME = "burst"
OUTPUT_NAMES = ("repeatability", "reliability", "half")
#: torch's exporter logs a warning for each torchvision op it cannot register without torchvision
#: (nms, roi_align, ...), ops that no lburst network holds
EXPORTER_LOGGER = "torch.onnx._internal.exporter._registration"


@contextmanager
def _quiet_exporter() -> Iterator[None]:
    """torch's ONNX exporter without its warnings about ops lburst's networks do not use."""
    logger = logging.getLogger(EXPORTER_LOGGER)
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        logger.setLevel(level)


def export_onnx(checkpoint: str | Path, out: str | Path, opset: int = 18) -> Path:
    """Export the checkpoint's network (the fast form of a Fast-Quad-L2-Net, or the inference
    form of a light network) to ``out`` (atomically)."""
    net, extra = load_checkpoint(checkpoint, "cpu")
    return export_network_onnx(net, out, extra.get("meta") if isinstance(extra.get("meta"), dict) else {}, opset)


def exported_module(net: LBurstNet | LiteNet) -> torch.nn.Module:
    """The module the ONNX export traces: ``x -> (repeatability, reliability, raw descriptor map)``,
    one graph for any size (the fast network untiled; the light network's inference form, fp32)."""
    if isinstance(net, LiteNet):
        return net.inference("fp32").eval()
    return CoreModule(FastLBurstNet(net, tiled=False).eval()).eval()


def export_network_onnx(net: LBurstNet | LiteNet, out: str | Path, meta: dict | None = None, opset: int = 18) -> Path:
    """Export ``net`` (:func:`exported_module`) to ``out`` (atomically), with ``meta`` (a
    checkpoint's ``meta``: input kind and descriptor whitening) kept beside the graph."""
    for module in ("onnx", "onnxscript"):
        require(module, "lburst export onnx")
    core = exported_module(net)
    example = torch.randn(1, net.config.in_channels, 96, 128)
    height, width = torch.export.Dim("height", min=32, max=8192), torch.export.Dim("width", min=32, max=8192)
    out = Path(out)
    with atomic_path(out) as tmp, _quiet_exporter():
        torch.onnx.export(
            core,
            (example,),
            str(tmp),
            dynamo=True,
            opset_version=opset,
            input_names=[INPUT_NAME],
            output_names=list(OUTPUT_NAMES),
            dynamic_shapes={"x": {2: height, 3: width}},
            external_data=False,
            verbose=False,
        )
        _store_meta(tmp, meta or {})
    return out


def _store_meta(path: Path, meta: dict) -> None:
    """Keep what extraction needs beside the graph (``metadata_props``): the weights' input
    (``aligned`` bursts or not) and their descriptor whitening."""
    import onnx

    model = onnx.load(str(path))
    for key, value in meta_props(meta).items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.save(model, str(path))


def meta_props(meta: dict) -> dict[str, str]:
    """A checkpoint's ``meta`` as the ``lburst.*`` strings kept beside an exported graph:
    ``lburst.input`` (``'burst'`` or ``'aligned'``), ``lburst.pad`` (:func:`default_pad`) and
    the descriptor whitening as JSON."""
    entries = {"lburst.input": str(meta.get("input", "burst")), "lburst.pad": str(default_pad(meta))}
    for key in WHITENING_KEYS:
        if meta.get(key) is not None:
            entries[f"lburst.{key}"] = json.dumps(np.asarray(meta[key], np.float32).tolist())
    return entries


def parse_meta(props: dict[str, str], path: str | Path) -> dict:
    """What :func:`_store_meta` kept (``lburst.*`` entries of ``props``): ``{'input': 'burst' or
    'aligned', 'pad' (0 for an export without it), 'descriptor_mean'?, 'descriptor_whitening'?}``;
    :class:`CheckpointError` naming ``path`` when unreadable."""
    try:
        return {
            "input": props.get("lburst.input", "burst"),
            "pad": check_pad(int(props.get("lburst.pad", "0")), "lburst.pad"),
            **{
                k: np.asarray(json.loads(props[f"lburst.{k}"]), np.float32)
                for k in WHITENING_KEYS
                if f"lburst.{k}" in props
            },
        }
    except ValueError as exc:
        raise CheckpointError(f"{path}: unreadable lburst metadata ({exc})") from exc


def nonfinite_initializers(path: str | Path) -> list[str]:
    """Names of the floating-point weights (initializers and constants) of the ONNX graph at
    ``path`` that hold NaN or inf."""
    onnx = require("onnx", "checking an ONNX model's weights")
    from onnx import numpy_helper

    graph = onnx.load(str(path)).graph
    tensors = [(t.name, t) for t in graph.initializer]
    tensors += [
        (node.output[0] if node.output else node.name, a.t)
        for node in graph.node
        if node.op_type == "Constant"
        for a in node.attribute
        if a.name == "value"
    ]
    broken = []
    for name, tensor in tensors:
        values = numpy_helper.to_array(tensor)
        if np.issubdtype(values.dtype, np.floating) and not np.isfinite(values).all():
            broken.append(name)
    return broken


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
        inputs = [i.name for i in self.session.get_inputs()]
        outputs = [o.name for o in self.session.get_outputs()]
        if inputs != [INPUT_NAME] or outputs != list(OUTPUT_NAMES):
            raise CheckpointError(
                f"{path}: not an lburst export (inputs {inputs}, outputs {outputs}; expected [{INPUT_NAME!r}] and "
                f"{list(OUTPUT_NAMES)}, as `lburst export onnx` writes)"
            )
        channels = self.session.get_inputs()[0].shape[1]
        if not isinstance(channels, int) or channels % 3:
            raise CheckpointError(f"{path}: input has {channels} channels, not 3N")
        check_finite_weights(path, nonfinite_initializers(path))
        self.frames = channels // 3
        self.meta = parse_meta(self.session.get_modelmeta().custom_metadata_map, path)

    def __call__(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        arrays = self.session.run(None, {INPUT_NAME: x.contiguous().cpu().numpy()})
        rep, rel, half = (torch.from_numpy(a) for a in arrays)
        return pad_maps(rep, rel, x.shape[-2:]) + (half,)


class _Reader:
    """ONNX Runtime's ``CalibrationDataReader`` protocol over a list of inputs."""

    def __init__(self, items: Sequence[np.ndarray]) -> None:
        self._items = iter(items)

    def get_next(self) -> dict[str, np.ndarray] | None:
        item = next(self._items, None)
        return None if item is None else {INPUT_NAME: item}


def quantize_onnx(onnx_path: str | Path, out: str | Path, calibration: Sequence[torch.Tensor]) -> Path:
    """ONNX Runtime static quantisation of the exported graph ``onnx_path`` to ``out``: QDQ
    format, int8 weights per channel, uint8 activations with MinMax ranges calibrated on
    ``calibration`` (normalised inputs ``(1, 3N, H, W)``); the ``lburst.*`` metadata is kept."""
    onnx = require("onnx", "ONNX Runtime int8 quantisation")
    require("onnxruntime", "ONNX Runtime int8 quantisation")
    from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    items = [np.ascontiguousarray(x.detach().cpu().numpy(), dtype=np.float32) for x in calibration]
    if not items:
        raise LBurstValueError("no calibration data")
    out = Path(out)
    work = Path(tempfile.mkdtemp(prefix="lburst-quant-"))
    try:
        prepared = work / "prepared.onnx"
        quant_pre_process(str(onnx_path), str(prepared), skip_symbolic_shape=True)
        with atomic_path(out) as tmp:
            quantize_static(
                str(prepared),
                str(tmp),
                _Reader(items),
                quant_format=QuantFormat.QDQ,
                per_channel=True,
                activation_type=QuantType.QUInt8,
                weight_type=QuantType.QInt8,
                calibrate_method=CalibrationMethod.MinMax,
                # not CalibMaxIntermediateOutputs: onnxruntime 1.32 drops the outputs it flushes
            )
            source, model = onnx.load(str(onnx_path)), onnx.load(str(tmp))
            del model.metadata_props[:]
            for entry in source.metadata_props:
                model.metadata_props.add(key=entry.key, value=entry.value)
            onnx.save(model, str(tmp))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out
