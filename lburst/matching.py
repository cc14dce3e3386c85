"""Matchers: a registry of ways to match the features of two images, chosen by name.

A matcher is called as ``matcher(features_a, features_b)`` with two features dicts
(:mod:`lburst.features`; it may read keypoints and scores as well as descriptors, as a
learned matcher would) and returns indices ``(M, 2)`` int64 of matched keypoint pairs
``(i, j)``: keypoint ``i`` of ``a`` with keypoint ``j`` of ``b``. Float descriptors are
compared by L2 distance, packed binary ones (uint8) by Hamming distance (on the CPU,
mutual nearest neighbours of binary descriptors by OpenCV's brute-force matcher with
cross-check: the same pairs, faster).  ``matcher.match(features_a, features_b)`` returns
``(matches, scores)``, ``scores`` (M,) float32 the similarity of each match's descriptors
in [-1, 1] (:func:`similarity`: the cosine, 1 - 2 x Hamming / bits for binary ones);
:func:`match_with_scores` gives them for any matcher, one that only has ``__call__`` too.

Matchers are created from a spec ``NAME[,KEY=VALUE...]`` whose options are checked
against the matcher's options dataclass (:func:`lburst.methods.options.parse_options`):

- ``mnn``: mutual nearest neighbours (the paper's protocol; the default everywhere),
  option ``max_distance``;
- ``ratio``: Lowe's ratio test from ``a`` to ``b`` only: each descriptor of ``a`` keeps its
  nearest in ``b`` when the nearest over the second-nearest distance is at most ``ratio``
  (default 0.8), and only when the two are also mutual nearest unless ``mutual=false``.  With ``mutual=false`` it is kornia's ``match_snn`` (except that a
  ``b`` of one descriptor gives its nearest neighbours, where kornia gives none); with
  ``mutual=true`` it is *not* kornia's ``match_smnn``, which also tests the ratio from
  ``b`` to ``a``: that is ``smnn``;
- ``smnn``: kornia's ``match_smnn``: mutual nearest neighbours that pass the ratio test
  (nearest over second-nearest distance at most ``ratio``, kornia's default 0.95) in
  both directions; fewer than two descriptors on either side give no matches.

Features extracted at several rotations (``rotations`` (K,): the degrees by which the
burst that each keypoint was found in was turned, :meth:`lburst.LBurst.extract`) are matched set
against set: the upright set of ``a`` against each set of ``b`` (or each set of ``a``
against ``b`` when only ``a`` has them), keeping the pair of sets with the most matches;
the pair is chosen on the strongest :data:`CHOICE_KEYPOINTS` of each set, then matched whole, and
the indices still refer to the whole features.  So two views turned by 90 or 180 degrees
against each other match as two upright ones do.

A learned matcher registers the same way (:func:`register` with its options class) and
receives the whole features dicts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Protocol

import numpy as np

from lburst.errors import LBurstValueError
from lburst.features import Features
from lburst.methods.options import describe_options, parse_options, parse_pairs

if TYPE_CHECKING:
    import torch

DEFAULT = "mnn"


class Matcher(Protocol):
    """A matcher: ``matcher(a, b)`` gives the matches (M, 2); ``matcher.match(a, b)``, where
    it has one, the matches and their scores (M,) (see the module docstring)."""

    name: str

    def __call__(self, a: Features, b: Features) -> np.ndarray: ...


def similarity(da: np.ndarray, db: np.ndarray, matches: np.ndarray) -> np.ndarray:
    """Similarity (M,) float32 in [-1, 1] of the descriptors of each match ``(i, j)``: the
    cosine of float descriptors (their dot product when L2-normalised, as LBurst's; 0 with
    a zero vector), and for packed binary ones ``1 - 2 h / bits``, ``h`` their Hamming
    distance (the cosine of their +-1 bit vectors)."""
    a, b = da[matches[:, 0]], db[matches[:, 1]]
    if da.dtype == np.uint8:
        bits = np.unpackbits(a ^ b, axis=1).sum(1)
        return (1 - 2 * bits / max(8 * da.shape[1], 1)).astype(np.float32)
    a, b = a.astype(np.float64), b.astype(np.float64)
    norms = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    dot = (a * b).sum(1)
    cosine = np.divide(dot, norms, out=np.zeros_like(dot), where=norms > 0)
    return np.clip(cosine, -1, 1).astype(np.float32)


def match_with_scores(matcher: Matcher, a: Features, b: Features) -> tuple[np.ndarray, np.ndarray]:
    """``matcher.match(a, b)``: matches (M, 2) and scores (M,); for a matcher without
    ``match``, its matches with their descriptors' :func:`similarity`."""
    if hasattr(matcher, "match"):
        return matcher.match(a, b)
    matches = matcher(a, b)
    return matches, similarity(a["descriptors"], b["descriptors"], matches)


class DescriptorMatcher:
    """A matcher of descriptors alone through the rotation sets (:func:`by_rotation`):
    a subclass gives ``_match(da, db) -> (M, 2)``; the scores are :func:`similarity`."""

    name: str

    def __call__(self, a: Features, b: Features) -> np.ndarray:
        return by_rotation(self._match, a, b)

    def match(self, a: Features, b: Features) -> tuple[np.ndarray, np.ndarray]:
        """Matches (M, 2) and the similarity (M,) of their descriptors, in [-1, 1]."""
        matches = self(a, b)
        return matches, similarity(a["descriptors"], b["descriptors"], matches)

    def _match(self, da: np.ndarray, db: np.ndarray) -> np.ndarray:
        raise NotImplementedError(f"{type(self).__name__} must define _match(da, db)")


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
        raise LBurstValueError(f"a matcher spec is a string such as 'mnn' or 'ratio,ratio=0.8', got {spec!r}")
    name, *pairs = spec.split(",")
    name = name.strip()
    if name not in _MATCHERS:
        raise LBurstValueError(
            f"unknown matcher {name!r}; available: "
            + "; ".join(f"{m.name} ({describe_options(m.options)})" for m in available())
        )
    info = _MATCHERS[name]
    matcher = info.factory(parse_options(info.options, parse_pairs(pairs, spec, "matcher"), name, kind="matcher"))
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

    def agreement(pair: tuple[np.ndarray, np.ndarray]) -> int:
        ca, cb = strongest(a, pair[0]), strongest(b, pair[1])
        return distinctive_matches(a["descriptors"][ca], b["descriptors"][cb])

    ia, ib = max(pairs, key=agreement)
    found = match(a["descriptors"][ia], b["descriptors"][ib])
    return np.stack([ia[found[:, 0]], ib[found[:, 1]]], 1).astype(np.int64).reshape(-1, 2)


#: Keypoints per set that choose the pair of rotation sets: the strongest by score.  The choice
#: costs ``sets x CHOICE_KEYPOINTS**2`` distances instead of ``sets x K**2`` (about 15 times
#: less at 4,000 keypoints per set); the chosen sets are then matched whole.
CHOICE_KEYPOINTS = 1024


def strongest(features: Features, index: np.ndarray, count: int = CHOICE_KEYPOINTS) -> np.ndarray:
    """The ``count`` entries of ``index`` with the highest ``scores`` (all of them when there
    are no more, or no scores), in their order in ``index``."""
    scores = features.get("scores")
    if len(index) <= count or scores is None:
        return index
    return index[np.sort(np.argpartition(-np.asarray(scores)[index], count - 1)[:count])]


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
        raise LBurstValueError(f"descriptor types differ: {a.dtype} vs {b.dtype}")
    return (torch.from_numpy(np.ascontiguousarray(a)).to(device), torch.from_numpy(np.ascontiguousarray(b)).to(device))


@dataclass(frozen=True)
class MNNOptions:
    """``max_distance``: drop pairs farther apart (L2, or Hamming bits); ``device``: where to compute."""

    max_distance: float | None = None
    device: str = "cpu"


class MutualNearestNeighbours(DescriptorMatcher):
    """:func:`lburst.match.mutual_nearest_neighbours` as a matcher."""

    def __init__(self, options: MNNOptions) -> None:
        self.options = options
        self.name = "mnn"

    def _match(self, da: np.ndarray, db: np.ndarray) -> np.ndarray:
        from lburst.match import mutual_nearest_neighbours

        return mutual_nearest_neighbours(da, db, self.options.max_distance, self.options.device)


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
            raise LBurstValueError(f"ratio must be in (0, 1], got {self.ratio}")


class RatioTest(DescriptorMatcher):
    """Lowe's ratio test from ``a`` to ``b``, optionally mutual (module docstring)."""

    def __init__(self, options: RatioOptions) -> None:
        self.options = options
        self.name = "ratio"

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
    """Lowe's ratio test from the first image to the second only (mutual by default; smnn tests both ways)."""
    return RatioTest(options)


@dataclass(frozen=True)
class SMNNOptions:
    """``ratio``: largest nearest / second-nearest distance, tested in both directions
    (kornia's default 0.95); ``device``: where to compute."""

    ratio: float = 0.95
    device: str = "cpu"

    def __post_init__(self) -> None:
        if not 0 < self.ratio <= 1:
            raise LBurstValueError(f"ratio must be in (0, 1], got {self.ratio}")


def _nearest_two(dist: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """For each row of ``dist``: its nearest over second-nearest distance (NaN or inf when
    the second is 0) and the index of its nearest."""
    import torch

    values, index = torch.topk(dist, 2, dim=1, largest=False)
    return values[:, 0] / values[:, 1], index[:, 0]


class SymmetricRatioTest(DescriptorMatcher):
    """kornia's ``match_smnn``: mutual nearest neighbours passing the ratio test both ways."""

    def __init__(self, options: SMNNOptions) -> None:
        self.options = options
        self.name = "smnn"

    def _match(self, da: np.ndarray, db: np.ndarray) -> np.ndarray:
        import torch

        from lburst.match import _distances, check_descriptors

        check_descriptors(da, db)
        if len(da) < 2 or len(db) < 2:  # no second neighbour on one side: no ratio, no match
            return np.zeros((0, 2), np.int64)
        ta, tb = _tensors(da, db, self.options.device)
        dist = _distances(ta, tb, da.dtype == np.uint8).clamp_min(0)
        ratio_ab, nn_ab = _nearest_two(dist)
        ratio_ba, nn_ba = _nearest_two(dist.t())
        ia = torch.arange(len(ta), device=dist.device)
        keep = (nn_ba[nn_ab] == ia) & (ratio_ab <= self.options.ratio) & (ratio_ba[nn_ab] <= self.options.ratio)
        return torch.stack([ia[keep], nn_ab[keep]], 1).cpu().numpy()


@register("smnn", SMNNOptions)
def smnn(options: SMNNOptions) -> SymmetricRatioTest:
    """kornia's match_smnn: mutual nearest neighbours passing the ratio test in both directions."""
    return SymmetricRatioTest(options)
