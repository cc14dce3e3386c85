"""Whether a model can be trusted without ground truth: the signs of a folded model.

COLMAP can register every image into a model that is wrong: on a night survey with
``lburst,rotations=2`` all 40 bursts registered while the model stood 35 m off (11 % of
the path), its turns held 8-14 3D points per image and two of its parts were joined by
almost nothing.  A user without ground truth sees ``40/40``.  The model carries the signs,
and :func:`assess` reads them:

- **images with few 3D points**: fewer than :data:`MIN_POINTS` and under a quarter of the
  model's median image (a small scene whose every image holds few points is not flagged);
- **a weak link**: along a trajectory (a recording, or a scene paired in order), the 3D
  points that tie the images up to one registered image to those after it, fewer than
  :data:`MIN_LINK` and under a tenth of the median such link; and any model joined from
  two (:func:`lburst.sfm.join.join_models`) whose joined images share fewer than
  :data:`MIN_LINK` points with the rest;
- **a scale jump**: along a trajectory, a camera whose step from the last camera and step
  to the next differ more than :data:`MAX_STEP_RATIO` times (steps under a twentieth of the
  median step, a camera that stands still, are left out);
- **large reprojection errors**: an image whose observations reproject on average more
  than :data:`MAX_IMAGE_ERROR_PX` pixels from its keypoints;
- **cameras far from their position priors**: with priors that placed the model, a camera
  more than :data:`PRIOR_SIGMAS` standard deviations of the prior from its position.

:func:`model_measures` computes, in the COLMAP child, what :func:`assess` needs of the
model besides its summary (:func:`lburst.sfm.colmap.summarize`); :func:`assess` gives the
``checks`` of ``result.json``: ``trusted``, the ``reasons`` when not, and the ``measures``
the verdict rests on.  The thresholds leave the built-in night flight, its recordings and
the test scenes trusted; NumPy only (the COLMAP child imports it).
"""

from __future__ import annotations

import numpy as np

#: an image holds too few 3D points below this (and below a quarter of the median image)
MIN_POINTS = 30
#: a link along the trajectory, or a join, is weak below this many shared 3D points
MIN_LINK = 30
#: a step between consecutive cameras this many times the next or the last one is a jump
MAX_STEP_RATIO = 5.0
#: an image whose observations reproject further than this on average (px) does not fit
MAX_IMAGE_ERROR_PX = 2.0
#: a camera this many prior standard deviations from its position is far from it
PRIOR_SIGMAS = 5.0


def model_measures(rec, names: list[str]) -> dict:
    """What :func:`assess` needs of the pycolmap model ``rec`` (images named as ``names``,
    without suffix, in trajectory order): each registered image's mean reprojection error
    (px), and for each pair of consecutive registered images the 3D points whose tracks
    have images up to the first and images from the second on (``trajectory_links``:
    ``[first, second, points]``)."""
    order = {name: i for i, name in enumerate(names)}
    position: dict[int, int] = {}
    errors: dict[str, float] = {}
    for image_id in rec.reg_image_ids():
        image = rec.images[image_id]
        name = image.name.rsplit(".", 1)[0]
        position[image_id] = order.get(name, -1)
        seen = [p for p in image.points2D if p.has_point3D()]
        if not seen:
            continue
        xyz = np.array([rec.points3D[p.point3D_id].xyz for p in seen])
        projected = np.asarray(rec.cameras[image.camera_id].img_from_cam(image.cam_from_world() * xyz), dtype=float)
        distance = np.linalg.norm(projected - np.array([p.xy for p in seen]), axis=1)
        errors[name] = float(np.mean(np.where(np.isfinite(distance), distance, np.inf)))
    spans = np.zeros(len(names) + 1, dtype=np.int64)
    for point in rec.points3D.values():
        at = [position[e.image_id] for e in point.track.elements if position.get(e.image_id, -1) >= 0]
        if at and min(at) < max(at):
            spans[min(at)] += 1
            spans[max(at)] -= 1
    crossing = np.cumsum(spans)  # crossing[k]: points with images at k or before and after k
    registered = sorted(p for p in position.values() if p >= 0)
    links = [[names[a], names[b], int(crossing[a])] for a, b in zip(registered, registered[1:])]
    return {"image_reprojection_errors": errors, "trajectory_links": links}


def assess(
    summary: dict,
    names: list[str],
    ordered: bool,
    priors: dict[str, np.ndarray] | None = None,
    prior_std: float | None = None,
) -> dict:
    """The ``checks`` of a model (module docstring) from the COLMAP child's ``summary``
    (:func:`lburst.sfm.colmap.summarize` with :func:`model_measures` and ``joins``).
    ``names``: every image in trajectory order; ``ordered``: whether that order is a
    trajectory (a recording, or a scene paired in sequence); ``priors``: name -> position
    of the images whose positions placed the model (``None``: no priors, or they did not
    place it), with ``prior_std`` (m)."""
    registered = [n for n in names if n in summary.get("registered", {})]
    if not registered:
        return {"trusted": False, "reasons": ["no model"], "measures": {}}
    reasons: list[str] = []
    measures: dict = {}
    reasons += _few_points(summary, registered, measures)
    if ordered:
        reasons += _weak_links(summary.get("trajectory_links", []), measures)
        reasons += _scale_jumps(summary, registered, measures)
    reasons += _weak_joins(summary.get("joins", []), measures)
    reasons += _reprojection(summary.get("image_reprojection_errors", {}), measures)
    if priors and prior_std:
        reasons += _far_from_priors(summary, registered, priors, prior_std, measures)
    return {"trusted": not reasons, "reasons": reasons, "measures": measures}


def _names(items: list[tuple[str, object]], unit: str = "") -> str:
    """``0010 (8), 0011 (12)``: at most five, then how many more."""
    shown = ", ".join(f"{n} ({v:.3g}{unit})" if isinstance(v, float) else f"{n} ({v}{unit})" for n, v in items[:5])
    return shown + (f" and {len(items) - 5} more" if len(items) > 5 else "")


def _few_points(summary: dict, registered: list[str], measures: dict) -> list[str]:
    points = {n: int(summary["registered"][n].get("num_points3D", 0)) for n in registered}
    median = float(np.median(list(points.values())))
    fewest = min(points, key=points.get)
    measures.update(median_points3D=median, fewest_points3D=[fewest, points[fewest]])
    few = [(n, p) for n, p in points.items() if p < MIN_POINTS and p < median / 4]
    if not few:
        return []
    return [f"{len(few)} images hold few 3D points against the median {median:.0f}: {_names(few)}"]


def _weak_links(links: list, measures: dict) -> list[str]:
    if not links:
        return []
    counts = [count for _, _, count in links]
    median = float(np.median(counts))
    weakest = min(links, key=lambda link: link[2])
    measures.update(weakest_link=weakest, median_link=median)
    weak = [(f"{a}-{b}", count) for a, b, count in links if count < MIN_LINK and count < median / 10]
    if not weak:
        return []
    return [
        f"the model hangs on few 3D points between consecutive images ({_names(weak)}; median {median:.0f}): "
        "its parts may be folded against each other"
    ]


def _scale_jumps(summary: dict, registered: list[str], measures: dict) -> list[str]:
    if len(registered) < 3:
        return []
    centres = []
    for name in registered:
        image = summary["registered"][name]
        R, t = np.asarray(image["R"], float), np.asarray(image["t"], float)
        centres.append(-R.T @ t)
    steps = np.linalg.norm(np.diff(np.array(centres), axis=0), axis=1)
    median = float(np.median(steps))
    moving = steps > median / 20
    ratios = [
        (f"{registered[i + 1]}", float(max(steps[i], steps[i + 1]) / min(steps[i], steps[i + 1])))
        for i in range(len(steps) - 1)
        if moving[i] and moving[i + 1]
    ]
    if not ratios:
        return []
    largest = max(ratios, key=lambda item: item[1])
    measures["largest_step_ratio"] = [largest[0], round(largest[1], 3)]
    jumps = [(n, round(r, 1)) for n, r in ratios if r > MAX_STEP_RATIO]
    if not jumps:
        return []
    return [f"the steps to and from a camera differ in scale (a jump in the model's scale) at {_names(jumps, 'x')}"]


def _weak_joins(joins: list, measures: dict) -> list[str]:
    if not joins:
        return []
    measures["joins"] = joins
    weak = [join for join in joins if join["points"] < MIN_LINK]
    return [
        f"a model of {join['images']} images was joined to the rest through {join['points']} shared 3D points"
        for join in weak
    ]


def _reprojection(errors: dict[str, float], measures: dict) -> list[str]:
    if not errors:
        return []
    worst = max(errors, key=errors.get)
    measures["largest_image_reprojection_error"] = [worst, round(errors[worst], 3)]
    large = [(n, round(e, 2)) for n, e in errors.items() if e > MAX_IMAGE_ERROR_PX]
    if not large:
        return []
    return [f"{len(large)} images reproject their points far from their keypoints: {_names(large, ' px')}"]


def _far_from_priors(
    summary: dict, registered: list[str], priors: dict[str, np.ndarray], std: float, measures: dict
) -> list[str]:
    distance = {}
    for name in registered:
        if name in priors:
            image = summary["registered"][name]
            R, t = np.asarray(image["R"], float), np.asarray(image["t"], float)
            distance[name] = float(np.linalg.norm(-R.T @ t - np.asarray(priors[name], float)))
    if not distance:
        return []
    farthest = max(distance, key=distance.get)
    measures["farthest_from_prior"] = [farthest, round(distance[farthest], 3)]
    far = sorted(((n, round(d, 1)) for n, d in distance.items() if d > PRIOR_SIGMAS * std), key=lambda x: -x[1])
    if not far:
        return []
    return [
        f"{len(far)} cameras lie over {PRIOR_SIGMAS:g} times the prior's standard deviation ({std:g} m) from their "
        f"positions: {_names(far, ' m')}"
    ]


def describe_checks(checks: dict) -> str:
    """One line that says what ``checks`` (:func:`assess`) found."""
    if not checks.get("trusted"):
        return "the model may be wrong (folded): " + "; ".join(checks.get("reasons", []))
    m = checks.get("measures", {})
    parts = []
    if "fewest_points3D" in m:
        name, count = m["fewest_points3D"]
        parts.append(f"fewest 3D points in an image {count} ({name}, median {m['median_points3D']:.0f})")
    if "weakest_link" in m:
        a, b, count = m["weakest_link"]
        parts.append(f"weakest link {count} points ({a}-{b})")
    if "largest_image_reprojection_error" in m:
        parts.append(f"largest mean reprojection error {m['largest_image_reprojection_error'][1]:.2f} px")
    if "farthest_from_prior" in m:
        parts.append(f"farthest from its position {m['farthest_from_prior'][1]:.3g} m")
    return "model checks passed: " + ", ".join(parts)
