"""A recording's ``meta.json`` (``X.meta.json`` beside a video ``X.mp4``, ``X/meta.json`` inside a
frame folder ``X/``), checked where it is read: a JSON object with, each optional,

- ``fps``: the frame rate of a frame folder (``null``: not given), a number from :data:`MIN_FPS` to :data:`MAX_FPS`
  (the bounds of ``--fps`` too: :func:`check_fps`);
- ``camera``: a COLMAP camera dict (``model``, ``width``, ``height``, ``params``), checked as
  :func:`lburst.camera_dict.check_camera` checks a camera before COLMAP sees it (its model and
  parameter count where pycolmap is installed: without it no camera reaches COLMAP).

Other keys are kept as they are (the simulated flight writes ``kind``, ``frames`` and its
configuration).  Every problem is a :class:`lburst.burst.io.BurstError` naming the file and the field.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from lburst.burst.io import BurstError
from lburst.camera_dict import check_camera
from lburst.extras import MissingExtra
from lburst.numbers import check_real

#: frames per second: the slowest frame rate lburst takes (a frame every 2.8 hours, a time-lapse);
#: below it timestamps and keyframe names grow without bound (``1e-300`` made names too long to write)
MIN_FPS = 1e-4
#: frames per second: the fastest frame rate lburst takes
MAX_FPS = 10_000.0
#: bytes: the largest ``meta.json`` read (a few hundred bytes is usual; a flight's configuration is 2 kB)
MAX_META_BYTES = 1 << 20


def check_fps(value: Any, name: str = "--fps") -> float:
    """``value`` as a frame rate (a finite number from :data:`MIN_FPS` to :data:`MAX_FPS`);
    ``ValueError`` naming ``name`` otherwise."""
    return check_real(value, name, MIN_FPS, MAX_FPS)


def read_meta(path: str | Path) -> dict[str, Any]:
    """The checked content of the ``meta.json`` at ``path`` (module docstring); ``{}`` when there
    is no such file."""
    path = Path(path)
    if not path.is_file():
        return {}
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_META_BYTES + 1)
    except OSError as err:
        raise BurstError(f"{path}: cannot be read ({err.strerror or err})") from None
    if len(data) > MAX_META_BYTES:
        raise BurstError(f"{path}: over {MAX_META_BYTES >> 10} kB, not a recording's meta.json (fps and camera)")
    try:
        meta = json.loads(data)
    except (ValueError, RecursionError) as err:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        raise BurstError(f"{path}: not valid JSON ({err})") from None
    return check_meta(meta, path)


def check_meta(meta: Any, path: str | Path) -> dict[str, Any]:
    """``meta`` (the parsed ``meta.json`` at ``path``) after checking it (module docstring)."""
    if not isinstance(meta, dict):
        raise BurstError(
            f'{path}: must be a JSON object such as {{"fps": 30, "camera": {{...}}}}, got a {_json_type(meta)}'
        )
    if meta.get("fps") is not None:
        try:
            check_fps(meta["fps"], "fps")
        except ValueError as err:
            raise BurstError(f"{path}: {err} (frames per second)") from None
    if meta.get("camera") is not None:
        check_meta_camera(meta["camera"], path)
    return meta


def check_meta_camera(camera: Any, path: str | Path) -> None:
    """``BurstError`` naming ``path`` for a ``camera`` COLMAP would refuse or abort on."""
    if not isinstance(camera, dict):
        raise BurstError(
            f"{path}: camera must be a JSON object (a COLMAP camera: model, width, height, params), "
            f"got a {_json_type(camera)}"
        )
    try:
        check_camera(camera)
    except MissingExtra:
        return  # the model needs pycolmap to be checked, and no reconstruction runs without it
    except ValueError as err:
        raise BurstError(f"{path}: camera: {err}") from None


def _json_type(value: Any) -> str:
    names = {dict: "object", list: "list", str: "string", bool: "boolean", int: "number", float: "number"}
    return "null" if value is None else names.get(type(value), type(value).__name__)
