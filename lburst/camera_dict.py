"""A camera as lburst passes it to COLMAP: a dict of ``model`` (a COLMAP camera model name),
``width`` and ``height`` (pixels) and ``params`` (that model's parameters, in COLMAP's order),
as ``reference.json`` and a recording's ``meta.json`` hold it.  :func:`check_camera` checks one
before COLMAP sees it (COLMAP aborts the process on some); it needs pycolmap for the models'
parameter counts, and checks the rest without it.
"""

from __future__ import annotations

import numpy as np

from lburst.errors import LBurstValueError
from lburst.extras import MissingExtra, pycolmap  # imported on first use, after cv2 (see lburst.sfm.colmap)


def check_camera(camera: dict) -> None:
    """``ValueError`` for a camera dict COLMAP would abort on: unknown model, bad size, or a
    parameter count other than the model's; :class:`lburst.extras.MissingExtra` where pycolmap,
    which knows the models, is not installed (after the checks that need no model)."""
    try:
        model, width, height, params = camera["model"], camera["width"], camera["height"], camera["params"]
    except (KeyError, TypeError) as err:
        raise LBurstValueError(f"a camera needs model, width, height and params (lacks {err})") from None
    if not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in (width, height)):
        raise LBurstValueError(f"width and height must be positive integers, got {width!r} x {height!r}")
    values = np.asarray(params, dtype=object)
    if values.ndim != 1 or not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in values
    ):
        raise LBurstValueError(f"params must be a list of finite numbers, got {params!r}")
    try:
        expected = len(pycolmap.Camera.create_from_model_name(0, str(model), 1.0, width, height).params)
    except MissingExtra:
        raise  # no pycolmap: the extra to install, not an unknown model
    except Exception:
        raise LBurstValueError(f"unknown camera model {model!r}") from None
    if len(values) != expected:
        raise LBurstValueError(f"{model} takes {expected} params, got {len(values)}")
    if values[0] <= 0:
        raise LBurstValueError(f"the focal length must be positive, got {values[0]}")
