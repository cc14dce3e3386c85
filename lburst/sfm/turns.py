"""Views turned against the views they are matched with, told by the positions of the images.

A drone's or a robot's camera turns with the platform: the neighbouring lines of a survey are
flown in opposite directions, and their views see the ground turned by 180 degrees, where
upright features do not match (docs/results/rotations.md).  :func:`headings` takes each image's
direction of travel from the positions of the images before and after it in the scene's order
(spanning at least twice ``baseline`` metres, so that a receiver's noise does not turn it), and
:func:`turned_pairs` the planned pairs whose two headings differ by more than
:data:`TURN_DEG` (:func:`find_turns`), where the images' order is a path (:func:`is_path`;
a photo set in any order has no heading).  A reconstruction then extracts with rotation sets
(:data:`TURN_ROTATIONS`: upright and turned by 180 degrees, :meth:`lburst.LBurst.extract`)
where the method takes them and its spec does not set them (``rotations=1`` in the spec keeps
upright features), and says so (:func:`switch_on`, :func:`describe_turns`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

#: pairs whose headings differ by more than this (degrees) are turned against each other
TURN_DEG = 90.0
#: the rotation sets switched on for turned pairs: upright and turned by 180 degrees
TURN_ROTATIONS = 2
#: the shortest baseline of a heading, in standard deviations of the positions (4 x 2 m: a heading
#: of a consumer receiver's positions within about 10 degrees)
BASELINE_STDS = 4.0
#: fewest turned pairs, as a share of the pairs, that switch the rotation sets on (a receiver's noise
#: can still turn a heading now and then; a survey's lines or a path flown back turn a large share)
MIN_TURNED_SHARE = 0.01
#: the images' order is a path when consecutive images lie at most this many times the distance
#: of an image's nearest one apart (median over the images); else a heading means nothing
PATH_FACTOR = 3.0


def is_path(centres: np.ndarray) -> bool:
    """Whether the images with a position (rows of ``centres`` (N, 3) without NaN), in their order,
    make a path: consecutive ones about as near as nearest ones (:data:`PATH_FACTOR`), not a photo
    set in any order."""
    xyz = np.asarray(centres, np.float64)
    xyz = xyz[~np.isnan(xyz).any(axis=1)]
    if len(xyz) < 3:
        return len(xyz) == 2
    step = float(np.median(np.linalg.norm(np.diff(xyz, axis=0), axis=1)))
    nearest = float(np.median(cKDTree(xyz).query(xyz, k=2)[0][:, 1]))
    return step <= PATH_FACTOR * nearest


def headings(centres: np.ndarray, baseline: float) -> np.ndarray:
    """(N,) direction of travel of each image in degrees (counter-clockwise from the first axis,
    in the horizontal plane of ``centres`` (N, 3)): from the image ``w`` before it in order to the
    image ``w`` after it (among those with a position; fewer at the ends), with the smallest ``w``
    that puts them ``2 * baseline`` metres apart, so that one noisy position turns no heading; NaN
    for an image without a position, or where no two images lie that far apart."""
    xy = np.asarray(centres, np.float64)[:, :2]
    known = np.flatnonzero(~np.isnan(xy).any(axis=1))
    out = np.full(len(xy), np.nan)
    last = len(known) - 1
    for a, i in enumerate(known):
        for w in range(1, last + 1):
            before, after = xy[known[max(a - w, 0)]], xy[known[min(a + w, last)]]
            d = after - before
            if np.hypot(*d) >= 2 * baseline:
                out[i] = np.degrees(np.arctan2(d[1], d[0]))
                break
            if a - w <= 0 and a + w >= last:
                break
    return out


def turn_between(a: float, b: float) -> float:
    """The angle between headings ``a`` and ``b`` (degrees), 0 to 180."""
    return float(abs((a - b + 180.0) % 360.0 - 180.0))


def turned_pairs(heading: np.ndarray, pairs: list[tuple[int, int]], limit: float = TURN_DEG) -> list[tuple[int, int]]:
    """The ``pairs`` whose two images' ``heading`` differ by more than ``limit`` degrees (pairs with
    an unknown heading are not)."""
    return [
        (i, j)
        for i, j in pairs
        if np.isfinite(heading[i]) and np.isfinite(heading[j]) and turn_between(heading[i], heading[j]) > limit
    ]


def find_turns(centres: np.ndarray, pairs: list[tuple[int, int]], std: float) -> dict | None:
    """What the positions ``centres`` (N, 3) say of ``pairs``: how many join views turned by
    more than :data:`TURN_DEG` (headings over :data:`BASELINE_STDS` x ``std`` m), of how many;
    ``None`` when fewer than :data:`MIN_TURNED_SHARE` of them are, or when the images' order is no
    path (:func:`is_path`)."""
    if not is_path(centres):
        return None
    turned = turned_pairs(headings(centres, BASELINE_STDS * std), pairs)
    if not turned or len(turned) < MIN_TURNED_SHARE * len(pairs):
        return None
    return {"turned_pairs": len(turned), "of": len(pairs), "limit_deg": TURN_DEG, "rotations": None}


def switch_on(found: dict, spec: str, rotated: bool, has_sets: bool) -> dict:
    """``found`` (:func:`find_turns`) with what was done: ``rotations`` :data:`TURN_ROTATIONS` where
    the method of ``spec`` was given them (``rotated``), else a note why not (it has no rotation
    sets, or its spec sets its own)."""
    if rotated:
        return {**found, "rotations": TURN_ROTATIONS}
    why = "has no rotation sets" if not has_sets else "sets its own rotations"
    return {**found, "note": f"{spec} {why}"}


def describe_turns(found: dict) -> str:
    """One line that says what :func:`rotation_sets` found and did."""
    what = f"{found['turned_pairs']} of {found['of']} pairs join views turned by over {found['limit_deg']:g} degrees"
    if found.get("rotations"):
        return f"{what}: rotation sets on (rotations={found['rotations']}; rotations=1 in --method keeps them upright)"
    return f"{what}; {found.get('note', 'upright features')}"
