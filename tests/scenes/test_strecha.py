"""Exact cameras in Strecha's format become a calibrated ``reference.json`` that projects world
points where the photos (resized from the originals) see them; bad camera files are refused in
one line naming the file; on the real castle-P30 the cameras agree with SIFT matches."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lburst.scenes.photo_scene import simulate_scene
from lburst.scenes.strecha import CameraFileError, read_camera, strecha_reference
from lburst.sfm.reference import Reference
from lburst.sfm.scene import reference_cameras

K = np.array([[2759.48, 0.0, 1520.69], [0.0, 2764.16, 1006.81], [0.0, 0.0, 1.0]])  # for 3072x2048
ORIGINAL = (3072, 2048)
SMALL = (192, 128)  # the originals resized by 1/16
POSES = {  # camera-to-world R (Strecha's convention) and centre C, metres
    "0000": (Rotation.from_euler("xyz", [100, 10, 35], degrees=True).as_matrix(), np.array([15.4, 12.7, 10.1])),
    "0001": (Rotation.from_euler("xyz", [95, -5, 60], degrees=True).as_matrix(), np.array([13.0, 14.2, 9.8])),
}


def camera_text(R, C, K=K, distortion="0 0 0", size=ORIGINAL) -> str:
    rows = [" ".join(f"{v:.9g}" for v in row) for row in (*K, *R)]
    return "\n".join([*rows[:3], distortion, *rows[3:], " ".join(f"{v:.9g}" for v in C), f"{size[0]} {size[1]}"]) + "\n"


@pytest.fixture
def photo_set(tmp_path):
    """``SET/images/NNNN.jpg`` (192x128) and ``SET/gt_cameras/NNNN.jpg.camera`` for 3072x2048."""
    root = tmp_path / "set"
    (root / "images").mkdir(parents=True)
    (root / "gt_cameras").mkdir()
    rng = np.random.default_rng(0)
    for name, (R, C) in POSES.items():
        image = cv2.GaussianBlur(rng.integers(0, 256, (SMALL[1], SMALL[0], 3), dtype=np.uint8), (0, 0), 1.5)
        cv2.imwrite(str(root / "images" / f"{name}.jpg"), image)
        (root / "gt_cameras" / f"{name}.jpg.camera").write_text(camera_text(R, C))
    return root


def expected_pixels(R, C, points):
    """Where the resized photo sees ``points`` (OpenCV's pixel centres): the original's pixel
    ``K R^T (X - C)``, then ``(u + 0.5) s - 0.5`` per axis."""
    cam = (points - C) @ R  # R^T (X - C) for each row
    uv = cam @ K.T
    uv = uv[:, :2] / uv[:, 2:]
    s = np.array(SMALL) / np.array(ORIGINAL)
    return (uv + 0.5) * s - 0.5


def points_in_front(R, C, rng, n=20):
    """World points 3-20 m in front of the camera, inside its view."""
    cam = np.c_[rng.uniform(-0.3, 0.3, (n, 2)), np.ones(n)] * rng.uniform(3, 20, (n, 1))
    return cam @ R.T + C


def test_simulate_scene_writes_a_calibrated_reference_that_projects_known_points(photo_set, tmp_path):
    out = tmp_path / "scene"
    ref = simulate_scene(photo_set, out, frames=3, noise="none", progress=False)  # SET itself: its images/
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["0000", "0001"]
    saved = Reference.load(out / "reference.json")
    assert ref is not None and saved.source == "strecha" and saved.is_calibration
    cameras = reference_cameras(out / "reference.json")
    rng = np.random.default_rng(1)
    for name, (R, C) in POSES.items():
        # the pose: world-to-camera R^T, -R^T C (R in the file is camera-to-world)
        np.testing.assert_allclose(saved.centers()[name], C, atol=1e-6)
        points = points_in_front(R, C, rng)
        one = Reference(saved.source, cameras[name], {name: saved.poses[name]})
        np.testing.assert_allclose(one.project(name, points) - 0.5, expected_pixels(R, C, points), atol=1e-6)
        # a point on the optical axis lands on the scaled principal point, (c + 0.5) s in COLMAP's convention
        axis = one.project(name, (C + 7.0 * R[:, 2])[None])[0]
        np.testing.assert_allclose(axis, [1521.19 / 16, 1007.31 / 16], atol=1e-6)
        assert cameras[name]["model"] == "PINHOLE" and (cameras[name]["width"], cameras[name]["height"]) == SMALL
        np.testing.assert_allclose(cameras[name]["params"][:2], [2759.48 / 16, 2764.16 / 16])
    # the path length through the centres in photo order
    assert saved.length == pytest.approx(np.linalg.norm(POSES["0000"][1] - POSES["0001"][1]))


def test_the_images_folder_finds_the_cameras_beside_it(photo_set):
    names_sizes = [(n, photo_set / "images" / f"{n}.jpg", SMALL) for n in POSES]
    ref, cameras = strecha_reference(photo_set / "gt_cameras", names_sizes)
    assert sorted(cameras) == sorted(POSES) and ref.is_calibration
    out = photo_set.parent / "from_images"
    simulate_scene(photo_set / "images", out, frames=1, noise="none", progress=False)
    assert Reference.load(out / "reference.json").source == "strecha"


@pytest.mark.parametrize(
    "text, problem",
    [
        ("1 0 0\n0 1 0\n", "9 lines"),
        (camera_text(np.eye(3), [0, 0, 0]).replace("3072", "x3072"), "not a number"),
        (camera_text(np.eye(3) * 1.1, [0, 0, 0]), "not a rotation"),
        (camera_text(np.diag([1.0, 1.0, -1.0]), [0, 0, 0]), "not a rotation"),
        (camera_text(np.eye(3), [0, 0, 0], distortion="0.1 0 0"), "distortion"),
        (camera_text(np.eye(3), [0, 0, 0], K=np.array([[1.0, 0.5, 1], [0, 1, 1], [0, 0, 1]])), "K (lines 1-3)"),
        (camera_text(np.eye(3), [0, 0, 0], size=(3072, 0)), "image size"),
        (camera_text(np.eye(3), [0, 0, 0], size=(2048, 2048)), "aspect ratio"),
        (camera_text(np.eye(3), [0, float("nan"), 0]), "not finite"),
    ],
)
def test_a_bad_camera_file_is_refused_in_one_line_naming_it(photo_set, tmp_path, text, problem):
    bad = photo_set / "gt_cameras" / "0001.jpg.camera"
    bad.write_text(text)
    with pytest.raises(CameraFileError) as err:
        simulate_scene(photo_set, tmp_path / "scene", frames=1, noise="none", progress=False)
    message = str(err.value)
    assert message.startswith(str(bad)) and problem in message and "\n" not in message


def test_a_missing_camera_file_is_named(photo_set, tmp_path):
    (photo_set / "gt_cameras" / "0001.jpg.camera").unlink()
    with pytest.raises(CameraFileError, match="0001.jpg.camera: no camera file for photo 0001.jpg"):
        simulate_scene(photo_set, tmp_path / "scene", frames=1, noise="none", progress=False)


def test_the_cli_says_which_camera_file_is_bad(photo_set, tmp_path, capsys):
    from lburst.cli import main

    bad = photo_set / "gt_cameras" / "0000.jpg.camera"
    bad.write_text("garbage\n")
    assert main(["simulate", "scene", str(photo_set), "--out", str(tmp_path / "s"), "--frames", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"lburst simulate scene: error: {bad}: a Strecha camera file has 9 lines")


def test_castle_cameras_agree_with_sift_matches_of_neighbouring_photos(shared):
    from lburst.scenes.photo_scene import photo_set as find_photo_set
    from lburst.sfm.metrics import epipolar_distances

    castle = shared / "data" / "multiview" / "castle-P30"
    if not (castle / "gt_cameras").is_dir():
        pytest.skip(f"{castle} not found")
    images, cameras_dir = find_photo_set(castle)
    assert cameras_dir == (castle / "gt_cameras").resolve()
    pairs = [("0000", "0001"), ("0010", "0011"), ("0020", "0021")]
    names = sorted({n for pair in pairs for n in pair})
    gray = {n: cv2.imread(str(images / f"{n}.jpg"), cv2.IMREAD_GRAYSCALE) for n in names}
    photos = [(n, images / f"{n}.jpg", gray[n].shape[::-1]) for n in names]
    ref, cameras = strecha_reference(cameras_dir, photos)
    assert K.tolist() == read_camera(cameras_dir / "0000.jpg.camera")[0].tolist()  # the constant above is castle's
    sift = cv2.SIFT_create(nfeatures=2000)
    features = {n: sift.detectAndCompute(gray[n], None) for n in names}
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    for a, b in pairs:
        (kp_a, desc_a), (kp_b, desc_b) = features[a], features[b]
        good = [m for m, n in matcher.knnMatch(desc_a, desc_b, k=2) if m.distance < 0.7 * n.distance]
        assert len(good) > 100
        xa = np.array([kp_a[m.queryIdx].pt for m in good]) + 0.5  # OpenCV's pixel centres to COLMAP's
        xb = np.array([kp_b[m.trainIdx].pt for m in good]) + 0.5
        d = epipolar_distances(xa, xb, cameras[a], cameras[b], ref.poses[a], ref.poses[b])
        assert np.median(d) < 1.0, (a, b, np.median(d))
