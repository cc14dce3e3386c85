"""Multi-scale detection: the pyramid, the 3x3 maxima, descriptors and the top k, whatever
runtime runs the network (:mod:`lburst.model.backend`).

A keypoint found at ``(x, y)`` in a level resized to ``w x h`` of a ``W x H`` burst maps back
as ``(x + 0.5) * W / w - 0.5`` (pixel centres at integer coordinates, see
:mod:`lburst.model.extractor`), or as ``x * W / w`` with ``published_coordinates``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from lburst.burst.align import check_warp
from lburst.errors import LBurstValueError
from lburst.features import Features, image_size
from lburst.model.backend import Backend
from lburst.model.fast import descriptor_stride, descriptors_at
from lburst.model.network import autocast_dtype, check_pad


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


class Whitening:
    """The weights' descriptor whitening (checkpoint ``meta``, :mod:`lburst.train.whitening`):
    descriptors ``d`` become ``normalize(W (d - mean))``, ``W`` the identity when ``matrix`` is
    ``None``; no whitening at all when ``mean`` is ``None``.  ``ValueError`` for a mean that is not
    a finite (D,) vector or a matrix that is not a finite (D, D) one."""

    def __init__(self, mean: np.ndarray | None, matrix: np.ndarray | None, device: torch.device) -> None:
        self.mean = self.matrix = None
        if matrix is not None and mean is None:
            raise LBurstValueError("descriptor_whitening needs descriptor_mean")
        if mean is not None:
            mean = torch.as_tensor(np.asarray(mean, np.float32))
            if mean.ndim != 1 or not torch.isfinite(mean).all():
                raise LBurstValueError(f"descriptor_mean must be a finite (D,) vector, got shape {tuple(mean.shape)}")
            self.mean = mean.to(device)
        if matrix is not None:
            matrix = torch.as_tensor(np.asarray(matrix, np.float32))
            if matrix.shape != (len(self.mean),) * 2 or not torch.isfinite(matrix).all():
                raise LBurstValueError(
                    f"descriptor_whitening must be a finite ({len(self.mean)}, "
                    f"{len(self.mean)}) matrix, got shape {tuple(matrix.shape)}"
                )
            self.matrix = matrix.to(device)

    def check(self) -> None:
        """``ValueError`` unless the weights carry a descriptor whitening."""
        if self.mean is None:
            raise LBurstValueError("these weights carry no descriptor whitening; add it with `lburst export whitened`")

    def __call__(self, desc: torch.Tensor, dim: int) -> torch.Tensor:
        """``desc`` whitened along ``dim``."""
        self.check()
        d = desc.float().movedim(dim, -1) - self.mean
        if self.matrix is not None:
            d = d @ self.matrix.T
        return F.normalize(d, dim=-1).movedim(-1, dim)

    def to(self, device: torch.device) -> None:
        """Move the mean and the matrix to ``device``."""
        self.mean = self.mean.to(device) if self.mean is not None else None
        self.matrix = self.matrix.to(device) if self.matrix is not None else None


def first_level(
    burst: np.ndarray, cfg: MultiScaleConfig, order: list[int], device: torch.device
) -> tuple[np.ndarray, float]:
    """The burst at the first pyramid level ``cfg`` uses, frame by frame in the network's
    frame ``order``, as float in [0, 1], and that level's scale (the burst unchanged, and
    1.0, when that level is the full resolution).

    The levels are resized one from the last by bilinear interpolation, as
    :meth:`Detector.detect` resizes the normalised input; doing it on the frames first keeps a
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
    for i in order:
        t = torch.from_numpy(np.ascontiguousarray(burst[i])).permute(2, 0, 1)[None].to(device, torch.float32)
        t = t * unit if unit != 1.0 else t
        for size in sizes:
            t = F.interpolate(t, size, mode="bilinear", align_corners=False)
        frames.append(t[0].permute(1, 2, 0).cpu().numpy())
    return np.stack(frames), s


@dataclass
class Detector:
    """Keypoints and descriptors of normalised bursts, the network run by ``backend``;
    ``whitening`` applies to descriptors when an extraction asks for it, ``pad`` is the reflected
    border of every level unless it says otherwise (:class:`MultiScaleConfig`)."""

    backend: Backend
    whitening: Whitening
    pad: int = 0

    def reflect(self, x: torch.Tensor, pad: int | None) -> tuple[torch.Tensor, int]:
        """``x`` with ``pad`` pixels (``None``: :attr:`pad`) of reflected image on every side, at
        most one less than its shorter side (what reflection allows), and that pad."""
        pad = min(self.pad if pad is None else check_pad(pad), x.shape[-2] - 1, x.shape[-1] - 1)
        if not pad:
            return x, 0
        return F.pad(x, (pad,) * 4, mode="reflect").contiguous(memory_format=_layout(x)), pad

    def dense(self, x: torch.Tensor, whiten: bool, pad: int | None) -> Features:
        """Dense maps of the normalised burst ``x`` (1, 3N, H, W) at its resolution (see
        :meth:`lburst.LBurst.dense`)."""
        h, w = x.shape[-2:]
        xp, pad = self.reflect(x, pad)
        inside = (..., slice(pad, pad + h), slice(pad, pad + w))  # the burst's pixels in the padded maps
        rep, rel, half = self.backend.run(xp)
        stride = descriptor_stride(half.shape[-1], xp.shape[-1])
        desc = F.interpolate(half, scale_factor=float(stride), mode="bilinear", align_corners=False)
        desc = F.normalize(desc[inside], dim=1)
        rep, rel = rep[inside], rel[inside]
        if whiten:
            desc = self.whitening(desc, dim=1)
        desc = F.pad(desc, (0, w - desc.shape[-1], 0, h - desc.shape[-2]), mode="replicate")
        return {
            "descriptors": desc[0].permute(1, 2, 0).float().cpu().numpy(),
            "repeatability": rep[0, 0].float().cpu().numpy(),
            "reliability": rel[0, 0].float().cpu().numpy(),
        }

    def detect(
        self, x: torch.Tensor, cfg: MultiScaleConfig, full_size: tuple[int, int] | None = None, start: float = 1.0
    ) -> Features | list[Features]:
        """Multi-scale features of the normalised bursts ``x`` (B, 3N, h, w): one features dict
        when B is 1 (what :meth:`lburst.LBurst.extract` returns), else a list of B.  ``x`` is the bursts at
        scale ``start`` of their ``full_size`` (H, W) (default: ``x`` is at full size)."""
        height, width = full_size or x.shape[-2:]
        if min(height, width) < MIN_SIDE:
            raise LBurstValueError(
                f"a {width}x{height} image is too small for features (at least {MIN_SIDE} px a side)"
            )
        if cfg.fast and self.backend.channels_last(cfg.precision):  # channels-last once: each level is resized in it
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
        xp, pad = self.reflect(x, cfg.pad)
        out = None if cfg.fast else self.backend.plain(xp)  # the plain network, where there is one
        if out is None:
            rep, rel, half = self.backend.run(xp, cfg.precision)
            stride = descriptor_stride(half.shape[-1], xp.shape[-1])
        else:
            rep, rel = out["repeatability"], out["reliability"]
        for b in range(x.shape[0]):
            y, xx = _local_maxima(rep[b : b + 1], rel[b : b + 1], cfg, pad)
            score = rep[b, 0, y, xx] * rel[b, 0, y, xx]
            keep = score >= _kth_best([score] + [level[3] for level in found[b]], cfg.top_k)
            y, xx, score = y[keep], xx[keep], score[keep]
            if out is None:
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
            "descriptors": (self.whitening(descs[order], dim=1) if cfg.whiten else descs[order]).float().cpu().numpy(),
        }
