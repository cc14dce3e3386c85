"""Learned extractors: LBurst networks (any number of frames) and single-image R2D2."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from lburst.extract import LBurst, MultiScaleConfig
from lburst.features import Features
from lburst.methods import register
from lburst.methods.options import as_bool
from lburst.model import autocast_dtype

DEFAULT_WEIGHTS = {"lburst": "lburst-b5", "r2d2": "lburst-b1"}


def weights_file(spec: str) -> Path | None:
    """The checkpoint file that a method spec loads (``None`` when it loads none).

    ``lburst[:CKPT]`` and ``r2d2[:CKPT]``, also behind ``merge+``; without ``CKPT`` the
    shipped weights.  Caches of results key on this file's content, so that a
    checkpoint retrained in place (or new shipped weights) is not served stale results.
    """
    from lburst.methods import parse_spec
    from lburst.weights import weights_path

    while spec.startswith("merge+"):
        spec = spec[len("merge+"):]
    name, arg, _ = parse_spec(spec)
    if name not in DEFAULT_WEIGHTS:
        return None
    return Path(arg) if arg else weights_path(DEFAULT_WEIGHTS[name])


def results_key(spec: str) -> str:
    """``spec``, plus ``@`` and 12 hex digits of the SHA-1 of the weights it loads, if any
    (the name under which benchmarks cache its results)."""
    from lburst.io import file_sha1

    path = weights_file(spec)
    return f"{spec}@{file_sha1(path)[:12]}" if path is not None and path.is_file() else spec


class LearnedExtractor:
    """Wraps :class:`lburst.LBurst` in the extractor interface."""

    def __init__(self, model: LBurst, top_k: int = 4000, **options) -> None:
        self.model = model
        self.top_k = top_k
        self.options = options
        replace(MultiScaleConfig(), top_k=top_k, **options)  # ValueError now for a bad option, not per burst
        self.name = "lburst"

    def __call__(self, burst: np.ndarray) -> Features:
        return self.model.extract(burst, top_k=self.top_k, **self.options)


def _precision(value: str) -> str:
    autocast_dtype(value)  # a clear error for an unknown precision
    return value


def _make(arg: str | None, default: str, device=None, frame_order: str = "temporal", top_k="4000", **options):
    model = (
        LBurst.from_checkpoint(arg, device=device, frame_order=frame_order)
        if arg
        else LBurst.pretrained(default, device=device)
    )
    conv = {"min_size": int, "max_size": int, "scale_factor": float, "rel_thr": float, "rep_thr": float,
            "published_coordinates": as_bool, "fast": as_bool, "precision": _precision}
    unknown = set(options) - set(conv)
    if unknown:
        raise ValueError(f"unknown options {sorted(unknown)} for a learned method; known: {sorted(conv)}")
    top = None if str(top_k).lower() == "none" else int(top_k)
    return LearnedExtractor(model, top, **{k: conv[k](v) for k, v in options.items()})


@register("lburst")
def lburst(arg: str | None = None, **options) -> LearnedExtractor:
    """A burst network: the shipped ``lburst-b5`` or the checkpoint at ``arg``."""
    return _make(arg, DEFAULT_WEIGHTS["lburst"], **options)


@register("r2d2")
def r2d2(arg: str | None = None, **options) -> LearnedExtractor:
    """A single-image network on the common frame: the shipped ``lburst-b1`` or the checkpoint ``arg``."""
    return _make(arg, DEFAULT_WEIGHTS["r2d2"], **options)
