"""What the COLMAP child reports of a model (lburst.sfm.colmap.summarize), by value, on a model
built by hand: two cameras 1 m apart looking at three points."""

import numpy as np
import pytest

from lburst.sfm.colmap import pycolmap, summarize

POINTS = np.array([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 6.0]])


def two_view_model(offset: float) -> "pycolmap.Reconstruction":
    """Images 0000.png (at the origin) and 0001.jpg (1 m to the right, its observations ``offset``
    px off in x and y from the projections, and one more keypoint in no track), each seeing every point."""
    rec = pycolmap.Reconstruction()
    camera = pycolmap.Camera(model="SIMPLE_PINHOLE", width=100, height=80, params=[100.0, 50.0, 40.0], camera_id=1)
    rec.add_camera_with_trivial_rig(camera)
    for i, (name, x) in enumerate([("0000.png", 0.0), ("0001.jpg", -1.0)]):
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(), np.array([x, 0.0, 0.0]))
        image = pycolmap.Image(name=name, camera_id=1, image_id=i + 1)
        seen = [np.asarray(camera.img_from_cam(pose * p)) + (offset if i else 0.0) for p in POINTS]
        unmatched = [np.array([10.0, 10.0])] * i  # a keypoint of the second image in no track
        image.points2D = pycolmap.Point2DList([pycolmap.Point2D(xy) for xy in seen + unmatched])
        rec.add_image_with_trivial_frame(image, pose)
    for k, p in enumerate(POINTS):
        track = pycolmap.Track()
        track.add_element(1, k)
        track.add_element(2, k)
        rec.add_point3D(p, track)
    rec.update_point_3d_errors()
    return rec


def test_the_summary_holds_each_registered_image_and_the_models_statistics():
    summary = summarize(two_view_model(offset=0.5))
    assert summary["converged"] is True
    assert sorted(summary["registered"]) == ["0000", "0001"]  # names without their suffix
    second = summary["registered"]["0001"]
    np.testing.assert_allclose(second["R"], np.eye(3))
    np.testing.assert_allclose(second["t"], [-1.0, 0.0, 0.0])
    assert second["camera"] == {"model": "SIMPLE_PINHOLE", "width": 100, "height": 80, "params": [100.0, 50.0, 40.0]}
    assert second["num_points3D"] == 3  # of its 4 keypoints
    assert summary["num_points3D"] == 3 and summary["num_observations"] == 6
    assert summary["mean_track_length"] == 2.0
    # each point: 0 px in the first image, 0.5 * sqrt(2) px in the second
    assert summary["mean_reprojection_error"] == pytest.approx(0.5 * np.sqrt(2) / 2, abs=1e-6)


def test_no_model_is_an_empty_summary():
    assert summarize(None) == {"converged": False, "registered": {}, "num_points3D": 0}
