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

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F

from lburst.burst.align import align_burst, check_warp
from lburst.errors import LBurstValueError
from lburst.features import Features, concatenate, image_size, select
from lburst.memory import memory_limit_bytes
from lburst.model.fast import FastLBurstNet, descriptor_stride, descriptors_at
from lburst.model.lite import LiteNet
from lburst.model.network import (
    WHITENING_KEYS,
    CheckpointError,
    LBurstNet,
    autocast_dtype,
    check_device,
    check_float_burst,
    check_pad,
    check_precision,
    default_pad,
    load_checkpoint,
    normalize_burst,
)
from lburst.model.onnx import OnnxRunner
from lburst.model.runtimes import choose_runtime, inference_form, make_runner
from lburst.rotation import map_points, rotate_image, rotation_map, turn_burst
from lburst.weights import weights_path

ROTATIONS = (1, 2, 4, 8)  # extraction at 0; 0 and 180; every quarter turn; every 45 degrees (LBurst.extract)


@dataclass(frozen=True)
class MultiScaleConfig:
    """Multi-scale detection settings; defaults are the paper's.

    Attributes:
        min_size: smallest long side of a pyramid level, in pixels.
        max_size: largest long side of a pyramid level, in pixels.
        scale_factor: ratio between consecutive levels.
        min_scale, max_scale: bounds on the level's scale relative to the input.  The published
            code's pyramid starts at the input's size (``max_scale`` 1); above 1 (at most
            :data:`MAX_UPSCALE`) it starts with levels upsampled from the input (bilinear), at
            the powers of ``scale_factor`` up to ``max_scale`` (and ``max_size``), so that a view
            seen from further away meets the nearer view's finest keypoints at their scale.
            The levels from the input down are the same as without them.
        rel_thr, rep_thr: reliability and repeatability thresholds for keypoints.
        top_k: keep the best ``top_k`` keypoints by score (``None``: all).
        published_coordinates: map level coordinates as the published code does
            (``x * W / w``) instead of the pixel-centre-correct mapping.
        fast: use :class:`lburst.model.fast.FastLBurstNet` (same features, less work);
            ``False`` runs the plain network as the published code does.
        precision: ``'fp32'``, or ``'bf16'``/``'fp16'`` for the fast path's backbone
            (autocast; heads stay fp32): faster where the hardware has it, not identical.
        whiten: return whitened descriptors (the weights' ``descriptor_whitening``,
            :mod:`lburst.train.whitening`): more mutual matches, a lower share of them correct.
        pad: pixels of reflected image added around each pyramid level before the network
            runs; keypoints are kept inside the level.  ``None``: the weights' own
            (:attr:`LBurst.pad`, their ``meta['pad']``; 0 for every shipped and published
            weights).  Without it the network sees each level's border as zero padding, to
            which lburst's weights learnt to give a low reliability, so their keypoints avoid
            the outer 16 px; with 32 px they cover it as the published model does, at about
            15 % more time and with mixed results in 3D (docs/results/border.md, "A reflected border
            at extraction").
        warp: how weights that read aligned bursts (:attr:`LBurst.align`) get them:
            ``'rigid'`` aligns each frame by a translation (and a rotation where the burst
            turns), ``'affine'`` refines that to an affine map per frame, which also takes out
            the zoom of a camera moving along its view (:func:`lburst.burst.align.affine_warps`).
        subpixel: move each keypoint to the vertex of a parabola through its repeatability
            peak and the two neighbours, along x and along y (:func:`subpixel_offsets`),
            instead of keeping the level's pixel centre, which is up to 2 px off at a
            quarter-size level.  Descriptors stay those of the peak's pixel.
    """

    min_size: int = 256
    max_size: int = 1024
    scale_factor: float = 2**0.25
    min_scale: float = 0.0
    max_scale: float = 1.0
    rel_thr: float = 0.7
    rep_thr: float = 0.7
    top_k: int | None = 4000
    published_coordinates: bool = False
    fast: bool = True
    precision: str = "fp32"
    whiten: bool = False
    pad: int | None = None
    subpixel: bool = False
    warp: str = "rigid"

    def __post_init__(self) -> None:
        """``ValueError`` naming the field for any value outside its range (every use of
        the settings goes through here, so no loop below can run away)."""
        for name in ("min_size", "max_size"):
            value = getattr(self, name)
            if not _is_int(value) or value < 1:
                raise LBurstValueError(f"{name} must be an integer >= 1, got {value!r}")
        if self.max_size < self.min_size:
            raise LBurstValueError(f"max_size {self.max_size} is below min_size {self.min_size}")
        if not _is_real(self.scale_factor) or not 1 < self.scale_factor < float("inf"):
            raise LBurstValueError(
                f"scale_factor must be a number > 1 (the ratio of consecutive levels), got {self.scale_factor!r}"
            )
        if not (
            _is_real(self.min_scale)
            and _is_real(self.max_scale)
            and 0 <= self.min_scale <= self.max_scale
            and 0 < self.max_scale <= MAX_UPSCALE
        ):
            raise LBurstValueError(
                f"scales must satisfy 0 <= min_scale <= max_scale, 0 < max_scale <= {MAX_UPSCALE} (levels above 1 "
                f"are upsampled from the input); got {self.min_scale!r}, {self.max_scale!r}"
            )
        for name in ("rel_thr", "rep_thr"):
            value = getattr(self, name)
            if not _is_real(value) or not 0 <= value <= 1:
                raise LBurstValueError(f"{name} must be in [0, 1], got {value!r}")
        if self.pad is not None:
            check_pad(self.pad)
        if self.top_k is not None and (not _is_int(self.top_k) or self.top_k < 0):
            raise LBurstValueError(f"top_k must be an integer >= 0 or None, got {self.top_k!r}")
        for name in ("published_coordinates", "fast", "whiten", "subpixel"):
            if not isinstance(getattr(self, name), bool):
                raise LBurstValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        autocast_dtype(self.precision)
        check_warp(self.warp)
        levels = 1 + math.log(self.max_size / self.min_size) / math.log(self.scale_factor)
        if levels > MAX_LEVELS:
            raise LBurstValueError(
                f"scale_factor {self.scale_factor} between max_size {self.max_size} and min_size "
                f"{self.min_size} makes {levels:.0f} pyramid levels (at most {MAX_LEVELS})"
            )


MAX_LEVELS = 64  # pyramid levels of one extraction (the paper's settings make 9)
MAX_UPSCALE = 4.0  # the largest max_scale: a level upsampled 4x costs 16 full-size levels
MIN_SIDE = 8  # pixels: images and pyramid levels smaller than this are not used


def top_scale(cfg: MultiScaleConfig, long_side: int) -> float:
    """The largest scale a pyramid level of an input of ``long_side`` pixels may have: at most
    ``cfg.max_scale``, and no level's long side above ``cfg.max_size``."""
    return min(cfg.max_scale, cfg.max_size / long_side)


def upper_scales(cfg: MultiScaleConfig, long_side: int) -> list[float]:
    """Scales above 1 of the levels upsampled from an input of ``long_side`` pixels, largest
    first: the powers of ``cfg.scale_factor`` up to :func:`top_scale` (none at the default
    ``max_scale`` 1)."""
    top = top_scale(cfg, long_side)
    if top <= 1.001:
        return []
    n = math.floor(math.log(top + 0.001) / math.log(cfg.scale_factor))
    return [cfg.scale_factor**k for k in range(n, 0, -1)]


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _is_real(value) -> bool:
    return (
        isinstance(value, (int, float, np.integer, np.floating))
        and not isinstance(value, bool)
        and math.isfinite(value)
    )


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


def _local_maxima(
    rep: torch.Tensor, rel: torch.Tensor, cfg: MultiScaleConfig, pad: int = 0
) -> tuple[torch.Tensor, torch.Tensor]:
    """(y, x) of 3x3 local maxima of ``rep`` (1,1,h,w) passing both thresholds, at least
    ``pad`` pixels inside every border."""
    maxima = rep == F.max_pool2d(rep, kernel_size=3, stride=1, padding=1)
    maxima &= rep >= cfg.rep_thr
    maxima &= rel >= cfg.rel_thr
    h, w = maxima.shape[-2:]
    yx = maxima[0, 0, pad : h - pad, pad : w - pad].nonzero() + pad
    return yx[:, 0], yx[:, 1]


def subpixel_offsets(rep: torch.Tensor, y: torch.Tensor, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Sub-pixel offsets ``(dy, dx)`` of the peaks of ``rep`` (1,1,h,w) at integer ``(y, x)``:
    the vertex of a parabola through each peak and its two neighbours, along each axis
    (as SIFT's and Harris' detectors refine their extrema), clipped to half a pixel.  An axis
    whose neighbour falls outside the map, or whose three samples are not concave, keeps 0."""
    h, w = rep.shape[-2:]
    r = rep[0, 0].float()
    up, down = (y - 1).clamp(min=0), (y + 1).clamp(max=h - 1)
    left, right = (x - 1).clamp(min=0), (x + 1).clamp(max=w - 1)
    centre = r[y, x]
    dy = _vertex(r[up, x], centre, r[down, x], (y > 0) & (y < h - 1))
    dx = _vertex(r[y, left], centre, r[y, right], (x > 0) & (x < w - 1))
    return dy, dx


def _vertex(before: torch.Tensor, centre: torch.Tensor, after: torch.Tensor, inside: torch.Tensor) -> torch.Tensor:
    """Offset of the vertex of the parabola through three samples one pixel apart, within
    half a pixel; 0 where ``inside`` is false or the samples are not concave."""
    curvature = before - 2 * centre + after
    concave = inside & (curvature < 0)
    step = torch.where(concave, (before - after) / (2 * curvature.where(concave, -1.0)), 0.0)
    return step.clamp(-0.5, 0.5)


def _layout(x: torch.Tensor) -> torch.memory_format:
    """The memory format ``x`` is in (channels-last or contiguous)."""
    return torch.channels_last if x.is_contiguous(memory_format=torch.channels_last) else torch.contiguous_format


def _kth_best(scores: list[torch.Tensor], k: int | None) -> float:
    """The ``k``-th best of the ``scores`` of the first list entry, and of all entries
    together: keypoints below it cannot reach the final top ``k``, so their descriptors are
    not sampled (``-inf`` when there are fewer than ``k``; the result is unchanged)."""
    if k is None or k == 0:
        return float("-inf") if k is None else float("inf")
    best = float("-inf")
    for pool in (scores[0], torch.cat(scores)):
        if len(pool) >= k:
            best = max(best, torch.topk(pool, k, sorted=False).values.min().item())
    return best


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


class LBurst:
    """Feature extractor for robotic bursts (or single images with a 1-frame net).

    Example::

        model = LBurst.from_checkpoint("lburst-b5.pt").to("cuda")
        feats = model.extract(burst)          # burst: (N, H, W, 3) uint8, or a tensor (N, 3, H, W)
        feats["keypoints"]                    # (K, 2) float32, x, y
    """

    def __init__(
        self,
        net: LBurstNet | None,
        device: str | torch.device = "cpu",
        frame_order: str = "temporal",
        runner: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor, torch.Tensor]] | None = None,
        frames: int | None = None,
        align: bool = False,
        descriptor_mean: np.ndarray | None = None,
        descriptor_whitening: np.ndarray | None = None,
        pad: int = 0,
    ) -> None:
        """``net``: the network; or ``runner`` (with ``frames``): any callable with the
        signature of :meth:`lburst.model.fast.FastLBurstNet.forward`, e.g. an ONNX Runtime session.
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
        if net is None and runner is None:
            raise LBurstValueError("give a network or a runner")
        self._device = check_device(device)
        self.pad = 0 if pad is None else check_pad(pad)
        self.net = net.eval().to(self.device) if net is not None else None
        self.frames = net.config.frames if net is not None else int(frames)
        self.frame_order = frame_order
        self.align = bool(align) and self.frames > 1
        self._perm = frame_permutation(self.frames, frame_order)
        self._runner = runner
        self.runtime = "torch" if runner is None else type(runner).__name__
        self._reduced: dict[str, FastLBurstNet] = {}
        self.descriptor_mean = self.descriptor_whitening = None
        if descriptor_whitening is not None and descriptor_mean is None:
            raise LBurstValueError("descriptor_whitening needs descriptor_mean")
        if descriptor_mean is not None:
            mean = torch.as_tensor(np.asarray(descriptor_mean, np.float32))
            if mean.ndim != 1 or not torch.isfinite(mean).all():
                raise LBurstValueError(f"descriptor_mean must be a finite (D,) vector, got shape {tuple(mean.shape)}")
            self.descriptor_mean = mean.to(self.device)
        if descriptor_whitening is not None:
            matrix = torch.as_tensor(np.asarray(descriptor_whitening, np.float32))
            if matrix.shape != (len(self.descriptor_mean),) * 2 or not torch.isfinite(matrix).all():
                raise LBurstValueError(
                    f"descriptor_whitening must be a finite ({len(self.descriptor_mean)}, "
                    f"{len(self.descriptor_mean)}) matrix, got shape {tuple(matrix.shape)}"
                )
            self.descriptor_whitening = matrix.to(self.device)

    @property
    def device(self) -> torch.device:
        """The torch device the network runs on (set at construction, changed by :meth:`to`)."""
        return self._device

    def to(self, device: str | torch.device) -> "LBurst":
        """Move the network and the descriptor whitening to ``device`` (``'cuda'``, ``'cpu'``,
        a ``torch.device``) and return this LBurst, as :meth:`torch.nn.Module.to` returns the
        module.  ``ValueError`` for a device that is not there, and for any device but the CPU
        when the network runs on a runtime other than torch (ONNX Runtime, OpenVINO)."""
        if not isinstance(device, (str, torch.device)):
            raise LBurstValueError(f"LBurst.to takes a device (a str or torch.device), got {device!r}")
        movable = self._runner is None or isinstance(self._runner, torch.nn.Module)
        if not movable and str(device).split(":")[0] != "cpu":
            raise LBurstValueError(
                f"runtime {self.runtime!r} runs on the CPU only; load the weights with runtime='torch'"
            )
        device = check_device(device)
        for module in (self.net, self._runner, *self._reduced.values()):
            if isinstance(module, torch.nn.Module):
                module.to(device)
        if self.descriptor_mean is not None:
            self.descriptor_mean = self.descriptor_mean.to(device)
        if self.descriptor_whitening is not None:
            self.descriptor_whitening = self.descriptor_whitening.to(device)
        self._device = device
        return self

    def check_whitening(self) -> None:
        """``ValueError`` unless the weights carry a descriptor whitening."""
        if self.descriptor_mean is None:
            raise LBurstValueError("these weights carry no descriptor whitening; add it with `lburst export whitened`")

    def _whiten(self, desc: torch.Tensor, dim: int) -> torch.Tensor:
        """``normalize(W (desc - mean))`` along ``dim`` (``W`` the identity without a matrix)."""
        self.check_whitening()
        d = desc.float().movedim(dim, -1) - self.descriptor_mean
        if self.descriptor_whitening is not None:
            d = d @ self.descriptor_whitening.T
        return F.normalize(d, dim=-1).movedim(-1, dim)

    @property
    def descriptor_dim(self) -> int:
        """D, the descriptors' size (128 for the shipped weights)."""
        return self.net.config.dim if self.net is not None and hasattr(self.net.config, "dim") else 128

    @property
    def fast_net(self) -> Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
        """The fast form of the network (built on first use): ``x -> (rep, rel, half)``."""
        if self._runner is None:
            self._runner = inference_form(self.net).to(self.device).eval()
        return self._runner

    def _torch_levels(self, precision: str) -> bool:
        """Whether the pyramid levels run through a torch module (which wants channels-last input)."""
        if self.net is None:
            return False
        return precision != "fp32" or self._runner is None or isinstance(self._runner, torch.nn.Module)

    def _fast_level(self, x: torch.Tensor, precision: str):
        if precision == "fp32" or self.net is None:
            return self.fast_net(x)
        if precision not in self._reduced:
            check_precision(precision, self.device)
            self._reduced[precision] = inference_form(self.net, precision).to(self.device).eval()
        return self._reduced[precision](x)

    @classmethod
    def from_onnx(cls, path: str | Path, frame_order: str = "temporal", threads: int | None = None) -> "LBurst":
        """Run a model exported by ``lburst export onnx`` with ONNX Runtime (CPU)."""
        runner = OnnxRunner(path, threads=threads)
        return cls(
            None,
            "cpu",
            frame_order,
            runner=runner,
            frames=runner.frames,
            align=runner.meta["input"] == "aligned",
            **{key: runner.meta.get(key) for key in WHITENING_KEYS},
            pad=runner.meta.get("pad", 0),
        )

    @classmethod
    def from_checkpoint(
        cls,
        path: str | Path,
        device: str | torch.device | None = None,
        frame_order: str = "temporal",
        align: bool | None = None,
        runtime: str | None = None,
        threads: int | None = None,
    ) -> "LBurst":
        """Load a published or lburst checkpoint (see :func:`lburst.model.load_checkpoint`).
        ``align`` defaults to what the checkpoint's ``meta['input']`` says.

        ``runtime`` (CPU only): one of :data:`lburst.model.runtimes.RUNTIMES`, ``'auto'`` for
        the fastest one on this CPU (:func:`lburst.model.runtimes.choose_runtime`), or ``None``:
        ``'auto'`` for the light network, ``'torch'`` (the fast path in fp32) for the
        Fast-Quad-L2-Net.  ``threads``: the runtime's threads (default: torch's setting)."""
        device = check_device(device or ("cuda" if torch.cuda.is_available() else "cpu"))
        net, extra = load_checkpoint(path, device)
        meta = extra.get("meta") if isinstance(extra.get("meta"), dict) else {}
        if align is None:
            align = meta.get("input") == "aligned"
        try:
            pad = default_pad(meta)
        except ValueError as exc:
            raise CheckpointError(f"{path}: {exc}") from None
        threads = threads or torch.get_num_threads()
        if runtime is None:
            runtime = "auto" if isinstance(net, LiteNet) and device.type == "cpu" else "torch"
        if runtime == "auto":
            runtime = choose_runtime(threads=threads) if device.type == "cpu" else "torch"
        if runtime != "torch" and device.type != "cpu":
            raise LBurstValueError(f"runtime {runtime!r} runs on the CPU only; on {device.type} use 'torch'")
        runner = None if runtime == "torch" else make_runner(runtime, net, threads=threads, meta=meta)
        model = cls(
            net,
            device,
            frame_order,
            runner=runner,
            align=align,
            **{key: meta.get(key) for key in WHITENING_KEYS},
            pad=pad,
        )
        model.runtime = runtime
        return model

    @classmethod
    def pretrained(
        cls,
        name: str = "lburst-b5",
        device: str | torch.device | None = None,
        runtime: str | None = None,
        threads: int | None = None,
    ) -> "LBurst":
        """Load weights shipped with the package: ``'lburst-b5'`` (the most accurate),
        ``'lburst-b5-lite'`` (the light network: several times faster, run by the fastest
        runtime of the CPU) or ``'lburst-b1'`` (single images).  ``runtime``, ``threads``:
        as :meth:`from_checkpoint`."""
        return cls.from_checkpoint(weights_path(name), device, runtime=runtime, threads=threads)

    def _input(self, burst: np.ndarray, cfg: MultiScaleConfig | None = None) -> tuple[torch.Tensor, float]:
        """The network's input for ``burst`` and the scale it is at: the full resolution
        (1.0), or, with ``cfg``, the first pyramid level that ``cfg`` uses (see :meth:`_reduce`)."""
        burst = as_burst(burst)
        if burst.ndim == 3:  # a single image
            burst = burst[None]
        if burst.ndim != 4 or burst.shape[-1] != 3:
            raise LBurstValueError(f"expected a burst (N, H, W, 3) or an image (H, W, 3), got shape {burst.shape}")
        n = burst.shape[0]
        if n != self.frames:
            if self.frames == 1 and n % 2 == 1:
                burst = burst[n // 2 : n // 2 + 1]  # single-image net: the common frame
            else:
                raise LBurstValueError(f"this network takes {self.frames}-frame bursts, got {n} frames")
        if min(burst.shape[1:3]) < MIN_SIDE:  # before any stage, the alignment included
            h, w = burst.shape[1:3]
            raise LBurstValueError(f"a {w}x{h} image is too small for features (at least {MIN_SIDE} px a side)")
        if self.align and n == self.frames and burst.dtype in (np.uint8, np.uint16):
            burst = align_burst(burst, warp=cfg.warp if cfg is not None else "rigid")
        burst, scale = self._reduce(burst, cfg) if cfg is not None else (burst, 1.0)
        if scale == 1.0:
            burst = burst[self._perm]
        torch_levels = self._torch_levels("fp32") if cfg is None else cfg.fast and self._torch_levels(cfg.precision)
        layout = torch.channels_last if torch_levels else torch.contiguous_format
        return normalize_burst(burst, self.device, layout), scale

    def _reduce(self, burst: np.ndarray, cfg: MultiScaleConfig) -> tuple[np.ndarray, float]:
        """The burst at the first pyramid level ``cfg`` uses, frame by frame in the network's
        frame order, as float in [0, 1], and that level's scale (the burst unchanged, and
        1.0, when that level is the full resolution).

        The levels are resized one from the last by bilinear interpolation, as
        :meth:`_extract` resizes the normalised input; doing it on the frames first keeps a
        large burst's memory to one frame's float copy (a 4000x3000 burst at the default
        1024 px) instead of the whole normalised burst at full resolution."""
        height, width = burst.shape[1:3]
        long_side = max(height, width)
        upper = top_scale(cfg, long_side)
        lowest = max(cfg.min_scale, cfg.min_size / long_side)
        s, sizes = 1.0, []
        while s - 0.001 > upper and s / cfg.scale_factor + 0.001 >= lowest:
            s /= cfg.scale_factor
            if min(height, width) * s < MIN_SIDE:
                break
            sizes.append((round(height * s), round(width * s)))
        if not sizes or min(height, width) * s < MIN_SIDE:
            return burst, 1.0
        unit = 1 / 255.0 if burst.dtype == np.uint8 else 1 / 65535.0 if burst.dtype == np.uint16 else 1.0
        frames = []
        for i in self._perm:
            t = torch.from_numpy(np.ascontiguousarray(burst[i])).permute(2, 0, 1)[None].to(self.device, torch.float32)
            t = t * unit if unit != 1.0 else t
            for size in sizes:
                t = F.interpolate(t, size, mode="bilinear", align_corners=False)
            frames.append(t[0].permute(1, 2, 0).cpu().numpy())
        return np.stack(frames), s

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
        height, width = self._full_size(burst)
        need, limit = dense_bytes(height, width, self.descriptor_dim), memory_limit_bytes()
        if limit is not None and need > limit:
            raise LBurstValueError(
                f"dense maps of a {width}x{height} burst need about {need / 2**30:.1f} GiB, more than half of "
                f"this machine's memory ({limit / 2**30:.1f} GiB): use extract(), or resize the burst"
            )
        x, _ = self._input(burst)
        h, w = x.shape[-2:]
        xp, pad = self._reflect(x, pad)
        inside = (..., slice(pad, pad + h), slice(pad, pad + w))  # the burst's pixels in the padded maps
        rep, rel, half = self.fast_net(xp)
        stride = descriptor_stride(half.shape[-1], xp.shape[-1])
        desc = F.interpolate(half, scale_factor=float(stride), mode="bilinear", align_corners=False)
        desc = F.normalize(desc[inside], dim=1)
        rep, rel = rep[inside], rel[inside]
        if whiten:
            desc = self._whiten(desc, dim=1)
        desc = F.pad(desc, (0, w - desc.shape[-1], 0, h - desc.shape[-2]), mode="replicate")
        return {
            "descriptors": desc[0].permute(1, 2, 0).float().cpu().numpy(),
            "repeatability": rep[0, 0].float().cpu().numpy(),
            "reliability": rel[0, 0].float().cpu().numpy(),
        }

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
            return self._extract_turned(burst, top_k, rotations, **options)
        cfg = replace(MultiScaleConfig(), top_k=top_k, **options)
        if cfg.whiten:
            self.check_whitening()
        x, scale = self._input(burst, cfg)
        return self._extract(x, cfg, self._full_size(burst), scale)

    def _extract_turned(self, burst: np.ndarray, top_k: int | None, rotations: int, **options) -> Features:
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
            feats = self.extract(turned, top_k if deg % 90 == 0 else None, **options)
            feats["keypoints"] = map_points(feats["keypoints"], np.linalg.inv(to_turned))
            x, y = feats["keypoints"].T
            inside = np.flatnonzero((x >= -0.5) & (x <= width - 0.5) & (y >= -0.5) & (y <= height - 0.5))
            feats = select(feats, inside[:top_k])  # by score, as extracted
            feats["rotations"] = np.full(len(feats["keypoints"]), deg, np.uint16)
            parts.append(feats)
        return {**concatenate(parts), "image_size": image_size(width, height)}

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
        sizes = {self._full_size(burst) for burst in bursts}
        if len(sizes) > 1:
            raise LBurstValueError(f"extract_batch takes bursts of one size, got {sorted(sizes)}")
        inputs = [self._input(burst, cfg) for burst in bursts]
        x = torch.cat([x for x, _ in inputs])
        found = self._extract(x, cfg, sizes.pop(), inputs[0][1])
        return found if isinstance(found, list) else [found]

    def _reflect(self, x: torch.Tensor, pad: int | None) -> tuple[torch.Tensor, int]:
        """``x`` with ``pad`` pixels (``None``: :attr:`pad`) of reflected image on every side, at
        most one less than its shorter side (what reflection allows), and that pad."""
        pad = min(self.pad if pad is None else check_pad(pad), x.shape[-2] - 1, x.shape[-1] - 1)
        if not pad:
            return x, 0
        return F.pad(x, (pad,) * 4, mode="reflect").contiguous(memory_format=_layout(x)), pad

    @staticmethod
    def _full_size(burst) -> tuple[int, int]:
        """(height, width) of a burst (N, H, W, 3) or an image (H, W, 3)."""
        shape = np.shape(burst)
        return (shape[-3], shape[-2]) if len(shape) >= 3 else tuple(shape)

    def _descriptors(self, desc: torch.Tensor, whiten: bool) -> np.ndarray:
        return (self._whiten(desc, dim=1) if whiten else desc).float().cpu().numpy()

    def _extract(
        self, x: torch.Tensor, cfg: MultiScaleConfig, full_size: tuple[int, int] | None = None, start: float = 1.0
    ) -> Features | list[Features]:
        """Multi-scale features of the normalised bursts ``x`` (B, 3N, h, w): one features dict
        when B is 1 (what :meth:`extract` returns), else a list of B.  ``x`` is the bursts at
        scale ``start`` of their ``full_size`` (H, W) (default: ``x`` is at full size)."""
        height, width = full_size or x.shape[-2:]
        if min(height, width) < MIN_SIDE:
            raise LBurstValueError(
                f"a {width}x{height} image is too small for features (at least {MIN_SIDE} px a side)"
            )
        if cfg.fast and self._torch_levels(cfg.precision):  # channels-last once: each level is resized in it
            x = x.contiguous(memory_format=torch.channels_last)
        batch = x.shape[0]
        long_side = max(height, width)
        found: list[list[tuple]] = [[] for _ in range(batch)]  # per burst: (x, y, scale, score, desc) per level
        if start == 1.0:  # levels above the input, each upsampled from it
            for s in upper_scales(cfg, long_side):
                level = F.interpolate(x, (round(height * s), round(width * s)), mode="bilinear", align_corners=False)
                self._level(level, s, cfg, found, full=(height, width))
        s, top = start, top_scale(cfg, long_side)
        lowest = max(cfg.min_scale, cfg.min_size / long_side)
        if s + 0.001 < lowest:  # an image smaller than min_size: one level at its own size
            lowest = s
        while s + 0.001 >= lowest:
            if s - 0.001 <= top:
                self._level(x, s, cfg, found, full=(height, width))
            s /= cfg.scale_factor
            if min(height, width) * s < MIN_SIDE:
                break
            if s + 0.001 >= lowest:  # a next level: resize the last one
                size = (round(height * s), round(width * s))
                x = F.interpolate(x, size, mode="bilinear", align_corners=False)
        if not found[0]:
            raise LBurstValueError(
                f"no pyramid level between max_size {cfg.max_size} and min_size {cfg.min_size} "
                f"for a {width}x{height} image"
            )
        results = [{**self._select(levels, cfg), "image_size": image_size(width, height)} for levels in found]
        return results[0] if batch == 1 else results

    def _level(
        self, x: torch.Tensor, s: float, cfg: MultiScaleConfig, found: list[list[tuple]], full: tuple[int, int]
    ) -> None:
        """Keypoints of one pyramid level ``x`` (B, 3N, h, w), at scale ``s`` of the bursts' ``full``
        (H, W), appended to each burst's list in ``found`` as (x, y, scale, score, descriptors)."""
        height, width = full
        h, w = x.shape[-2:]
        xp, pad = self._reflect(x, cfg.pad)
        if cfg.fast or self.net is None:
            rep, rel, half = self._fast_level(xp, cfg.precision)
            stride = descriptor_stride(half.shape[-1], xp.shape[-1])
        else:
            out = self.net(xp)
            rep, rel = out["repeatability"], out["reliability"]
        for b in range(x.shape[0]):
            y, xx = _local_maxima(rep[b : b + 1], rel[b : b + 1], cfg, pad)
            score = rep[b, 0, y, xx] * rel[b, 0, y, xx]
            keep = score >= _kth_best([score] + [level[3] for level in found[b]], cfg.top_k)
            y, xx, score = y[keep], xx[keep], score[keep]
            if cfg.fast or self.net is None:
                desc = descriptors_at(half[b : b + 1], y, xx, stride)
            else:
                desc = out["descriptors"][b, :, y, xx].t()
            fy, fx = subpixel_offsets(rep[b : b + 1], y, xx) if cfg.subpixel else (0.0, 0.0)
            y, xx = y.float() - pad + fy, xx.float() - pad + fx
            if cfg.published_coordinates:
                px, py = xx * width / w, y * height / h
            else:
                px, py = (xx + 0.5) * (width / w) - 0.5, (y + 0.5) * (height / h) - 0.5
            found[b].append((px, py, torch.full((len(y),), 32 / s, device=x.device), score, desc))

    def _select(self, levels: list[tuple], cfg: MultiScaleConfig) -> Features:
        """The ``top_k`` best keypoints of one burst over its pyramid levels, by decreasing score."""
        xs, ys, scales, scores, descs = (torch.cat(parts) for parts in zip(*levels))
        k = len(scores) if cfg.top_k is None else min(cfg.top_k, len(scores))
        order = torch.topk(scores, k, sorted=True).indices
        return {
            "keypoints": torch.stack([xs, ys], -1)[order].float().cpu().numpy(),
            "scales": scales[order].float().cpu().numpy(),
            "scores": scores[order].float().cpu().numpy(),
            "descriptors": self._descriptors(descs[order], cfg.whiten),
        }
