"""``lburst simulate scene``: a burst scene from a multi-view photo set, with reference poses.

Each photo ``PHOTOS/<name>.jpg`` becomes the burst ``SCENE/<name>/frame_000.png ...``
(:func:`lburst.simulate.simulate_burst`: in-burst motion and noise, seeded by
``stable_seed(seed, name)`` so each photo's burst is the same whatever the others are);
the middle frame keeps the photo's pixel grid, so the photo's camera is the burst's.

The reference poses are the reconstruction of the *clean* photos with SIFT through
:func:`lburst.sfm.reconstruct_scene` (files in ``SCENE/.reference/``), stored as
``SCENE/reference.json`` with source ``'sift-clean'``: poses of the registered photos,
their refined cameras in ``cameras`` (per image, exact COLMAP model), ``camera`` the
first one as a ``PINHOLE`` approximation (its distortion dropped), and ``length`` the
path length through the camera centres in scene order (model units).

``reference_options`` are :class:`lburst.sfm.ReconstructOptions` fields for that clean
reconstruction, e.g. ``single_camera=True`` and ``fix_intrinsics=True``
(``--reference-single-camera --reference-fix-intrinsics``) for a set shot with one camera
under forward motion, where bundle adjustment lets the focal length and distortion drift
and registration stops (``lund``, one phone on a forward walk, on 2 threads: 23/29
photos with one camera per photo, whose focal lengths spread from 178 to 1313 px; 6/29
with one shared refined camera; 29/29 with the shared camera kept at its EXIF focal
length).  Their non-default values are saved in
``SCENE/.reference/options.json``; a re-run reuses the reference only when they are the
same, else it reconstructs the clean photos again (the SIFT features stay cached).

``reference_seeds`` also reconstruct the clean photos under those COLMAP seeds and record
how far each lies from the reference (:mod:`lburst.scenes.reference_spread`): the precision
below which the scene's ATE cannot rank two methods.

A photo set with exact cameras in Strecha's format, a ``gt_cameras/`` folder beside the photo
folder (``SET/images/`` and ``SET/gt_cameras/``; ``SET`` itself may be given), has them as its
reference instead (:mod:`lburst.scenes.strecha`: source ``'strecha'``, calibrated, one
``PINHOLE`` camera per photo scaled to its size): no clean reconstruction is made, and
``reference_seeds`` and ``reference_options`` are not used.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lburst.burst.io import atomic_path, frame_name, save_burst
from lburst.noise import noise_from_spec
from lburst.scenes.reference_spread import drop_spread, reference_spread
from lburst.scenes.strecha import CAMERAS_DIR, cameras_folder, save_strecha_reference
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.poses import path_length
from lburst.sfm.reconstruct import reconstruct_scene
from lburst.sfm.reference import Reference
from lburst.sfm.scene import SceneError, list_scene, read_image, save_reference
from lburst.simulate import random_motion, simulate_burst, stable_seed

REFERENCE_METHOD = "sift"
REFERENCE_SOURCE = "sift-clean"
REFERENCE_DIR = ".reference"
REFERENCE_OPTIONS_FILE = "options.json"


def burst_done(folder: Path, frames: int) -> bool:
    return all((folder / frame_name(k)).is_file() for k in range(frames)) and not (folder / frame_name(frames)).exists()


def pinhole(camera: dict) -> dict:
    """A ``PINHOLE`` approximation (distortion dropped) of a COLMAP camera dict."""
    model, p = camera["model"], [float(v) for v in camera["params"]]
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL", "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE"):
        fx = fy = p[0]
        cx, cy = p[1], p[2]
    else:  # PINHOLE, OPENCV, FULL_OPENCV, ...: fx, fy, cx, cy first
        fx, fy, cx, cy = p[:4]
    return {
        "model": "PINHOLE",
        "width": int(camera["width"]),
        "height": int(camera["height"]),
        "params": [fx, fy, cx, cy],
    }


def make_reference(photos: Path, scene_dir: Path, progress: bool = True, **options) -> Reference | None:
    """Reconstruct the clean photos with SIFT and save ``scene_dir/reference.json``; ``None`` if nothing registered."""
    opts = ReconstructOptions(progress=progress, **options)
    result = reconstruct_scene(photos, REFERENCE_METHOD, scene_dir / REFERENCE_DIR, opts)
    with atomic_path(scene_dir / REFERENCE_DIR / REFERENCE_OPTIONS_FILE) as tmp:
        tmp.write_text(json.dumps(non_default_options(options), indent=1, sort_keys=True))
    if not result.registered:
        return None
    order = [n for n in result.names if n in result.poses]
    poses = {n: result.poses[n] for n in order}
    centres = np.array([-R.T @ t for R, t in poses.values()])
    reference = Reference(REFERENCE_SOURCE, pinhole(result.cameras[order[0]]), poses, path_length(centres))
    save_reference(reference, scene_dir / "reference.json", {n: result.cameras[n] for n in order})
    return reference


def non_default_options(options: dict) -> dict:
    """``options`` without the fields equal to :class:`lburst.sfm.ReconstructOptions`' defaults."""
    from dataclasses import MISSING, fields

    defaults = {f.name: f.default for f in fields(ReconstructOptions) if f.default is not MISSING}
    return {k: v for k, v in options.items() if k not in defaults or defaults[k] != v}


def reference_options_used(scene_dir: Path) -> dict:
    """The non-default options the scene's clean reference was made with (``{}`` when the file is absent)."""
    path = Path(scene_dir) / REFERENCE_DIR / REFERENCE_OPTIONS_FILE
    return json.loads(path.read_text()) if path.is_file() else {}


def photo_set(photos: str | Path) -> tuple[Path, Path | None]:
    """The photo folder of ``photos`` and its exact cameras' folder, if any (module docstring):
    ``SET`` with ``images/`` and ``gt_cameras/`` is read as ``SET/images``."""
    photos = Path(photos)
    if (photos / "images").is_dir() and (photos / CAMERAS_DIR).is_dir():
        photos = photos / "images"
    return photos, cameras_folder(photos)


def exact_reference(photos: Path, cameras: Path, scene_dir: Path) -> Reference:
    """Write ``scene_dir/reference.json`` from the Strecha camera files in ``cameras`` and return it."""
    items = [item for item in list_scene(photos).items if item.kind == "image"]
    sizes = [read_image(item.path).shape[1::-1] for item in items]
    drop_spread(scene_dir, REFERENCE_DIR)  # a spread measured a clean-SIFT reference this one replaces
    return save_strecha_reference(
        cameras, [(item.name, item.path, size) for item, size in zip(items, sizes)], scene_dir / "reference.json"
    )


def simulate_scene(
    photos: str | Path,
    out: str | Path,
    frames: int = 5,
    motion_px: float = 2.0,
    noise: str | None = "gaussian:50",
    seed: int = 0,
    reference: bool = True,
    progress: bool = True,
    reference_options: dict | None = None,
    reference_seeds: Sequence[int] = (),
) -> Reference | None:
    """Write the burst scene of ``photos`` into ``out`` (module docstring); returns the reference (or ``None``).

    Bursts already written with ``frames`` frames are kept (a re-run resumes), and so is a
    clean-SIFT reference made with the same ``reference_options``.  ``reference_seeds``: the
    reference's spread under those seeds, in ``out/.reference/spread.json`` (module docstring).
    """
    (photos, cameras), out = photo_set(photos), Path(out)
    items = [item for item in list_scene(photos).items if item.kind == "image"]
    if not items:
        raise SceneError(f"{photos}: no photos found")
    noise_model = noise_from_spec(noise) if noise and noise != "none" else None
    for item in tqdm(items, desc="bursts", disable=not progress, leave=False):
        folder = out / item.name
        if burst_done(folder, frames):
            continue
        rng = np.random.default_rng(stable_seed(seed, item.name))
        motion = random_motion(rng, motion_px)
        burst = simulate_burst(read_image(item.path), frames=frames, motion=motion, noise=noise_model, rng=rng)
        save_burst(burst, folder, whole=True)
    if not reference:
        return None
    if cameras is not None:
        return exact_reference(photos, cameras, out)
    reference_options = dict(reference_options or {})
    made = None
    if (out / "reference.json").is_file():
        existing = Reference.load(out / "reference.json")
        if existing.source == REFERENCE_SOURCE and reference_options_used(out) == non_default_options(
            reference_options
        ):
            made = existing
    if made is None:
        drop_spread(out, REFERENCE_DIR)  # reruns under other seeds belong to the reference they measured
        made = make_reference(photos, out, progress, **reference_options)  # replaces reference.json atomically
    if made is None:
        (out / "reference.json").unlink(missing_ok=True)  # one made with other options is not this reference
    elif reference_seeds:
        reference_spread(photos, out, reference_seeds, REFERENCE_METHOD, REFERENCE_DIR, reference_options, progress)
    return made
