"""Listing a scene folder: its bursts (or single images) in trajectory order, and its reference.

A scene folder holds one sub-folder per burst, ``SCENE/<burst>/frame_000.png ...``, or
single images ``SCENE/<name>.png|jpg|...``, named so that natural sort order
(``2`` before ``10``) is trajectory order, and optionally ``SCENE/reference.json``
(:class:`lburst.sfm.reference.Reference`).  An item's *name* is the sub-folder name
or the image file's stem; it names the image in COLMAP and in ``reference.json``.

``reference.json`` may carry, beside its one ``camera``, a ``cameras`` object mapping
image names to COLMAP camera dicts, for scenes whose images come from different cameras;
:func:`reference_cameras` reads either form.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lburst.burst.io import IMAGE_SUFFIXES, BurstError, atomic_path, load_burst, natural_key
from lburst.burst.io import read_image as read_rgb
from lburst.errors import LBurstValueError
from lburst.sfm.reference import Reference

REFERENCE_FILE = "reference.json"


class SceneError(LBurstValueError):
    """A scene folder (or one of its items) that cannot be used; the message names it."""


@dataclass(frozen=True)
class SceneItem:
    """One burst folder (``kind='burst'``) or single image (``kind='image'``) of a scene."""

    name: str
    path: Path
    kind: str


@dataclass(frozen=True)
class Scene:
    """The items of a scene in trajectory order, its optional reference file, and the camera
    of a recording's ``meta.json`` or bag (a COLMAP camera dict used as the intrinsics prior),
    if any, with where it came from (``camera_source``, as the report says it)."""

    root: Path
    items: tuple[SceneItem, ...]
    reference_path: Path | None
    camera: dict | None = None
    camera_source: str = "meta.json"

    @property
    def names(self) -> list[str]:
        return [item.name for item in self.items]

    def reference(self) -> Reference | None:
        """The scene's reference cameras, or ``None`` when it has no ``reference.json``."""
        return None if self.reference_path is None else Reference.load(self.reference_path)


def _has_frames(folder: Path) -> bool:
    return any(p.suffix.lower() in IMAGE_SUFFIXES for p in folder.iterdir() if p.is_file())


def list_scene(root: str | Path) -> Scene:
    """The bursts and single images of ``root`` in natural order; ``SceneError`` if there are none.

    Hidden entries and sub-folders without image files are ignored; a name used by both
    a burst folder and an image file is an error.
    """
    root = Path(root)
    if not root.is_dir():
        raise SceneError(f"{root}: not a folder")
    items: dict[str, SceneItem] = {}
    for entry in root.iterdir():
        if entry.name.startswith("."):
            continue
        if entry.is_dir() and _has_frames(entry):
            item = SceneItem(entry.name, entry, "burst")
        elif entry.is_file() and entry.suffix.lower() in IMAGE_SUFFIXES:
            item = SceneItem(entry.stem, entry, "image")
        else:
            continue
        if item.name in items:
            raise SceneError(f"{root}: two items named {item.name!r} ({items[item.name].path.name}, {entry.name})")
        items[item.name] = item
    if not items:
        raise SceneError(f"{root}: no bursts (sub-folders of frames) or images found")
    ordered = tuple(items[name] for name in sorted(items, key=natural_key))
    reference = root / REFERENCE_FILE
    return Scene(root, ordered, reference if reference.is_file() else None)


def read_image(path: Path) -> np.ndarray:
    """An image file as RGB ``(H, W, 3)`` uint8 or uint16; ``SceneError`` naming the file if unreadable."""
    try:
        return read_rgb(path)
    except BurstError as err:
        raise SceneError(str(err)) from err


def load_item(item: SceneItem) -> np.ndarray:
    """The burst ``(N, H, W, 3)`` of an item (a single image is a 1-frame burst).

    Raises ``SceneError`` naming the file when it cannot be read.
    """
    if item.kind == "image":
        return read_image(item.path)[None]

    try:
        return load_burst(item.path)
    except BurstError as err:
        raise SceneError(str(err)) from err


def exif_source(item: SceneItem) -> Path | None:
    """The file whose EXIF may give a focal length prior: the image of a single-image item."""
    return (
        item.path if item.kind == "image" and item.path.suffix.lower() in (".jpg", ".jpeg", ".tif", ".tiff") else None
    )


def reference_cameras(path: str | Path) -> dict[str, dict]:
    """Image name -> COLMAP camera dict from ``reference.json`` (per-image ``cameras`` or the one ``camera``)."""
    data = json.loads(Path(path).read_text())
    per_image = data.get("cameras") or {}
    return {name: dict(per_image.get(name, data["camera"])) for name in data["images"]}


def save_reference(reference: Reference, path: str | Path, cameras: dict[str, dict] | None = None) -> None:
    """Write ``reference.json`` atomically, with per-image ``cameras`` when given."""
    data = reference.to_json()
    if cameras:
        data["cameras"] = {name: _camera_json(cam) for name, cam in cameras.items()}
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1))


def _camera_json(camera: dict) -> dict:
    return {
        "model": str(camera["model"]),
        "width": int(camera["width"]),
        "height": int(camera["height"]),
        "params": [float(v) for v in camera["params"]],
    }
