"""Which runtime runs the network: a typed :class:`Runtime` value, what is installed, the choice
for this CPU, and the runner of each runtime.

A runtime is an engine and a precision (:data:`RUNTIMES` lists their names):

- ``torch``, ``torch-bf16``: the inference form in torch (:func:`inference_form`);
- ``onnxruntime``, ``onnxruntime-int8``: the ONNX export (:mod:`lburst.model.onnx`) run by ONNX
  Runtime, as exported or statically quantised (QDQ, int8 weights per channel, uint8 activations,
  :func:`lburst.model.onnx.quantize_onnx`);
- ``openvino``, ``openvino-bf16``, ``openvino-int8``: OpenVINO (:mod:`lburst.model.openvino`),
  fp32, with ``INFERENCE_PRECISION_HINT`` bf16 (only worth it with native bf16, see
  :func:`native_bf16`), or quantised by NNCF.

A name is parsed once (:meth:`Runtime.parse`); :func:`make_runner` builds the runner of a
:class:`Runtime`: a callable ``x (1, 3N, H, W) float32 -> (repeatability, reliability, raw
descriptor map)``.  The int8 runtimes are calibrated on inputs the caller gives
(``calibration``; :mod:`lburst.calibration` makes the default set from the training photos).
Measurements of every runtime: docs/speed.md.

OpenVINO and NNCF are optional (``pip install 'lburst[openvino]'``), imported on first use;
ONNX Runtime comes with ``lburst[onnx]``.
"""

from __future__ import annotations

import importlib.util
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

import numpy as np
import torch

from lburst.errors import LBurstValueError
from lburst.model.fast import FastLBurstNet
from lburst.model.lite import LiteNet
from lburst.model.network import LBurstNet, normalize_burst
from lburst.model.onnx import OnnxRunner, export_network_onnx, quantize_onnx
from lburst.model.openvino import OpenVinoRunner, openvino_model, quantize_openvino
from lburst.model.precision import NATIVE_BF16_FLAGS, cpu_flags

#: the precisions each engine runs the network in
PRECISIONS: dict[str, tuple[str, ...]] = {
    "torch": ("fp32", "bf16"),
    "onnxruntime": ("fp32", "int8"),
    "openvino": ("fp32", "bf16", "int8"),
}
#: the packages each engine needs beyond lburst's own dependencies
PACKAGES: dict[str, tuple[str, ...]] = {
    "torch": (),
    "onnxruntime": ("onnx", "onnxscript", "onnxruntime"),
    "openvino": ("openvino",),
}


@dataclass(frozen=True)
class Runtime:
    """A runtime of the network: an ``engine`` of :data:`PRECISIONS` and one of its precisions."""

    engine: str = "torch"
    precision: str = "fp32"

    def __post_init__(self) -> None:
        if self.precision not in PRECISIONS.get(self.engine, ()):
            raise LBurstValueError(f"unknown runtime {self.name!r}: use one of {', '.join(RUNTIMES)}")

    @classmethod
    def parse(cls, name: str | Runtime) -> Runtime:
        """The runtime called ``name`` (one of :data:`RUNTIMES`; a :class:`Runtime` as it is)."""
        if isinstance(name, Runtime):
            return name
        if name not in _BY_NAME:
            raise LBurstValueError(f"unknown runtime {name!r}: use one of {', '.join(RUNTIMES)}")
        return _BY_NAME[name]

    @property
    def name(self) -> str:
        """``engine``, or ``engine-precision`` for any precision but fp32 (``openvino-bf16``)."""
        return self.engine if self.precision == "fp32" else f"{self.engine}-{self.precision}"

    @property
    def modules(self) -> tuple[str, ...]:
        """The packages it needs beyond lburst's own dependencies (NNCF for OpenVINO's int8)."""
        extra = ("nncf",) if (self.engine, self.precision) == ("openvino", "int8") else ()
        return PACKAGES[self.engine] + extra

    @property
    def cpu_only(self) -> bool:
        """Whether it runs on the CPU only (every engine but torch)."""
        return self.engine != "torch"

    def __str__(self) -> str:
        return self.name


#: every runtime, in the order of ``scripts/runtime_speed.py``'s table
ALL_RUNTIMES = tuple(
    Runtime(engine, precision) for engine, precisions in PRECISIONS.items() for precision in precisions
)
_BY_NAME = {runtime.name: runtime for runtime in ALL_RUNTIMES}
#: every runtime name (what ``--runtime`` and ``runtime=`` take, with ``auto``)
RUNTIMES = tuple(_BY_NAME)
#: what each runtime needs beyond lburst's own dependencies
RUNTIME_MODULES: dict[str, tuple[str, ...]] = {name: runtime.modules for name, runtime in _BY_NAME.items()}
#: int8 calibration: normalised inputs ``(1, 3N, H, W)`` or bursts ``(N, H, W, 3)``, or a function
#: of the network's frame count that gives them (:func:`lburst.calibration.training_calibration`)
CalibrationItem = torch.Tensor | np.ndarray
Calibration = Iterable[CalibrationItem] | Callable[[int], Iterable[CalibrationItem]]
Runner = Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor, torch.Tensor]]


def inference_form(net: LBurstNet | LiteNet, precision: str = "fp32") -> torch.nn.Module:
    """The torch runtime of ``net``: ``x -> (repeatability, reliability, raw descriptor map)``
    (:class:`FastLBurstNet` for the Fast-Quad-L2-Net, :class:`LiteInference` for the light network)."""
    if isinstance(net, LiteNet):
        return net.inference(precision)
    return FastLBurstNet(net, precision)


def native_bf16(flags: set[str] | None = None) -> bool:
    """Whether the CPU computes in bf16 natively (``avx512_bf16`` or ``amx_bf16`` among ``flags``,
    by default those of ``/proc/cpuinfo``)."""
    flags = cpu_flags() if flags is None else flags
    return bool(flags and set(flags).intersection(NATIVE_BF16_FLAGS))


def _installed(runtime: Runtime) -> bool:
    return all(importlib.util.find_spec(m) is not None for m in runtime.modules)


def available(runtime: str | Runtime) -> bool:
    """Whether the packages ``runtime`` needs are installed (and, for ``openvino-bf16``, the CPU
    has native bf16: OpenVINO's emulated bf16 is slower than fp32)."""
    runtime = Runtime.parse(runtime)
    if runtime == Runtime("openvino", "bf16") and not native_bf16():
        return False
    return _installed(runtime)


def installed_runtimes() -> list[str]:
    """The names of the runtimes whose packages are installed (whatever the CPU)."""
    return [runtime.name for runtime in ALL_RUNTIMES if _installed(runtime)]


def choose_runtime(
    flags: set[str] | None = None,
    installed: Iterable[str] | None = None,
    exact: bool = False,
    threads: int | None = None,
) -> Runtime:
    """The runtime to run the light network with on this CPU, by this rule (``flags``: CPU flags,
    default ``/proc/cpuinfo``; ``installed``: names of the runtimes whose packages are there,
    default :func:`installed_runtimes`; ``threads``: the threads it will get, ``None`` for every core):

    1. unless ``exact``, on a CPU with native bf16 (``avx512_bf16`` or ``amx_bf16``) with
       OpenVINO installed: ``openvino-bf16``;
    2. on one thread ``onnxruntime``, else ``openvino`` (fp32), the other one when the first is
       not installed;
    3. ``torch-bf16`` where bf16 is native (unless ``exact``), else ``torch``.

    The int8 runtimes are never chosen (they move keypoints); ask for them by name.  The
    measurements behind the rule: docs/speed.md.
    """
    installed = set(installed_runtimes() if installed is None else installed)
    bf16 = not exact and native_bf16(flags)
    if bf16 and installed & {"openvino", "openvino-bf16"}:
        return Runtime("openvino", "bf16")
    order = ("onnxruntime", "openvino") if threads == 1 else ("openvino", "onnxruntime")
    for engine in order:
        if engine in installed:
            return Runtime(engine)
    return Runtime("torch", "bf16" if bf16 else "fp32")


def resolve_runtime(name: str | Runtime | None, light: bool, device: torch.device, threads: int | None) -> Runtime:
    """The runtime that ``name`` asks for on ``device``: ``'auto'`` is :func:`choose_runtime` on a
    CPU and ``torch`` elsewhere; ``None`` is ``'auto'`` for the ``light`` network, ``torch`` for the
    others.  ``ValueError`` for a CPU-only runtime on another device."""
    if name is None:
        name = "auto" if light and device.type == "cpu" else "torch"
    if name == "auto":
        return choose_runtime(threads=threads) if device.type == "cpu" else Runtime("torch")
    runtime = Runtime.parse(name)
    if runtime.cpu_only and device.type != "cpu":
        raise LBurstValueError(f"runtime {runtime.name!r} runs on the CPU only; on {device.type} use 'torch'")
    return runtime


def calibration_inputs(calibration: Calibration | None, runtime: Runtime, frames: int) -> list[torch.Tensor]:
    """The normalised inputs ``(1, 3N, H, W)`` that quantise ``runtime``: ``calibration`` called with
    ``frames`` when it is a function, bursts ``(N, H, W, 3)`` normalised; ``ValueError`` without any."""
    if calibration is None:
        raise LBurstValueError(
            f"runtime {runtime.name!r} is calibrated on bursts the caller gives: pass calibration= (bursts, or a "
            "function of the frame count such as lburst.calibration.training_calibration)"
        )
    items = calibration(frames) if callable(calibration) else calibration
    inputs = [item if isinstance(item, torch.Tensor) else normalize_burst(np.asarray(item)) for item in items]
    if not inputs:
        raise LBurstValueError("no calibration data")
    return inputs


def make_runner(
    runtime: str | Runtime,
    net: LBurstNet | LiteNet,
    *,
    threads: int | None = None,
    meta: dict | None = None,
    onnx_path: str | Path | None = None,
    calibration: Calibration | None = None,
    workdir: str | Path | None = None,
) -> Runner:
    """A runner of ``net`` on ``runtime`` (a :class:`Runtime` or one of :data:`RUNTIMES`).

    ``threads``: the runtime's threads (the torch runtimes use torch's global setting:
    ``torch.set_num_threads``).  ``meta``: the checkpoint's ``meta`` (kept in exported
    models).  ``onnx_path``: an existing export of ``net`` (else it is exported to ``workdir``,
    a temporary folder by default).  ``calibration``: what the int8 runtimes are calibrated on
    (:data:`Calibration`; needed for them, unused by the others)."""
    runtime = Runtime.parse(runtime)
    if runtime.engine == "torch":
        return inference_form(net, runtime.precision).eval()
    if runtime.precision == "int8":
        calibration = calibration_inputs(calibration, runtime, net.config.frames)
    if runtime.engine == "openvino":
        model = openvino_model(net, meta)
        if runtime.precision == "int8":
            model = quantize_openvino(model, calibration)
        return OpenVinoRunner(model, threads=threads, precision="bf16" if runtime.precision == "bf16" else "fp32")
    folder = Path(workdir) if workdir is not None else Path(tempfile.mkdtemp(prefix="lburst-runtime-"))
    folder.mkdir(parents=True, exist_ok=True)
    if onnx_path is None:
        onnx_path = export_network_onnx(net, folder / "model.onnx", meta)
    if runtime.precision == "int8":
        onnx_path = quantize_onnx(onnx_path, folder / "model-int8.onnx", calibration)
    return OnnxRunner(onnx_path, threads=threads)
