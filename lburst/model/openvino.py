"""The OpenVINO runtime of the exported graph (``openvino``, ``openvino-bf16``, ``openvino-int8``).

:class:`OpenVinoRunner` has the interface of :class:`lburst.model.onnx.OnnxRunner`: a callable
``x (1, 3N, H, W) float32 torch tensor -> (repeatability, reliability, raw descriptor map)``
with ``frames`` and ``meta`` attributes.  OpenVINO compiles one model per input shape (cached);
:func:`quantize_openvino` quantises a model to int8 with NNCF on calibration inputs that the
caller gives.  OpenVINO and NNCF are optional (``pip install 'lburst[openvino]'``), imported on
first use.  Measurements: docs/speed.md.
"""

from __future__ import annotations

import time
import warnings
from collections import OrderedDict
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from lburst.errors import LBurstValueError
from lburst.extras import require
from lburst.model.fast import pad_maps
from lburst.model.lite import LiteNet
from lburst.model.network import CheckpointError, LBurstNet, check_finite_weights
from lburst.model.onnx import INPUT_NAME, OUTPUT_NAMES, exported_module, meta_props, parse_meta


def _ov():
    return require("openvino", "the OpenVINO runtime")


def openvino_model(source: str | Path | LBurstNet | LiteNet, meta: dict | None = None):
    """An ``openvino.Model`` of the exported graph (input ``burst`` ``(1, 3N, ?, ?)``, outputs
    ``repeatability``, ``reliability``, ``half``) from an ONNX file (its ``lburst.*`` metadata kept),
    an OpenVINO IR (``.xml``), or a network (converted from torch by ``openvino.convert_model``;
    ``meta``, a checkpoint's ``meta``, is stored in the model's ``rt_info``)."""
    ov = _ov()
    if isinstance(source, (str, Path)):
        path = Path(source)
        if not path.is_file():
            raise CheckpointError(f"{path}: model file not found")
        try:
            return ov.Core().read_model(str(path))
        except Exception as exc:
            raise CheckpointError(f"{path}: not a readable ONNX or OpenVINO model ({exc})") from exc

    module = exported_module(source)
    channels = source.config.in_channels
    with torch.inference_mode(False), torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch.jit.trace deprecation, tracer warnings
        model = ov.convert_model(
            module, example_input=torch.randn(1, channels, 96, 128), input=[ov.PartialShape([1, channels, -1, -1])]
        )
    model.inputs[0].get_tensor().set_names({INPUT_NAME})
    for output, name in zip(model.outputs, OUTPUT_NAMES):
        output.get_tensor().set_names({name})
    for key, value in meta_props(meta or {}).items():
        model.set_rt_info(value, ["framework", key])
    return model


def nonfinite_constants(model) -> list[str]:
    """Names of the floating-point constants (the weights) of an ``openvino.Model`` that hold NaN or inf."""
    return [
        op.get_friendly_name()
        for op in model.get_ordered_ops()
        if op.get_type_name() == "Constant" and op.get_element_type().is_real() and not np.isfinite(op.get_data()).all()
    ]


def _model_props(model) -> dict[str, str]:
    """The ``lburst.*`` entries of an ``openvino.Model``'s ``rt_info['framework']`` (where ONNX
    ``metadata_props`` land, and where :func:`openvino_model` puts a checkpoint's ``meta``)."""
    try:
        framework = model.get_rt_info()["framework"]
        return {k: v.astype(str) for k, v in framework.items() if k.startswith("lburst.")}
    except (KeyError, RuntimeError, AttributeError):
        return {}


#: ``precision`` of :class:`OpenVinoRunner` -> OpenVINO's ``INFERENCE_PRECISION_HINT``
OV_PRECISIONS = {"fp32": "f32", "bf16": "bf16"}


class OpenVinoRunner:
    """An OpenVINO CPU model with the interface of :class:`lburst.model.onnx.OnnxRunner`.

    ``model``: an ONNX file, an OpenVINO IR, an ``openvino.Model`` or a network (see
    :func:`openvino_model`).  ``threads``: ``INFERENCE_NUM_THREADS`` (default: OpenVINO's,
    every core).  ``precision``: ``'fp32'`` (set explicitly: OpenVINO's default on CPUs with
    native bf16 is bf16) or ``'bf16'``; for an int8 model it is the precision of the layers
    left unquantised.  ``dynamic``: one dynamic-shape compiled model instead of one per input
    shape (slower per call: docs/speed.md).  Per-shape models are cached, the
    ``cache_size`` most recently used kept; ``compile_seconds`` sums the time spent compiling.
    Outputs are copied out of OpenVINO's buffers, so they stay valid after the next call.
    """

    def __init__(
        self,
        model,
        threads: int | None = None,
        precision: str = "fp32",
        dynamic: bool = False,
        cache_size: int = 32,
    ) -> None:
        ov = _ov()
        if precision not in OV_PRECISIONS:
            raise LBurstValueError(f"precision must be {' or '.join(OV_PRECISIONS)}, got {precision!r}")
        if not isinstance(model, ov.Model):
            where = str(model) if isinstance(model, (str, Path)) else type(model).__name__
            model = openvino_model(model)
        else:
            where = model.get_friendly_name() or "openvino model"
        self.model = model
        self.precision = precision
        self.threads = threads
        self.dynamic = dynamic
        self.cache_size = cache_size
        self.compile_seconds = 0.0
        self.core = ov.Core()
        self.config: dict[str, object] = {
            "PERFORMANCE_HINT": "LATENCY",
            "INFERENCE_PRECISION_HINT": OV_PRECISIONS[precision],
        }
        if threads:
            self.config["INFERENCE_NUM_THREADS"] = int(threads)
        channels = model.inputs[0].get_partial_shape()[1]
        if channels.is_dynamic or channels.get_length() % 3:
            raise CheckpointError(f"{where}: input has {channels} channels, not 3N")
        check_finite_weights(where, nonfinite_constants(model))
        self.frames = channels.get_length() // 3
        self.meta = parse_meta(_model_props(model), where)
        names = [o.get_names() for o in model.outputs]  # by name where it has them, else in order
        found = [next((i for i, n in enumerate(names) if name in n), None) for name in OUTPUT_NAMES]
        self._order = found if None not in found else [0, 1, 2]
        self._requests: OrderedDict[tuple[int, ...] | None, object] = OrderedDict()

    def _compile(self, model):
        start = time.perf_counter()
        compiled = self.core.compile_model(model, "CPU", self.config)
        self.compile_seconds += time.perf_counter() - start
        return compiled

    def _request(self, shape: tuple[int, ...]):
        key = None if self.dynamic else shape
        request = self._requests.get(key)
        if request is not None:
            self._requests.move_to_end(key)
            return request
        if self.dynamic:
            model = self.model
        else:
            model = self.model.clone()
            model.reshape({0: list(shape)})
        request = self._compile(model).create_infer_request()
        self._requests[key] = request
        while len(self._requests) > max(1, self.cache_size):
            self._requests.popitem(last=False)
        return request

    def __call__(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        array = np.ascontiguousarray(x.detach().cpu().numpy(), dtype=np.float32)
        request = self._request(array.shape)
        request.infer({0: array}, share_inputs=True)
        rep, rel, desc = (torch.from_numpy(np.array(request.get_output_tensor(i).data)) for i in self._order)
        return pad_maps(rep, rel, x.shape[-2:]) + (desc,)


def quantize_openvino(model, calibration: Sequence[torch.Tensor], fast_bias_correction: bool = True):
    """The OpenVINO model (see :func:`openvino_model` for what ``model`` may be) quantised to int8
    by NNCF post-training quantisation (``nncf.quantize``: symmetric int8 weights per channel,
    activations calibrated on ``calibration``, normalised inputs ``(1, 3N, H, W)``).  Deterministic for
    given calibration data.  The ``lburst.*`` metadata is kept."""
    ov = _ov()
    nncf = require("nncf", "int8 quantisation")
    if not isinstance(model, ov.Model):
        model = openvino_model(model)
    props = _model_props(model)
    items = [np.ascontiguousarray(x.detach().cpu().numpy(), dtype=np.float32) for x in calibration]
    if not items:
        raise LBurstValueError("no calibration data")
    quantized = nncf.quantize(
        model,
        nncf.Dataset(items),
        subset_size=len(items),
        fast_bias_correction=fast_bias_correction,
    )
    for key, value in props.items():
        quantized.set_rt_info(value, ["framework", key])
    return quantized
