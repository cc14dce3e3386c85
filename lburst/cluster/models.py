"""One extractor per process: on a cluster the network is loaded once per worker, not once per burst.

A task names its extractor by an :class:`ExtractorRequest`: the method (a
:class:`lburst.methods.Method`, which pickles) and the options to create it with, its key
(the store's :func:`lburst.store.method_key`: the spec with its weights' SHA-1 and options,
plus the device), and the torch threads a burst runs with.
:class:`WorkerExtractor` is the per-burst ``compute`` of
:func:`lburst.sfm.feature_stage.keyframe_features` on a cluster: it travels with each task,
and :func:`extractor_for` creates the extractor on a worker's first task with that key and
keeps it for the next ones.  A run in one process computes with its own extractor instead
(:func:`lburst.sfm.feature_stage.compute_for`), created once per run.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from lburst import store
from lburst.features import Features, check_features
from lburst.methods import Method

_LOADED: dict[str, Callable] = {}


@dataclass(frozen=True)
class ExtractorRequest:
    """The extractor a task needs (module docstring); ``threads`` ``None`` leaves torch's count."""

    method: Method
    options: tuple[tuple[str, Any], ...] = ()
    key: str = ""
    threads: int | None = None


def extractor_request(
    method: str | Method, options: dict[str, Any] | None = None, threads: int | None = None
) -> ExtractorRequest:
    """The :class:`ExtractorRequest` of ``method.create(**options)``; its key costs one read of the weights."""
    method, options = Method.of(method), dict(options or {})
    stored = store.method_key(method, **{k: v for k, v in options.items() if k != "device"})
    key = json.dumps({"method": stored, "device": options.get("device")}, sort_keys=True)
    return ExtractorRequest(method, tuple(sorted(options.items())), key, threads)


def set_threads(threads: int | None) -> None:
    """torch's thread count in this process (``None``: leave it)."""
    if threads is None:
        return
    import torch

    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)


def extractor_for(request: ExtractorRequest) -> Callable:
    """The extractor of ``request`` in this process (created on first use), with torch set to
    ``request.threads`` threads."""
    set_threads(request.threads)
    if request.key not in _LOADED:
        _LOADED[request.key] = request.method.create(**dict(request.options))
    return _LOADED[request.key]


@dataclass(frozen=True)
class WorkerExtractor:
    """``compute(burst)`` by the extractor of ``request`` in the process that runs the task, checked."""

    request: ExtractorRequest

    def __call__(self, burst: np.ndarray) -> Features:
        return check_features(extractor_for(self.request)(burst))
