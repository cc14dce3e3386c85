"""Matchers: a registry of ways to match the features of two images, chosen by name.

A matcher is called as ``matcher(features_a, features_b)`` with two features dicts
(:mod:`lburst.features`; it may read keypoints and scores as well as descriptors, as a
learned matcher would) and returns indices ``(M, 2)`` int64 of matched keypoint pairs
``(i, j)``: keypoint ``i`` of ``a`` with keypoint ``j`` of ``b``. Float descriptors are
compared by L2 distance, packed binary ones (uint8) by Hamming distance.

Matchers are created from a spec ``NAME[,KEY=VALUE...]`` whose options are checked
against the matcher's options dataclass (:func:`lburst.methods.options.parse_options`):

- ``mnn``: mutual nearest neighbours (the paper's protocol; the default everywhere),
  option ``max_distance``;
- ``ratio``: Lowe's ratio test, nearest over second-nearest distance at most
  ``ratio`` (default 0.8), kept only when mutual unless ``mutual=false``; these are
  kornia's ``match_smnn`` and ``match_snn``.

Features extracted at several rotations (``rotations`` (K,): the degrees by which the
burst that each keypoint was found in was turned, :meth:`lburst.LBurst.extract`) are matched set
against set: the upright set of ``a`` against each set of ``b`` (or each set of ``a``
against ``b`` when only ``a`` has them), keeping the pair of sets with the most matches;
the indices still refer to the whole features.  So two views turned by 90 or 180 degrees
against each other match as two upright ones do.

A learned matcher registers the same way (:func:`register` with its options class) and
receives the whole features dicts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from lburst.features import Features
from lburst.methods.options import describe_options, parse_options

DEFAULT = "mnn"


class Matcher(Protocol):
    name: str

    def __call__(self, a: Features, b: Features) -> np.ndarray: ...


@dataclass(frozen=True)
class MatcherInfo:
    name: str
    factory: Callable[..., Matcher]  # factory(options) -> Matcher
    options: type | None
    summary: str


_MATCHERS: dict[str, MatcherInfo] = {}


def register(name: str, options: type | None = None) -> Callable:
    """Decorator: register ``factory(options) -> Matcher`` as ``name`` with its options dataclass."""

    def wrap(factory: Callable[..., Matcher]) -> Callable[..., Matcher]:
        summary = (factory.__doc__ or "").strip().splitlines()[0] if factory.__doc__ else ""
        _MATCHERS[name] = MatcherInfo(name, factory, options, summary)
        return factory

    return wrap


def available() -> list[MatcherInfo]:
    """Every registered matcher, by name."""
    return [_MATCHERS[n] for n in sorted(_MATCHERS)]


def create(spec: str = DEFAULT) -> Matcher:
    """The matcher of ``spec`` (``NAME[,KEY=VALUE...]``)."""
    if not isinstance(spec, str):
        raise ValueError(f"a matcher spec is a string such as 'mnn' or 'ratio,ratio=0.8', got {spec!r}")
    name, *pairs = spec.split(",")
    name = name.strip()
    if name not in _MATCHERS:
        raise ValueError(
            f"unknown matcher {name!r}; available: "
            + "; ".join(f"{m.name} ({describe_options(m.options)})" for m in available())
        )
    given = {}
    for pair in pairs:
        key, eq, value = pair.partition("=")
        if not eq or not key.strip():
            raise ValueError(f"bad option {pair!r} in matcher spec {spec!r}: expected KEY=VALUE")
        if key.strip() in given:
            raise ValueError(f"option {key.strip()!r} given twice in matcher spec {spec!r}")
        given[key.strip()] = value.strip()
    info = _MATCHERS[name]
    matcher = info.factory(parse_options(info.options, given, name, kind="matcher"))
    matcher.name = spec
    return matcher


def by_rotation(match: Callable[[np.ndarray, np.ndarray], np.ndarray], a: Features, b: Features) -> np.ndarray:
    """``match(descriptors_a, descriptors_b)`` through the rotation sets of ``a`` and ``b``
    (see the module docstring); without them, ``match`` of all descriptors.  The pair of
    sets is the one with the most distinctive mutual matches (:func:`distinctive_matches`),
    which, unlike a plain count, does not favour the set with more keypoints."""
    ra, rb = a.get("rotations"), b.get("rotations")
    if ra is None and rb is None:
        return match(a["descriptors"], b["descriptors"])
    everything_a, everything_b = np.arange(len(a["descriptors"])), np.arange(len(b["descriptors"]))
    if rb is not None:
        fixed = np.flatnonzero(ra == ra.min()) if ra is not None and len(ra) else everything_a
        pairs = [(fixed, np.flatnonzero(rb == turn)) for turn in np.unique(rb)]
    else:
        pairs = [(np.flatnonzero(ra == turn), everything_b) for turn in np.unique(ra)]
    if not pairs:
        return np.zeros((0, 2), np.int64)
    ia, ib = max(pairs, key=lambda p: distinctive_matches(a["descriptors"][p[0]], b["descriptors"][p[1]]))
    found = match(a["descriptors"][ia], b["descriptors"][ib])
    return np.stack([ia[found[:, 0]], ib[found[:, 1]]], 1).astype(np.int64).reshape(-1, 2)


def distinctive_matches(da: np.ndarray, db: np.ndarray, ratio: float = 0.9) -> int:
    """Mutual nearest neighbours whose nearest distance is at most ``ratio`` times the
    second nearest: how much two descriptor sets agree."""
    import torch

    from lburst.match import _distances, check_descriptors

    check_descriptors(da, db)
    if len(da) < 2 or len(db) < 2:
        return 0
    ta, tb = _tensors(da, db, "cpu")
    dist = _distances(ta, tb, da.dtype == np.uint8).clamp_min(0)
    values, index = torch.topk(dist, 2, dim=1, largest=False)
    mutual = dist.argmin(0)[index[:, 0]] == torch.arange(len(ta))
    return int((mutual & (values[:, 0] <= ratio * values[:, 1])).sum())


def _tensors(a: np.ndarray, b: np.ndarray, device: str):
    import torch

    if a.dtype != b.dtype:
        raise ValueError(f"descriptor types differ: {a.dtype} vs {b.dtype}")
    return (torch.from_numpy(np.ascontiguousarray(a)).to(device), torch.from_numpy(np.ascontiguousarray(b)).to(device))


@dataclass(frozen=True)
class MNNOptions:
    """``max_distance``: drop pairs farther apart (L2, or Hamming bits); ``device``: where to compute."""

    max_distance: float | None = None
    device: str = "cpu"


class MutualNearestNeighbours:
    def __init__(self, options: MNNOptions) -> None:
        self.options = options
        self.name = "mnn"

    def __call__(self, a: Features, b: Features) -> np.ndarray:
        from lburst.match import mutual_nearest_neighbours

        def match(da: np.ndarray, db: np.ndarray) -> np.ndarray:
            return mutual_nearest_neighbours(da, db, self.options.max_distance, self.options.device)

        return by_rotation(match, a, b)


@register("mnn", MNNOptions)
def mnn(options: MNNOptions) -> MutualNearestNeighbours:
    """Mutual nearest neighbours: j is i's nearest in b and i is j's nearest in a."""
    return MutualNearestNeighbours(options)


@dataclass(frozen=True)
class RatioOptions:
    """``ratio``: largest nearest / second-nearest distance; ``mutual``: also require mutual nearest."""

    ratio: float = 0.8
    mutual: bool = True
    device: str = "cpu"

    def __post_init__(self) -> None:
        if not 0 < self.ratio <= 1:
            raise ValueError(f"ratio must be in (0, 1], got {self.ratio}")


class RatioTest:
    def __init__(self, options: RatioOptions) -> None:
        self.options = options
        self.name = "ratio"

    def __call__(self, a: Features, b: Features) -> np.ndarray:
        return by_rotation(self._match, a, b)

    def _match(self, da: np.ndarray, db: np.ndarray) -> np.ndarray:
        import torch

        from lburst.match import _distances, check_descriptors

        check_descriptors(da, db)
        if len(da) == 0 or len(db) == 0:
            return np.zeros((0, 2), np.int64)
        ta, tb = _tensors(da, db, self.options.device)
        dist = _distances(ta, tb, da.dtype == np.uint8).clamp_min(0)
        ia = torch.arange(len(ta), device=dist.device)
        if dist.shape[1] < 2:  # no second neighbour: nearest neighbours only
            nn_ab = dist.argmin(1)
            keep = torch.ones_like(ia, dtype=torch.bool)
        else:
            values, index = torch.topk(dist, 2, dim=1, largest=False)
            nn_ab = index[:, 0]
            keep = values[:, 0] <= self.options.ratio * values[:, 1]
            keep &= values[:, 1] > 0  # two identical nearest distances of 0: ambiguous
        if self.options.mutual:
            keep &= dist.argmin(0)[nn_ab] == ia
        return torch.stack([ia[keep], nn_ab[keep]], 1).cpu().numpy()


@register("ratio", RatioOptions)
def ratio(options: RatioOptions) -> RatioTest:
    """Lowe's ratio test on descriptor distances (mutual by default)."""
    return RatioTest(options)
