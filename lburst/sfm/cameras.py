"""The COLMAP cameras of a reconstruction: one per image, as COLMAP does by default (a shared
camera whose intrinsics drift in bundle adjustment, as they do under forward motion, stops
every later registration), or with ``single_camera`` one for all images when their priors
agree; by default (``None``) a recording, which one camera shot, has one camera, a scene one
per image (without a ``meta.json`` camera, one estimated camera put the simulated flight's
PNG frames at 0.201 m ATE, one per keyframe at 1.186 m: docs/recordings.md).

The prior is, by the ``camera`` option (:class:`lburst.sfm.options.Camera`): ``'auto'`` the
scene's calibration when it has one (a recording's ``meta.json`` camera, or
``reference.json`` cameras that are a calibration: see :mod:`lburst.sfm.reference`), held
fixed, else the focal length from EXIF when a single image has one, else COLMAP's default
``SIMPLE_RADIAL`` with ``f = 1.2 * max(W, H)`` and a centred principal point;
``'default'`` always the latter; ``'reference'`` the scene's ``reference.json`` cameras
(refined too unless ``fix_intrinsics``); ``'reference-focal'`` only their focal length: COLMAP's
default prior (``camera_model``, centred principal point, no distortion) at each image's
reference focal length (the mean of ``fx`` and ``fy``), refined unless ``fix_intrinsics``, as a
user with a rough calibration (a focal length from the lens) would start.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from lburst.sfm.colmap import check_camera, default_camera, exif_camera, pycolmap
from lburst.sfm.options import Camera, ReconstructOptions
from lburst.sfm.reference import Reference
from lburst.sfm.result import ReconstructionError
from lburst.sfm.scene import Scene, exif_source, reference_cameras


def check_reference(path: Path) -> dict[str, dict]:
    """The cameras of a scene's ``reference.json`` after checking the whole file (poses and
    every camera against its COLMAP model), so that a bad one fails before COLMAP runs;
    ``ReconstructionError`` naming the file and the problem."""
    try:
        Reference.load(path)
        cameras = reference_cameras(path)
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        named = str(err).startswith(f"{path}:")  # Reference.load names the file already
        raise ReconstructionError(str(err) if named else f"{path}: malformed reference file ({err})") from err
    for name, camera in cameras.items():
        try:
            check_camera(camera)
        except ValueError as err:
            raise ReconstructionError(f"{path}: camera of image {name!r}: {err}") from err
    return cameras


def mean_focal(camera: dict) -> float:
    """The mean focal length in pixels of a COLMAP camera dict (``f``, or the mean of ``fx`` and ``fy``)."""
    return float(pycolmap.Camera({k: camera[k] for k in ("model", "width", "height", "params")}).mean_focal_length())


def calibrated_reference(scene: Scene) -> bool:
    """Whether the scene's ``reference.json`` cameras are a calibration (:class:`lburst.sfm.reference.Reference`)."""
    reference = scene.reference()
    return reference is not None and reference.is_calibration


def scene_cameras(
    scene: Scene, sizes: list[tuple[int, int]], options: ReconstructOptions
) -> tuple[list[dict], list[int]]:
    """COLMAP camera priors (distinct dicts) and the camera index of every image of size (W, H)
    ``sizes`` (module docstring)."""
    if options.camera in (Camera.REFERENCE, Camera.REFERENCE_FOCAL) and scene.reference_path is None:
        raise ReconstructionError(f"{scene.root}: camera='{options.camera}' but the scene has no reference.json")
    ref_cams = None if scene.reference_path is None else check_reference(scene.reference_path)
    if options.camera == Camera.DEFAULT or (options.camera == Camera.AUTO and not calibrated_reference(scene)):
        ref_cams = None
    priors = []
    for item, (w, h) in zip(scene.items, sizes):
        camera = None
        if ref_cams is not None:
            if item.name not in ref_cams:
                raise ReconstructionError(f"{scene.reference_path}: no camera for image {item.name!r}")
            if options.camera == Camera.REFERENCE_FOCAL:
                camera = default_camera(w, h, options.camera_model, focal=mean_focal(ref_cams[item.name]))
            else:
                camera = {**ref_cams[item.name], "prior_focal": True}
        elif options.camera == Camera.AUTO and scene.camera is not None:
            camera = {**scene.camera, "prior_focal": True}
        elif options.camera == Camera.AUTO and exif_source(item) is not None:
            camera = exif_camera(exif_source(item), options.camera_model)
        priors.append(camera or default_camera(w, h, options.camera_model))
    if options.single_camera and all(prior == priors[0] for prior in priors):
        return [priors[0]], [0] * len(priors)
    return priors, list(range(len(priors)))


@dataclass(frozen=True)
class CameraPlan:
    """The cameras COLMAP starts from (:func:`camera_plan`)."""

    cameras: list[dict]  # distinct priors
    camera_of_image: list[int]  # index into cameras of every image
    calibrated: bool  # the scene's calibration: one camera, held fixed
    fixed: bool  # intrinsics held fixed in bundle adjustment


def camera_plan(scene: Scene, sizes: list[tuple[int, int]], options: ReconstructOptions) -> CameraPlan:
    """:func:`scene_cameras`, then a recording's ``meta.json`` camera, or a ``reference.json``
    that is a calibration, is the calibration: one camera, held fixed (refining it from dark
    frames moved the simulated flight's ATE from 0.133 to 1.17 m, docs/defaults.md)."""
    cameras, camera_of_image = scene_cameras(scene, sizes, options)
    calibrated = options.camera == Camera.AUTO and (scene.camera is not None or calibrated_reference(scene))
    if calibrated and all(cam == cameras[0] for cam in cameras):
        cameras, camera_of_image = cameras[:1], [0] * len(sizes)
    return CameraPlan(cameras, camera_of_image, calibrated, options.fix_intrinsics or calibrated)


def camera_origin(scene: Scene, plan: CameraPlan, options: ReconstructOptions) -> str:
    """Where a recording's intrinsics came from, in words (``result.json``'s ``metrics.camera``, ``report.md``)."""
    if plan.calibrated:
        return f"{scene.camera_source}, held fixed"
    if plan.fixed:
        return f"default prior held fixed ({'no meta.json camera' if scene.camera is None else '--camera'})"
    if scene.camera is None:
        return f"estimated, {'one for all keyframes' if options.single_camera else 'one per keyframe'} (no meta.json camera)"
    return f"estimated (meta.json camera not used: --camera {options.camera})"
