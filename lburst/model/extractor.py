"""LBurst feature extraction: dense maps at one scale and multi-scale keypoints.

Pixel convention (used throughout lburst): a keypoint ``(x, y)`` is in pixels of the
burst's common (middle) frame at full resolution, with pixel *centres* at integer
coordinates: ``(0, 0)`` is the centre of the top-left pixel (as in OpenCV and hloc;
add 0.5 for COLMAP).  The published extractor maps a keypoint found at ``(x, y)`` in
a level resized to ``w x h`` back as ``x * W / w``, which is off by
``0.5 * (W / w - 1)`` pixels; lburst maps it as ``(x + 0.5) * W / w - 0.5`` unless
``published_coordinates=True``.  At full scale both agree.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from lburst.burst.align import align_burst
from lburst.errors import LBurstValueError
from lburst.features import Features, concatenate, image_size, select
from lburst.memory import memory_limit_bytes
from lburst.model.backend import Backend, RunnerBackend, TorchBackend, open_backend
from lburst.model.detector import (  # noqa: F401  (MAX_LEVELS, MAX_UPSCALE, top_scale, upper_scales, subpixel_offsets: re-exported)
    MAX_LEVELS,
    MAX_UPSCALE,
    MIN_SIDE,
    Detector,
    MultiScaleConfig,
    Whitening,
    first_level,
    subpixel_offsets,
    top_scale,
    upper_scales,
)
from lburst.model.lite import LiteNet
from lburst.model.network import (
    WHITENING_KEYS,
    CheckpointError,
    LBurstNet,
    check_device,
    check_float_burst,
    check_pad,
    default_pad,
    load_checkpoint,
    normalize_burst,
)
from lburst.model.onnx import OnnxRunner
from lburst.model.runtimes import Calibration, Runner, Runtime, resolve_runtime
from lburst.rotation import map_points, rotate_image, rotation_map, turn_burst
from lburst.weights import weights_path

ROTATIONS = (1, 2, 4, 8)  # extraction at 0; 0 and 180; every quarter turn; every 45 degrees (LBurst.extract)


def frame_permutation(n: int, order: str) -> list[int]:
    """Indices that reorder a temporally ordered burst of ``n`` frames.

    ``'temporal'`` keeps ``[-h, ..., 0, ..., h]``.  ``'published'`` is the order the
    published LBurst weights were trained with: ``[-1, -2, ..., -h, 0, 1, ..., h]``
    (for 5 frames ``[-1, -2, 0, +1, +2]``).
    """
    if order == "temporal":
        return list(range(n))
    if order == "published":
        h = n // 2
        return [h - k for k in range(1, h + 1)] + list(range(h, n))
    raise LBurstValueError(f"unknown frame order {order!r}: use 'temporal' or 'published'")


def dense_bytes(height: int, width: int, dim: int = 128) -> int:
    """Bytes :meth:`LBurst.dense` holds at its peak for an ``height x width`` burst: the
    upsampled, the normalised and the returned ``(H, W, D)`` float32 descriptors."""
    return 3 * 4 * height * width * dim


EIGHT_BIT_TOLERANCE = 1e-3  # in steps of 1/255: a float value this close to k/255 came from 8 bits
_INTEGER_TENSORS = (torch.uint8, getattr(torch, "uint16", torch.uint8))  # taken as they are


def _channels_last(x: torch.Tensor) -> np.ndarray:
    """A ``(..., 3, H, W)`` tensor as a NumPy ``(..., H, W, 3)`` array on the CPU."""
    return x.movedim(-3, -1).contiguous().cpu().numpy()


def _integer_frames(x: torch.Tensor) -> torch.Tensor:
    """A float tensor in [0, 1] as integers without loss where it can: uint8 ``round(255 x)``
    when every value is a multiple of 1/255 (an 8-bit image, within
    :data:`EIGHT_BIT_TOLERANCE`; always for float16 and bfloat16, which hold no more), else
    uint16 ``round(65535 x)``."""
    values = x.float()
    finite = torch.isfinite(values)
    if not finite.all():
        raise LBurstValueError(f"the burst tensor holds {int((~finite).sum())} NaN or infinite values")
    check_float_burst(np.array([values.min().item(), values.max().item()]))
    values = values.clamp(0, 1)
    eight = torch.round(values * 255)
    if x.dtype in (torch.float16, torch.bfloat16) or (values * 255 - eight).abs().max() <= EIGHT_BIT_TOLERANCE:
        return eight.to(torch.uint8)
    return torch.round(values * 65535).to(torch.int32)


def burst_from_tensor(x: torch.Tensor) -> np.ndarray:
    """The NumPy burst ``(N, H, W, 3)`` (an image: ``(H, W, 3)``) of a torch burst in torch's
    layout, ``(N, 3, H, W)`` (an image: ``(3, H, W)``), on any device.

    ``x``: uint8 (uint16 where torch has it), or float in [0, 1] (kornia's and LightGlue's
    convention), converted to integers without loss where it can (:func:`_integer_frames`):
    a float burst ``u8 / 255`` gives exactly the features of the uint8 burst ``u8``.
    ``ValueError`` in one line for another layout, dtype or range."""
    if x.ndim not in (3, 4) or x.shape[-3] != 3:
        hint = " (channels last: use x.permute(0, 3, 1, 2), or pass the NumPy array)" if x.shape[-1:] == (3,) else ""
        hint = hint or (
            " (gray: repeat the channel, x.expand(-1, 3, -1, -1))" if x.ndim == 4 and x.shape[1] == 1 else ""
        )
        raise LBurstValueError(
            f"a burst tensor must be (N, 3, H, W), (3, H, W) or a batch (B, N, 3, H, W), got {tuple(x.shape)}{hint}"
        )
    x = x.detach()
    if x.dtype in _INTEGER_TENSORS:
        return _channels_last(x)
    if not x.is_floating_point():
        raise LBurstValueError(f"a burst tensor must be uint8 or float in [0, 1], got {x.dtype}")
    frames = _integer_frames(x)
    array = _channels_last(frames)
    return array if frames.dtype == torch.uint8 else array.astype(np.uint16)


def as_burst(burst) -> np.ndarray:
    """``burst`` as a NumPy array: a torch tensor through :func:`burst_from_tensor`."""
    return burst_from_tensor(burst) if isinstance(burst, torch.Tensor) else np.asarray(burst)


def network_burst(burst: np.ndarray, frames: int) -> np.ndarray:
    """``burst`` as the ``frames``-frame burst ``(N, H, W, 3)`` a network takes (an image
    ``(H, W, 3)`` as one frame; a 1-frame network takes the middle frame of an odd burst);
    ``ValueError`` in one line for another shape or frame count, or an image too small."""
    burst = as_burst(burst)
    if burst.ndim == 3:  # a single image
        burst = burst[None]
    if burst.ndim != 4 or burst.shape[-1] != 3:
        raise LBurstValueError(f"expected a burst (N, H, W, 3) or an image (H, W, 3), got shape {burst.shape}")
    n = burst.shape[0]
    if n != frames:
        if frames == 1 and n % 2 == 1:
            burst = burst[n // 2 : n // 2 + 1]  # single-image net: the common frame
        else:
            raise LBurstValueError(f"this network takes {frames}-frame bursts, got {n} frames")
    if min(burst.shape[1:3]) < MIN_SIDE:  # before any stage, the alignment included
        h, w = burst.shape[1:3]
        raise LBurstValueError(f"a {w}x{h} image is too small for features (at least {MIN_SIDE} px a side)")
    return burst


def full_size(burst) -> tuple[int, int]:
    """(height, width) of a burst (N, H, W, 3) or an image (H, W, 3)."""
    shape = np.shape(burst)
    return (shape[-3], shape[-2]) if len(shape) >= 3 else tuple(shape)


def extract_turned(
    extract: Callable[..., Features], burst: np.ndarray, top_k: int | None, rotations: int, **options
) -> Features:
    """The features ``extract`` finds in ``burst`` turned by each of ``rotations`` steps of a full
    turn, mapped back to the burst's pixels (see :meth:`LBurst.extract`)."""
    if rotations not in ROTATIONS:
        raise LBurstValueError(f"rotations must be one of {ROTATIONS}, got {rotations!r}")
    burst = np.asarray(burst)
    height, width = burst.shape[1:3]
    parts = []
    for step in range(rotations):
        deg = 360 * step // rotations
        if deg % 90 == 0:
            turned = turn_burst(burst, deg // 90)
            to_turned, _ = rotation_map(deg, burst.shape[1:3])
        else:  # bilinear on the turned image's bounding box; reflected borders make no false edges
            turned = np.stack([rotate_image(frame, deg, reflect=True)[0] for frame in burst])
            to_turned, _ = rotation_map(deg, burst.shape[1:3])
        feats = extract(turned, top_k if deg % 90 == 0 else None, **options)
        feats["keypoints"] = map_points(feats["keypoints"], np.linalg.inv(to_turned))
        x, y = feats["keypoints"].T
        inside = np.flatnonzero((x >= -0.5) & (x <= width - 0.5) & (y >= -0.5) & (y <= height - 0.5))
        feats = select(feats, inside[:top_k])  # by score, as extracted
        feats["rotations"] = np.full(len(feats["keypoints"]), deg, np.uint16)
        parts.append(feats)
    return {**concatenate(parts), "image_size": image_size(width, height)}


class LBurst:
    """Feature extractor for robotic bursts (or single images with a 1-frame net): the network's
    runtime (:class:`lburst.model.backend.Backend`, chosen once) under the multi-scale detector
    (:class:`lburst.model.detector.Detector`).

    Example::

        model = LBurst.from_checkpoint("lburst-b5.pt").to("cuda")
        feats = model.extract(burst)          # burst: (N, H, W, 3) uint8, or a tensor (N, 3, H, W)
        feats["keypoints"]                    # (K, 2) float32, x, y
    """

    def __init__(
        self,
        net: LBurstNet | LiteNet | None,
        device: str | torch.device = "cpu",
        frame_order: str = "temporal",
        runner: Runner | None = None,
        frames: int | None = None,
        align: bool = False,
        descriptor_mean: np.ndarray | None = None,
        descriptor_whitening: np.ndarray | None = None,
        pad: int = 0,
        backend: Backend | None = None,
    ) -> None:
        """``net``: the network; or ``runner`` (with ``frames``): any callable with the
        signature of :meth:`lburst.model.fast.FastLBurstNet.forward`, e.g. an ONNX Runtime session;
        or ``backend``, a :class:`lburst.model.backend.Backend` (:meth:`from_checkpoint` opens one).
        ``align``: the weights are run on aligned bursts (their checkpoint says
        ``meta['input'] == 'aligned'``): :meth:`extract` and :meth:`dense` warp a uint8 or
        uint16 burst's frames onto the common frame first (:func:`lburst.burst.align.align_burst`:
        ECC shifts with a constant velocity), as ``align+lburst`` does.
        ``descriptor_mean`` (D,) and ``descriptor_whitening`` (D, D): the weights' descriptor
        whitening (checkpoint ``meta``, :mod:`lburst.train.whitening`); with ``whiten=True``
        descriptors are returned as ``normalize(W (d - mean))`` (``W`` the identity when not
        given).  ``pad``: the reflected border each pyramid level gets unless the call says
        otherwise (:class:`MultiScaleConfig`; :meth:`from_checkpoint` takes it from the weights,
        :func:`default_pad`)."""
        if backend is None and net is None and runner is None:
            raise LBurstValueError("give a network or a runner")
        device = check_device(device)
        if backend is None and runner is None:
            backend = TorchBackend(net, device)
        elif backend is None:
            count = net.config.frames if net is not None else int(frames)
            backend = RunnerBackend(runner, type(runner).__name__, count, net, device)
        self.backend = backend
        self.net, self.frames, self.runtime = backend.net, backend.frames, backend.name  # the network and its runtime
        self.descriptor_dim = backend.descriptor_dim  # D, the descriptors' size
        self.pad = 0 if pad is None else check_pad(pad)
        self.frame_order = frame_order
        self.align = bool(align) and self.frames > 1
        self._perm = frame_permutation(self.frames, frame_order)
        self.whitening = Whitening(descriptor_mean, descriptor_whitening, backend.device)

    @property
    def device(self) -> torch.device:
        """The torch device the network runs on (set at construction, changed by :meth:`to`)."""
        return self.backend.device

    @property
    def fast_net(self) -> Runner:
        """What runs the network in fp32 (built on first use): ``x -> (rep, rel, raw descriptor map)``."""
        return self.backend.runner

    @property
    def descriptor_mean(self) -> torch.Tensor | None:
        """(D,) mean of the descriptor whitening on :attr:`device` (``None`` without one)."""
        return self.whitening.mean

    @property
    def descriptor_whitening(self) -> torch.Tensor | None:
        """(D, D) matrix of the descriptor whitening on :attr:`device` (``None`` without one)."""
        return self.whitening.matrix

    def to(self, device: str | torch.device) -> LBurst:
        """Move the network and the descriptor whitening to ``device`` (``'cuda'``, ``'cpu'``,
        a ``torch.device``) and return this LBurst, as :meth:`torch.nn.Module.to` returns the
        module.  ``ValueError`` for a device that is not there, and for any device but the CPU
        when the network runs on a runtime other than torch (ONNX Runtime, OpenVINO)."""
        if not isinstance(device, (str, torch.device)):
            raise LBurstValueError(f"LBurst.to takes a device (a str or torch.device), got {device!r}")
        self.whitening.to(self.backend.to(device).device)
        return self

    def check_whitening(self) -> None:
        """``ValueError`` unless the weights carry a descriptor whitening."""
        self.whitening.check()

    @classmethod
    def from_onnx(cls, path: str | Path, frame_order: str = "temporal", threads: int | None = None) -> LBurst:
        """Run a model exported by ``lburst export onnx`` with ONNX Runtime (CPU)."""
        runner = OnnxRunner(path, threads=threads)
        whitening = {key: runner.meta.get(key) for key in WHITENING_KEYS}
        align, pad = runner.meta["input"] == "aligned", runner.meta.get("pad", 0)
        return cls(None, "cpu", frame_order, runner=runner, frames=runner.frames, align=align, **whitening, pad=pad)

    @classmethod
    def from_checkpoint(
        cls,
        path: str | Path,
        device: str | torch.device | None = None,
        frame_order: str = "temporal",
        align: bool | None = None,
        runtime: str | Runtime | None = None,
        threads: int | None = None,
        calibration: Calibration | None = None,
    ) -> LBurst:
        """Load a published or lburst checkpoint (see :func:`lburst.model.load_checkpoint`).
        ``align`` defaults to what the checkpoint's ``meta['input']`` says.

        ``runtime`` (CPU only): one of :data:`lburst.model.runtimes.RUNTIMES`, ``'auto'`` for
        the fastest one on this CPU (:func:`lburst.model.runtimes.choose_runtime`), or ``None``:
        ``'auto'`` for the light network, ``'torch'`` (the fast path in fp32) for the
        Fast-Quad-L2-Net.  ``threads``: the runtime's threads (default: torch's setting).
        ``calibration``: what an int8 runtime is calibrated on (bursts, or a function of the frame
        count giving them, such as :func:`lburst.calibration.training_calibration`)."""
        device = check_device(device or ("cuda" if torch.cuda.is_available() else "cpu"))
        net, extra = load_checkpoint(path, device)
        meta = extra.get("meta") if isinstance(extra.get("meta"), dict) else {}
        try:
            pad = default_pad(meta)
        except ValueError as exc:
            raise CheckpointError(f"{path}: {exc}") from None
        threads = threads or torch.get_num_threads()
        runtime = resolve_runtime(runtime, isinstance(net, LiteNet), device, threads)
        backend = open_backend(runtime, net, device, threads=threads, meta=meta, calibration=calibration)
        align = meta.get("input") == "aligned" if align is None else align
        whitening = {key: meta.get(key) for key in WHITENING_KEYS}
        return cls(net, device, frame_order, align=align, **whitening, pad=pad, backend=backend)

    @classmethod
    def pretrained(
        cls,
        name: str = "lburst-b5",
        device: str | torch.device | None = None,
        runtime: str | Runtime | None = None,
        threads: int | None = None,
        calibration: Calibration | None = None,
    ) -> LBurst:
        """Load weights shipped with the package: ``'lburst-b5'`` (the most accurate),
        ``'lburst-b5-lite'`` (the light network: several times faster, run by the fastest
        runtime of the CPU) or ``'lburst-b1'`` (single images).  ``runtime``, ``threads``,
        ``calibration``: as :meth:`from_checkpoint`."""
        return cls.from_checkpoint(
            weights_path(name), device, runtime=runtime, threads=threads, calibration=calibration
        )

    def _detector(self) -> Detector:
        return Detector(self.backend, self.whitening, self.pad)

    def _input(self, burst: np.ndarray, cfg: MultiScaleConfig | None = None) -> tuple[torch.Tensor, float]:
        """The network's input for ``burst`` and the scale it is at: the full resolution
        (1.0), or, with ``cfg``, the first pyramid level that ``cfg`` uses (:func:`first_level`)."""
        burst = network_burst(burst, self.frames)
        if self.align and burst.dtype in (np.uint8, np.uint16):
            burst = align_burst(burst, warp=cfg.warp if cfg is not None else "rigid")
        burst, scale = first_level(burst, cfg, self._perm, self.device) if cfg is not None else (burst, 1.0)
        if scale == 1.0:
            burst = burst[self._perm]
        fast, precision = (True, "fp32") if cfg is None else (cfg.fast, cfg.precision)
        layout = torch.channels_last if fast and self.backend.channels_last(precision) else torch.contiguous_format
        return normalize_burst(burst, self.device, layout), scale

    @torch.inference_mode()
    def dense(self, burst: np.ndarray | torch.Tensor, whiten: bool = False, pad: int | None = None) -> Features:
        """Dense outputs at the input's resolution (``whiten``, ``pad``: as :class:`MultiScaleConfig`;
        ``burst``: one burst, NumPy or torch, as :meth:`extract` takes it).

        Returns ``descriptors`` (H, W, D), ``repeatability`` (H, W) and
        ``reliability`` (H, W), float32 NumPy arrays.  ``ValueError`` before any work when
        they would need more than half of the machine's memory (:func:`dense_bytes`; a
        4000x3000 burst needs about 18 GB): use :meth:`extract`, or a smaller burst.
        """
        burst = as_burst(burst)
        height, width = full_size(burst)
        need, limit = dense_bytes(height, width, self.descriptor_dim), memory_limit_bytes()
        if limit is not None and need > limit:
            raise LBurstValueError(
                f"dense maps of a {width}x{height} burst need about {need / 2**30:.1f} GiB, more than half of "
                f"this machine's memory ({limit / 2**30:.1f} GiB): use extract(), or resize the burst"
            )
        x, _ = self._input(burst)
        return self._detector().dense(x, whiten, pad)

    @torch.inference_mode()
    def extract(
        self, burst: np.ndarray | torch.Tensor, top_k: int | None = 4000, rotations: int = 1, **options
    ) -> Features | list[Features]:
        """Multi-scale keypoints and descriptors of the burst's common frame.

        ``burst``: a NumPy burst ``(N, H, W, 3)`` uint8, uint16 or float in [0, 1], temporal
        order (an image ``(H, W, 3)`` for a 1-frame network); or a torch tensor in torch's
        layout, ``(N, 3, H, W)`` (an image ``(3, H, W)``) uint8 or float in [0, 1], as kornia
        and LightGlue take images, on any device (:func:`burst_from_tensor`: a float tensor
        ``u8 / 255`` gives exactly the features of the uint8 burst ``u8``); or a batch tensor
        ``(B, N, 3, H, W)``, which returns a list of B features dicts (:meth:`extract_batch`).
        ``ValueError`` in one line for another shape, dtype, value range or frame count.

        ``options`` are fields of :class:`MultiScaleConfig`.  Returns, sorted by
        decreasing score: ``keypoints`` (K, 2) float32 x, y (see the module
        docstring for the convention), ``scales`` (K,) (32 / level scale, as
        published), ``scores`` (K,) = reliability x repeatability,
        ``descriptors`` (K, 128) float32, L2-normalised, and ``image_size`` (2,) int64,
        the burst's (width, height) as LightGlue's.

        ``rotations`` 2, 4 or 8 also extracts from the burst turned by 180 degrees (2), by
        each quarter turn (4) or every 45 degrees (8; the odd ones bilinear, with reflected
        borders), up to ``top_k`` keypoints each, mapped back to the burst's pixels (those
        that fall outside are dropped); ``rotations`` (K,) uint16 then says by how many
        degrees (counter-clockwise) each keypoint's burst was turned, and the features are
        sorted by it, then by score.  Matchers match views rotated against each other through
        these sets (:mod:`lburst.matching`): the cost of extraction grows ``rotations``-fold.
        """
        if isinstance(burst, torch.Tensor) and burst.ndim == 5:
            if rotations != 1:
                return [self.extract(one, top_k, rotations, **options) for one in burst]
            return self.extract_batch(burst, top_k, **options)
        burst = as_burst(burst)
        if rotations != 1:
            return extract_turned(self.extract, burst, top_k, rotations, **options)
        cfg = replace(MultiScaleConfig(), top_k=top_k, **options)
        if cfg.whiten:
            self.check_whitening()
        x, scale = self._input(burst, cfg)
        return self._detector().detect(x, cfg, full_size(burst), scale)

    @torch.inference_mode()
    def extract_batch(self, bursts, top_k: int | None = 4000, **options) -> list[Features]:
        """:meth:`extract` of several bursts of one size, run through each pyramid level as
        one batch (what pays on a GPU; on a CPU it equals a loop over :meth:`extract`).
        ``bursts``: a sequence of bursts (NumPy or torch, as :meth:`extract` takes them), an
        array ``(B, N, H, W, 3)`` or a tensor ``(B, N, 3, H, W)``.  Returns a list of B features
        dicts (one for a batch of one); each equals :meth:`extract` of that burst up to float
        rounding."""
        cfg = replace(MultiScaleConfig(), top_k=top_k, **options)
        if cfg.whiten:
            self.check_whitening()
        bursts = [as_burst(burst) for burst in bursts]
        if not bursts:
            return []
        sizes = {full_size(burst) for burst in bursts}
        if len(sizes) > 1:
            raise LBurstValueError(f"extract_batch takes bursts of one size, got {sorted(sizes)}")
        inputs = [self._input(burst, cfg) for burst in bursts]
        x = torch.cat([x for x, _ in inputs])
        found = self._detector().detect(x, cfg, sizes.pop(), inputs[0][1])
        return found if isinstance(found, list) else [found]
