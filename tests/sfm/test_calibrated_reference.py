"""``--camera auto`` takes a scene's calibration: reference.json cameras that are a calibration
(synthetic, or marked ``"calibrated": true``) become the cameras, held fixed by default; cameras
estimated from the images (``sift-clean``) are not used as a prior unless asked."""

import json

import numpy as np
import pytest

from lburst.burst.io import write_image
from lburst.sfm.cameras import calibrated_reference, camera_plan, scene_cameras
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.result import ReconstructionError
from lburst.sfm.scene import list_scene

CAMERA = {"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 50.0, 32.0, 24.0]}


def make_scene(root, **reference):
    for name in ("0000", "0001"):
        (root / name).mkdir()
        for k in range(3):
            write_image(root / name / f"frame_{k:03d}.png", np.full((48, 64, 3), 40 * k, np.uint8))
    poses = {name: {"R": np.eye(3).tolist(), "t": [float(i), 0.0, 0.0]} for i, name in enumerate(("0000", "0001"))}
    (root / "reference.json").write_text(json.dumps({"camera": CAMERA, "images": poses, "length": 1.0, **reference}))
    return list_scene(root)


@pytest.mark.parametrize(
    "reference, calibrated",
    [
        ({"source": "synthetic"}, True),
        ({"source": "sift-clean"}, False),
        ({"source": "sift-clean", "calibrated": True}, True),
        ({"source": "synthetic", "calibrated": False}, False),
    ],
)
def test_auto_takes_the_reference_cameras_only_when_they_are_a_calibration(tmp_path, reference, calibrated):
    scene = make_scene(tmp_path, **reference)
    assert calibrated_reference(scene) is calibrated
    priors, _ = scene_cameras(scene, [(64, 48)] * 2, ReconstructOptions(camera="auto"))
    assert (priors[0]["params"] == CAMERA["params"]) is calibrated
    default, _ = scene_cameras(scene, [(64, 48)] * 2, ReconstructOptions(camera="default"))
    assert default[0]["params"] != CAMERA["params"]


def test_a_calibrated_flag_that_is_not_a_boolean_is_refused_by_file(tmp_path):
    from lburst.sfm.reference import Reference

    make_scene(tmp_path, source="sift-clean", calibrated="yes")
    with pytest.raises(ValueError, match="calibrated must be true or false"):
        Reference.load(tmp_path / "reference.json")


def test_reference_focal_starts_colmaps_default_camera_at_the_reference_focal_length(tmp_path):
    scene = make_scene(tmp_path, source="strecha", calibrated=True)
    options = ReconstructOptions(camera="reference-focal", single_camera=True)
    priors, of_image = scene_cameras(scene, [(64, 48)] * 2, options)
    # one shared SIMPLE_RADIAL camera: the reference's focal length, the principal point at the
    # image centre and no distortion (COLMAP's default prior otherwise), refined
    assert of_image == [0, 0]
    assert priors == [
        {"model": "SIMPLE_RADIAL", "width": 64, "height": 48, "params": [50.0, 32.0, 24.0, 0.0], "prior_focal": True}
    ]
    plan = camera_plan(scene, [(64, 48)] * 2, options)
    assert not plan.fixed and not plan.calibrated
    fixed = camera_plan(scene, [(64, 48)] * 2, ReconstructOptions(camera="reference-focal", fix_intrinsics=True))
    assert fixed.fixed
    (tmp_path / "reference.json").unlink()
    with pytest.raises(ReconstructionError, match="reference-focal. but the scene has no reference.json"):
        scene_cameras(list_scene(tmp_path), [(64, 48)] * 2, options)
