"""ROS bags as recordings: ROS 1 and ROS 2 (sqlite3, mcap) bags written and read back, every
Image encoding, CompressedImage, CameraInfo as the camera and NavSatFix as the GNSS, and the
bad bags a robot leaves (no images, several image topics, an unsupported encoding, an
uncalibrated CameraInfo)."""

import json

import numpy as np
import pytest

pytest.importorskip("rosbags")

from lburst.burst.io import BurstError  # noqa: E402
from lburst.burst.rosbag import BagWriter, decode_image, is_bag  # noqa: E402
from lburst.burst.sources import RecordingOptions, is_recording, open_recording  # noqa: E402

CAMERA = {"model": "OPENCV", "width": 32, "height": 24, "params": [30.0, 31.0, 16.0, 12.0, -0.1, 0.01, 0.0, 0.0]}


def frame(j: int) -> np.ndarray:
    image = np.zeros((24, 32, 3), np.uint8)
    image[..., 0], image[..., 1], image[..., 2] = 10 * j, 100, 200
    return image


def write_bag(path, storage="sqlite3", n=6, gnss_every=2):
    with BagWriter(path, storage) as bag:
        for j in range(n):
            stamp = 1_700_000_000.0 + j * 0.05
            bag.image("/cam/image_raw", stamp, frame(j), "rgb8")
            bag.camera_info("/cam/camera_info", stamp, CAMERA)
            if j % gnss_every == 0:
                bag.navsat("/gps/fix", stamp + 0.01, 47.0 + j * 1e-5, 8.0, 400.0 + j)
    return path


@pytest.mark.parametrize("name, storage", [("log.bag", "sqlite3"), ("log", "sqlite3"), ("log", "mcap")])
def test_a_bag_is_a_recording_of_its_frames_camera_and_fixes(tmp_path, name, storage):
    path = write_bag(tmp_path / name, storage)
    assert is_bag(path) and is_recording(path)
    rec = open_recording(path, RecordingOptions(burst=3, every=2))
    bursts = list(rec.bursts())
    assert [k.index for k, _ in bursts] == [0, 2, 4]
    assert [k.time for k, _ in bursts] == pytest.approx([0.0, 0.1, 0.2])
    np.testing.assert_array_equal(bursts[1][1][1], frame(2))  # the keyframe is the burst's middle frame
    np.testing.assert_array_equal(bursts[1][1][0], frame(1))
    assert rec.camera == CAMERA | {"model": "OPENCV"} and rec.fps == pytest.approx(20.0, rel=0.05)
    assert rec.camera_source == f"the CameraInfo of {path.name}"  # as the report names the camera
    track = rec.gnss_track()
    assert [f.time for f in track.fixes] == pytest.approx([0.01, 0.11, 0.21])
    assert [f.alt for f in track.fixes] == [400.0, 402.0, 404.0] and "/gps/fix (NavSatFix, 3 fixes)" in track.source


def _bayer(rgb: np.ndarray, pattern: str) -> np.ndarray:
    """The Bayer mosaic of ``rgb`` with ``pattern`` (e.g. 'rggb': R at (0,0), G at (0,1), ...)."""
    channel = {"r": 0, "g": 1, "b": 2}
    out = np.zeros(rgb.shape[:2], rgb.dtype)
    for k, (dy, dx) in enumerate([(0, 0), (0, 1), (1, 0), (1, 1)]):
        out[dy::2, dx::2] = rgb[dy::2, dx::2, channel[pattern[k]]]
    return out


@pytest.mark.parametrize("pattern", ["rggb", "bggr", "gbrg", "grbg"])
@pytest.mark.parametrize("bits", [8, 16])
def test_bayer_frames_are_demosaiced_to_their_colours(tmp_path, pattern, bits):
    dtype = np.uint8 if bits == 8 else np.uint16
    rgb = np.zeros((8, 8, 3), dtype)
    rgb[...] = np.array([200, 100, 50]) * (1 if bits == 8 else 256)
    with BagWriter(tmp_path / "b.bag") as bag:
        bag.image("/cam/image_raw", 1.0, _bayer(rgb, pattern), f"bayer_{pattern}{bits}")
    rec = open_recording(tmp_path / "b.bag", RecordingOptions(burst=1, every=1))
    got = next(iter(rec.bag.frames())).image
    assert got.dtype == dtype
    np.testing.assert_array_equal(got[3:5, 3:5], rgb[3:5, 3:5])


@pytest.mark.parametrize(
    "encoding, pixels, expected",
    [
        ("mono8", np.full((4, 6), 77, np.uint8), np.full((4, 6, 3), 77, np.uint8)),
        ("mono16", np.full((4, 6), 4000, np.uint16), np.full((4, 6, 3), 4000, np.uint16)),
        (
            "bgr8",
            np.tile([[[3, 2, 1]]], (4, 6, 1)).astype(np.uint8),
            np.tile([[[1, 2, 3]]], (4, 6, 1)).astype(np.uint8),
        ),
        (
            "rgba8",
            np.tile([[[1, 2, 3, 9]]], (4, 6, 1)).astype(np.uint8),
            np.tile([[[1, 2, 3]]], (4, 6, 1)).astype(np.uint8),
        ),
    ],
)
def test_plain_encodings_are_read_as_rgb(tmp_path, encoding, pixels, expected):
    with BagWriter(tmp_path / "e.bag") as bag:
        bag.image("/cam/image_raw", 1.0, pixels, encoding)
    rec = open_recording(tmp_path / "e.bag", RecordingOptions(burst=1, every=1))
    got = next(iter(rec.bag.frames())).image
    assert got.dtype == expected.dtype
    np.testing.assert_array_equal(got, expected)


def test_a_compressed_png_and_a_padded_row_are_read(tmp_path):
    import cv2

    from lburst.burst.rosbag import COMPRESSED, IMAGE

    class Msg:
        format = "png"
        data = np.frombuffer(cv2.imencode(".png", frame(3)[..., ::-1])[1].tobytes(), np.uint8)

    np.testing.assert_array_equal(decode_image(Msg, COMPRESSED, "x"), frame(3))

    class Padded:
        encoding, width, height, step, is_bigendian = "mono8", 3, 2, 8, 0
        data = np.array([1, 2, 3, 0, 0, 0, 0, 0, 4, 5, 6, 0, 0, 0, 0, 0], np.uint8)

    np.testing.assert_array_equal(decode_image(Padded, IMAGE, "x")[..., 0], [[1, 2, 3], [4, 5, 6]])


def test_a_bag_without_images_names_its_topics(tmp_path):
    with BagWriter(tmp_path / "g.bag") as bag:
        bag.navsat("/gps/fix", 1.0, 47.0, 8.0, 400.0)
    with pytest.raises(BurstError, match=r"g.bag: no image topic; its topics: /gps/fix \(NavSatFix\)"):
        open_recording(tmp_path / "g.bag")


def test_several_image_topics_need_topic_and_the_error_lists_them(tmp_path):
    with BagWriter(tmp_path / "two") as bag:
        bag.image("/left/image_raw", 1.0, frame(0), "rgb8")
        bag.compressed("/right/image_raw/compressed", 1.0, frame(1))
    with pytest.raises(BurstError, match=r"2 image topics \(/left/image_raw, /right/image_raw/compressed\): pick one"):
        open_recording(tmp_path / "two")
    with pytest.raises(BurstError, match="no image topic '/middle'; its image topics: /left/image_raw, /right"):
        open_recording(tmp_path / "two", RecordingOptions(topic="/middle"))
    rec = open_recording(tmp_path / "two", RecordingOptions(topic="/right/image_raw/compressed", burst=1, every=1))
    assert np.abs(next(iter(rec.bag.frames())).image.astype(int) - frame(1)).max() < 8  # JPEG


def test_an_unsupported_encoding_names_the_topic_and_message(tmp_path):
    with BagWriter(tmp_path / "y.bag") as bag:
        bag.image("/cam/image_raw", 1.0, frame(0), "rgb8")
        bag.image("/cam/image_raw", 1.05, np.zeros((24, 64), np.uint8), "yuv422")
    rec = open_recording(tmp_path / "y.bag", RecordingOptions(burst=1, every=1))
    with pytest.raises(BurstError, match=r"y.bag: /cam/image_raw message 1: encoding 'yuv422' is not supported"):
        list(rec.bursts())


def test_an_uncalibrated_camera_info_is_refused_unless_a_meta_json_says_what_to_do(tmp_path):
    path = tmp_path / "u.bag"
    with BagWriter(path) as bag:
        bag.image("/cam/image_raw", 1.0, frame(0), "rgb8")
        bag.camera_info("/cam/camera_info", 1.0, CAMERA | {"params": [0.0, 0.0, 16.0, 12.0]})
    with pytest.raises(
        BurstError, match=r"u.bag: /cam/camera_info: CameraInfo with focal length 0, 0 \(an uncalibrated"
    ):
        _ = open_recording(path).camera
    (tmp_path / "u.meta.json").write_text(json.dumps({"camera": None}))
    assert open_recording(path).camera is None and open_recording(path).camera_source == "meta.json"


def test_fixes_without_a_fix_are_left_out_with_a_note(tmp_path):
    path = tmp_path / "n.bag"
    with BagWriter(path) as bag:
        for j in range(3):
            bag.image("/cam/image_raw", 1.0 + j, frame(j), "rgb8")
            bag.navsat("/fix", 1.0 + j, 47.0, 8.0, 400.0, status=-1 if j == 1 else 0)
    track = open_recording(path).gnss_track()
    assert [f.time for f in track.fixes] == [0.0, 2.0]
    assert track.notes == [f"{path}: /fix: 1 message(s) without a fix (status -1); not used"]


def test_extract_cuts_a_bag_into_keyframes_without_every(tmp_path):
    from lburst.sfm.inputs import RecordingInput, open_bursts

    path = write_bag(tmp_path / "log.bag")
    source = open_bursts(path, RecordingOptions(burst=1, every=2))
    assert isinstance(source, RecordingInput)
    assert [b.name for b in source.keyframe_bursts()] == ["f000000_t0.000s", "f000002_t0.100s", "f000004_t0.200s"]
