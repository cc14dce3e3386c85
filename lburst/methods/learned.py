"""Learned extractors: LBurst networks (any number of frames) and single-image R2D2."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np

from lburst.calibration import training_calibration
from lburst.errors import LBurstValueError
from lburst.features import Features, concatenate, select, spread_top_k
from lburst.methods import register
from lburst.model.extractor import ROTATIONS, LBurst, MultiScaleConfig
from lburst.model.network import autocast_dtype
from lburst.model.runtimes import RUNTIMES
from lburst.weights import resolve_weights, weights_path

DEFAULT_WEIGHTS = {"lburst": "lburst-b5", "lburst-lite": "lburst-b5-lite", "r2d2": "lburst-b1"}


@dataclass(frozen=True)
class LearnedOptions:
    """Options of a learned method: loading (``frame_order``, ``device``, ``runtime``: one of
    :data:`lburst.model.runtimes.RUNTIMES` or ``auto``, by default ``auto`` for the light
    network and ``torch`` for the others, see :meth:`lburst.LBurst.from_checkpoint`), how many
    keypoints (``top_k``; ``none``: all), ``spread`` (N > 0: the top-k spread over an N x N
    grid, :func:`lburst.features.spread_top_k`), ``rotations`` (1, 2 or 4: also extract from the burst
    turned by 180 degrees or by every quarter turn, so that views rotated against each other
    match; see :meth:`lburst.LBurst.extract`) and the :class:`lburst.model.extractor.MultiScaleConfig`
    fields below (the paper's defaults)."""

    top_k: int | None = 4000
    frame_order: Literal["temporal", "published"] = "temporal"
    device: str | None = None
    runtime: str | None = None
    min_size: int = MultiScaleConfig.min_size
    max_size: int = MultiScaleConfig.max_size
    scale_factor: float = MultiScaleConfig.scale_factor
    max_scale: float = MultiScaleConfig.max_scale
    rel_thr: float = MultiScaleConfig.rel_thr
    rep_thr: float = MultiScaleConfig.rep_thr
    published_coordinates: bool = MultiScaleConfig.published_coordinates
    fast: bool = MultiScaleConfig.fast
    precision: str = MultiScaleConfig.precision
    whiten: bool = MultiScaleConfig.whiten
    pad: int | None = MultiScaleConfig.pad
    subpixel: bool = MultiScaleConfig.subpixel
    warp: str = MultiScaleConfig.warp
    rotations: int = 1
    spread: int = 0

    def __post_init__(self) -> None:
        autocast_dtype(self.precision)  # a clear error for an unknown precision
        if self.top_k is not None and (
            isinstance(self.top_k, bool) or not isinstance(self.top_k, int) or self.top_k < 1
        ):
            raise LBurstValueError(f"top_k must be an integer >= 1 (none: every keypoint), got {self.top_k!r}")
        if isinstance(self.spread, bool) or not isinstance(self.spread, int) or not 0 <= self.spread <= 64:
            raise LBurstValueError(
                f"spread must be an integer 0-64 (cells per side; 0: plain top-k), got {self.spread!r}"
            )
        if self.rotations not in ROTATIONS:
            raise LBurstValueError(
                f"rotations must be one of {', '.join(map(str, ROTATIONS))} (views turned by 0; 0 and 180; "
                f"every 90; every 45 degrees), got {self.rotations!r}"
            )
        if self.runtime is not None and self.runtime != "auto" and self.runtime not in RUNTIMES:
            raise LBurstValueError(f"unknown runtime {self.runtime!r}: use auto or one of {', '.join(RUNTIMES)}")

    def multiscale(self) -> dict:
        """The :class:`MultiScaleConfig` fields, for :meth:`LBurst.extract`."""
        return {
            name: getattr(self, name)
            for name in (
                "min_size",
                "max_size",
                "scale_factor",
                "max_scale",
                "rel_thr",
                "rep_thr",
                "published_coordinates",
                "fast",
                "precision",
                "whiten",
                "pad",
                "subpixel",
                "warp",
            )
        }


class LearnedExtractor:
    """Wraps :class:`lburst.LBurst` in the extractor interface."""

    def __init__(self, model: LBurst, top_k: int | None = 4000, rotations: int = 1, spread: int = 0, **options) -> None:
        self.model = model
        self.top_k = top_k
        self.rotations = rotations
        self.spread = spread
        self.options = options
        cfg = replace(MultiScaleConfig(), top_k=top_k, **options)  # ValueError now for a bad option, not per burst
        if cfg.whiten:
            model.check_whitening()
        self.name = "lburst"

    def __call__(self, burst: np.ndarray) -> Features:
        if not self.spread or self.top_k is None:
            return self.model.extract(burst, top_k=self.top_k, rotations=self.rotations, **self.options)

        every = self.model.extract(burst, top_k=None, rotations=self.rotations, **self.options)
        size = (burst.shape[2], burst.shape[1])
        if "rotations" not in every:
            return spread_top_k(every, self.top_k, size, self.spread)
        sets = [
            spread_top_k(select(every, every["rotations"] == turn), self.top_k, size, self.spread)
            for turn in np.unique(every["rotations"])
        ]
        return concatenate(sets)


def _make(arg: str | None, default: str, options: LearnedOptions) -> LearnedExtractor:
    model = (
        LBurst.from_checkpoint(
            resolve_weights(arg),
            device=options.device,
            frame_order=options.frame_order,
            runtime=options.runtime,
            calibration=training_calibration,
        )
        if arg
        else LBurst.pretrained(
            default, device=options.device, runtime=options.runtime, calibration=training_calibration
        )
    )
    return LearnedExtractor(model, options.top_k, options.rotations, options.spread, **options.multiscale())


def _weights(default: str):
    def weights(arg: str | None) -> Path:
        return resolve_weights(arg) if arg else weights_path(default)

    return weights


@register("lburst", LearnedOptions, arg="checkpoint", weights=_weights(DEFAULT_WEIGHTS["lburst"]))
def lburst(arg: str | None, options: LearnedOptions) -> LearnedExtractor:
    """A burst network: the shipped lburst-b5, or the checkpoint ARG (a file or a shipped name)."""
    return _make(arg, DEFAULT_WEIGHTS["lburst"], options)


@register("lburst-lite", LearnedOptions, arg="checkpoint", weights=_weights(DEFAULT_WEIGHTS["lburst-lite"]))
def lburst_lite(arg: str | None, options: LearnedOptions) -> LearnedExtractor:
    """The light burst network: the shipped lburst-b5-lite (about 10x faster), or the checkpoint ARG."""
    return _make(arg, DEFAULT_WEIGHTS["lburst-lite"], options)


@register("r2d2", LearnedOptions, arg="checkpoint", weights=_weights(DEFAULT_WEIGHTS["r2d2"]))
def r2d2(arg: str | None, options: LearnedOptions) -> LearnedExtractor:
    """A single-image network on the common frame: the shipped lburst-b1, or the checkpoint ARG."""
    return _make(arg, DEFAULT_WEIGHTS["r2d2"], options)
