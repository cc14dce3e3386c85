"""CPU runtimes for the light network (and the exported graph of any LBurst network).

Every runner here has the interface of :class:`lburst.model.onnx.OnnxRunner`: a callable
``x (1, 3N, H, W) float32 torch tensor -> (repeatability, reliability, raw descriptor map)``
torch tensors, with ``frames`` and ``meta`` attributes, so ``LBurst(None, runner=r, frames=r.frames)``
runs it at every pyramid level (``LBurst.from_checkpoint(path, runtime=...)`` builds that from a checkpoint).

Runtimes (:data:`RUNTIMES`):

- ``torch``, ``torch-bf16``: the inference form in torch (:func:`inference_form`);
- ``onnxruntime``: the ONNX export (:mod:`lburst.model.onnx`) run by ONNX Runtime;
- ``onnxruntime-int8``: the export statically quantised by ONNX Runtime (QDQ, int8 weights per
  channel, uint8 activations), calibrated on training bursts (:func:`quantize_onnx`);
- ``openvino``, ``openvino-bf16``: OpenVINO (:class:`OpenVinoRunner`), fp32, or with
  ``INFERENCE_PRECISION_HINT`` bf16 (only worth it with native bf16, see :func:`native_bf16`);
- ``openvino-int8``: NNCF post-training quantisation of the OpenVINO model, calibrated on
  training bursts (:func:`quantize_openvino`).

OpenVINO compiles one model per input shape (:class:`OpenVinoRunner`, cached): on the
2-core AMD EPYC (Zen 4), one thread, the 9 pyramid levels of a 1024x768 burst took 0.82 s
of CPU per-shape against 0.91 s for one dynamic-shape model (bf16: 0.48 against 0.60 s);
a per-shape compile takes about 0.1-0.2 s, paid once per level size (the first burst of
each size: about 1-2 s in all), and the cache keeps the most recent 32 shapes.

Calibration data (:func:`calibration_bursts`): photos of the training split (``$LBURST_SHARED/data/train``)
at a random size of the pyramid's range, made into noisy low-light bursts by
:func:`lburst.simulate.simulate_burst` (random motion, Gaussian or photon noise, seeded),
aligned by :func:`lburst.burst.align.align_burst` as the light weights' input is, and normalised
by :func:`lburst.model.normalize_burst`.

Which runtime to use on which CPU: :func:`choose_runtime` (measurements in its docstring and
``scripts/runtime_speed.py``).

OpenVINO and NNCF are optional (``pip install 'lburst[openvino]'``), imported on first use;
ONNX Runtime comes with ``lburst[onnx]``.
"""

from __future__ import annotations

import shutil
import tempfile
import time
import warnings
import zlib
from collections import OrderedDict
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np
import torch

from lburst.burst.align import align_burst
from lburst.burst.io import IMAGE_SUFFIXES, atomic_path, decode_file
from lburst.errors import LBurstFileNotFoundError, LBurstOSError, LBurstValueError
from lburst.extras import require
from lburst.model.fast import FastLBurstNet, pad_maps
from lburst.model.lite import LiteNet
from lburst.model.network import (
    CheckpointError,
    LBurstNet,
    check_finite_weights,
    normalize_burst,
)
from lburst.model.onnx import (
    INPUT_NAME,
    OUTPUT_NAMES,
    OnnxRunner,
    export_network_onnx,
    exported_module,
    meta_props,
    parse_meta,
)
from lburst.model.precision import NATIVE_BF16_FLAGS, cpu_flags
from lburst.noise import GaussianNoise, LowLightNoise
from lburst.paths import shared_dir
from lburst.simulate import random_motion, simulate_burst

#: every runtime name, in the order of ``scripts/runtime_speed.py``'s table
RUNTIMES = (
    "torch",
    "torch-bf16",
    "onnxruntime",
    "onnxruntime-int8",
    "openvino",
    "openvino-bf16",
    "openvino-int8",
)
#: what each runtime needs beyond lburst's own dependencies
RUNTIME_MODULES: dict[str, tuple[str, ...]] = {
    "torch": (),
    "torch-bf16": (),
    "onnxruntime": ("onnx", "onnxscript", "onnxruntime"),
    "onnxruntime-int8": ("onnx", "onnxscript", "onnxruntime"),
    "openvino": ("openvino",),
    "openvino-bf16": ("openvino",),
    "openvino-int8": ("openvino", "nncf"),
}

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


def available(runtime: str) -> bool:
    """Whether the packages ``runtime`` needs are installed (and, for ``openvino-bf16``, the CPU
    has native bf16: OpenVINO's emulated bf16 is slower than fp32)."""
    if runtime not in RUNTIME_MODULES:
        raise LBurstValueError(f"unknown runtime {runtime!r}: use one of {', '.join(RUNTIMES)}")
    import importlib.util

    if runtime == "openvino-bf16" and not native_bf16():
        return False
    return all(importlib.util.find_spec(m) is not None for m in RUNTIME_MODULES[runtime])


def installed_runtimes() -> list[str]:
    """The runtimes whose packages are installed (whatever the CPU)."""
    import importlib.util

    return [r for r in RUNTIMES if all(importlib.util.find_spec(m) is not None for m in RUNTIME_MODULES[r])]


def choose_runtime(
    flags: set[str] | None = None,
    installed: Iterable[str] | None = None,
    exact: bool = False,
    threads: int | None = None,
) -> str:
    """The runtime to run the light network with on this CPU, by this rule (``flags``: CPU flags,
    default ``/proc/cpuinfo``; ``installed``: runtimes whose packages are there, default
    :func:`installed_runtimes`; ``threads``: the threads it will get, ``None`` for every core):

    1. unless ``exact``, on a CPU with native bf16 (``avx512_bf16`` or ``amx_bf16``) with
       OpenVINO installed: ``openvino-bf16``;
    2. on one thread ``onnxruntime``, else ``openvino`` (fp32), the other one when the first is
       not installed;
    3. ``torch-bf16`` where bf16 is native (unless ``exact``), else ``torch``.

    Measured by ``scripts/runtime_speed.py --weights lburst/weights/lburst-b5-lite.pt`` on a
    2-core AMD EPYC (Zen 4: avx512_bf16 and avx512_vnni, no AMX), nothing else running: full
    9-level extraction of a 1024x768 5-frame burst (4000 keypoints), wall seconds, median of 5.

    - Two threads: torch 0.593, torch bf16 0.385, ONNX Runtime 0.588, OpenVINO 0.621, OpenVINO
      bf16 0.388, ONNX Runtime int8 0.468, OpenVINO int8 0.353 (lburst-b5's fast path 5.11).
    - One thread: torch 0.929, torch bf16 0.622, ONNX Runtime 0.751, OpenVINO 0.868, OpenVINO
      bf16 0.537, ONNX Runtime int8 0.495, OpenVINO int8 0.422.
    - Agreement with torch fp32: the fp32 runtimes within 7e-6 (the same keypoints); bf16 raw
      maps within 6e-2 and 99.6 % of the keypoints within 1 px; int8 92 % (below the 95 % this
      project asks of a runtime, so never chosen).
    - The same CPU shared with a training job (a partly trained network): two threads, torch
      5.9, ONNX Runtime 3.7, OpenVINO 2.7, OpenVINO bf16 2.2 s: OpenVINO suffers least from
      sharing the cores, hence its place in rule 2 on two threads or more.

    So OpenVINO bf16 is the fastest runtime that keeps the features wherever bf16 is native
    (tied with torch bf16 on two idle threads; without native bf16 OpenVINO's bf16 is emulated,
    slower than fp32); among the exact runtimes ONNX Runtime is the fastest on one thread, and
    on two the three are within 5 % on idle cores while OpenVINO holds up best on busy ones.
    The int8 runtimes are never chosen (they move keypoints); ask for them by name.
    No other CPU was measured: with AMX, or without AVX-512, the order may differ (run the
    script there).
    """
    installed = set(installed_runtimes() if installed is None else installed)
    if not exact and native_bf16(flags) and installed & {"openvino", "openvino-bf16"}:
        return "openvino-bf16"
    order = ("onnxruntime", "openvino") if threads == 1 else ("openvino", "onnxruntime")
    for runtime in order:
        if runtime in installed:
            return runtime
    return "torch-bf16" if not exact and native_bf16(flags) else "torch"


# --------------------------------------------------------------------------- OpenVINO


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
    shape (slower per call, see the module docstring).  Per-shape models are cached, the
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


# --------------------------------------------------------------------------- calibration


def default_photo_folder() -> Path:
    """``$LBURST_SHARED/data/train`` (default ``../shared/data/train``), the training photos."""
    return shared_dir() / "data" / "train"


def training_photos(folder: str | Path | None = None) -> list[Path]:
    """The training split's photos under ``folder`` (default :func:`default_photo_folder`), sorted:
    the validation tenth is left out by the rule of :func:`lburst.train.data.is_validation_photo`
    (CRC-32 of the file stem divisible by 10; repeated here since lburst.model never imports
    lburst.train)."""
    folder = Path(folder) if folder is not None else default_photo_folder()
    if not folder.is_dir():
        raise LBurstFileNotFoundError(f"{folder}: calibration photo folder not found (set LBURST_SHARED)")
    photos = sorted(
        p for p in folder.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES and zlib.crc32(p.stem.encode()) % 10
    )
    if not photos:
        raise LBurstFileNotFoundError(f"no training photos under {folder}")
    return photos


def calibration_bursts(
    photos: str | Path | Sequence[str | Path | np.ndarray] | None = None,
    count: int = 24,
    frames: int = 5,
    long_side: tuple[int, int] = (256, 768),
    seed: int = 0,
    align: bool = True,
) -> list[torch.Tensor]:
    """``count`` normalised bursts ``(1, 3 frames, H, W)`` for post-training quantisation.

    ``photos``: a folder (default :func:`default_photo_folder`, its training split), or a list
    of image files or RGB uint8 arrays.  Burst ``i`` is drawn with ``numpy.random.default_rng([seed, i])``:
    a photo, a long side uniform in ``long_side`` (the pyramid's range of sizes), a per-frame
    motion of up to 3 px, a darkening (exposure 0.15-1, probability 0.3) and either photon noise
    (3-60 photons at white, probability 1/3) or Gaussian noise of std 25-120 (the light
    network's training recipe, ``lburst train --preset lite``); it is then aligned (``align``,
    as the light weights read their input) and normalised."""
    import cv2

    if photos is None or isinstance(photos, (str, Path)):
        photos = training_photos(photos)
    if not len(photos):
        raise LBurstValueError("no calibration photos")
    out = []
    for i in range(count):
        rng = np.random.default_rng([seed, i])
        item = photos[int(rng.integers(len(photos)))]
        if isinstance(item, np.ndarray):
            photo = item
        else:
            bgr = decode_file(item, cv2.IMREAD_COLOR)
            if bgr is None:
                raise LBurstOSError(f"{item}: not a readable image")
            photo = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        target = rng.uniform(*long_side)
        scale = target / max(photo.shape[:2])
        size = (max(32, round(photo.shape[1] * scale)), max(32, round(photo.shape[0] * scale)))
        photo = cv2.resize(photo, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
        if rng.random() < 0.3:
            photo = np.clip(np.round(photo * rng.uniform(0.15, 1.0)), 0, 255).astype(np.uint8)
        if rng.random() < 1 / 3:
            noise = LowLightNoise(float(np.exp(rng.uniform(np.log(3.0), np.log(60.0)))))
        else:
            noise = GaussianNoise(float(rng.uniform(25.0, 120.0)))
        burst = simulate_burst(photo, frames, random_motion(rng, 3.0), noise, rng=rng)
        if align and frames > 1:
            burst = align_burst(burst)
        out.append(normalize_burst(burst))
    return out


# --------------------------------------------------------------------------- int8


def quantize_openvino(model, calibration: Sequence[torch.Tensor], fast_bias_correction: bool = True):
    """The OpenVINO model (see :func:`openvino_model` for what ``model`` may be) quantised to int8
    by NNCF post-training quantisation (``nncf.quantize``: symmetric int8 weights per channel,
    activations calibrated on ``calibration``, :func:`calibration_bursts`).  Deterministic for
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
    ``calibration`` (:func:`calibration_bursts`); the ``lburst.*`` metadata is kept."""
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


# --------------------------------------------------------------------------- runners


def make_runner(
    runtime: str,
    net: LBurstNet | LiteNet,
    *,
    threads: int | None = None,
    meta: dict | None = None,
    onnx_path: str | Path | None = None,
    calibration: Sequence[torch.Tensor] | None = None,
    workdir: str | Path | None = None,
) -> Runner:
    """A runner of ``net`` on ``runtime`` (one of :data:`RUNTIMES`).

    ``threads``: the runtime's threads (the torch runtimes use torch's global setting:
    ``torch.set_num_threads``).  ``meta``: the checkpoint's ``meta`` (kept in exported
    models).  ``onnx_path``: an existing export of ``net`` (else it is exported to ``workdir``,
    a temporary folder by default).  ``calibration``: inputs for the int8 runtimes (default
    :func:`calibration_bursts` with ``net``'s frame count)."""
    if runtime not in RUNTIMES:
        raise LBurstValueError(f"unknown runtime {runtime!r}: use one of {', '.join(RUNTIMES)}")
    if runtime in ("torch", "torch-bf16"):
        return inference_form(net, "bf16" if runtime == "torch-bf16" else "fp32").eval()
    if runtime.endswith("-int8") and calibration is None:
        calibration = calibration_bursts(frames=net.config.frames)
    if runtime.startswith("openvino"):
        model = openvino_model(net, meta)
        if runtime == "openvino-int8":
            model = quantize_openvino(model, calibration)
        return OpenVinoRunner(model, threads=threads, precision="bf16" if runtime == "openvino-bf16" else "fp32")

    folder = Path(workdir) if workdir is not None else Path(tempfile.mkdtemp(prefix="lburst-runtime-"))
    folder.mkdir(parents=True, exist_ok=True)
    if onnx_path is None:
        onnx_path = export_network_onnx(net, folder / "model.onnx", meta)
    if runtime == "onnxruntime-int8":
        onnx_path = quantize_onnx(onnx_path, folder / "model-int8.onnx", calibration)
    return OnnxRunner(onnx_path, threads=threads)
