"""A model mapped with position priors, put in their frame where COLMAP's mapper left it elsewhere.

COLMAP's incremental mapper with ``use_prior_position`` aligns the model to the priors (a
robust similarity) and then holds each camera near its prior in bundle adjustment.  When
its robust alignment finds no inliers, for instance because the priors' standard deviation
(``--position-std``) is far below their real error, it keeps its own frame without a word:
0.5 m of receiver noise with a standard deviation of 0.01 m left the cameras 43 m from
their priors.  :func:`align_to_priors` measures how far the registered cameras lie from their
priors and, where a least-squares similarity (:func:`lburst.sfm.poses.umeyama`) brings them
to less than half that distance, applies it to the model (poses and points), so that a
model made with priors always comes out in their frame.  It runs in the COLMAP child
process (:func:`lburst.sfm.colmap.run_job`) before the model is written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lburst.extras import pycolmap
from lburst.sfm.poses import umeyama

#: fewest registered images with a prior for a similarity to the priors
MIN_IMAGES = 3


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def align_to_priors(rec, names: list[str], positions: list[list[float] | None]) -> dict | None:
    """Put ``rec`` (a ``pycolmap.Reconstruction``) in the frame of ``positions`` (the prior
    centre of each image ``names[i]``, or ``None``) where a similarity fits them better than
    the mapper did (module docstring); returns ``{"before": m, "after": m, "applied": bool}``
    (RMS distances of the registered cameras to their priors), ``None`` with fewer than
    :data:`MIN_IMAGES` registered images with a prior."""
    prior = {name: np.asarray(p, float) for name, p in zip(names, positions) if p is not None}
    model, target = [], []
    for image_id in rec.reg_image_ids():
        image = rec.images[image_id]
        name = Path(image.name).stem
        if name in prior:
            model.append(np.asarray(image.projection_center()))
            target.append(prior[name])
    if len(model) < MIN_IMAGES:
        return None
    model, target = np.array(model), np.array(target)
    before = _rms(model, target)
    try:
        sim = umeyama(model, target)
    except ValueError:  # the cameras coincide
        return {"before": before, "after": before, "applied": False}
    after = _rms(sim.apply(model), target)
    applied = after < 0.5 * before
    if applied:
        rotation = pycolmap.Rotation3d(sim.rotation)
        rec.transform(pycolmap.Sim3d(sim.scale, rotation, np.asarray(sim.translation, float)))
    return {"before": before, "after": after if applied else before, "applied": applied}
