"""Keyframes by motion: the measured motion is the true one, and a hovering camera gets no keyframes."""

import cv2
import numpy as np
import pytest

from lburst.burst.io import write_image
from lburst.burst.keyframes import MotionGate, MotionTracker, apparent_motion, thumbnail
from lburst.burst.sources import RecordingOptions, open_recording


def _texture(rng: np.random.Generator, shape=(480, 800)) -> np.ndarray:
    smooth = cv2.GaussianBlur(rng.random(shape, dtype=np.float32), (0, 0), 4)
    smooth = (smooth - smooth.min()) / (smooth.max() - smooth.min())
    return np.repeat((30 + 190 * smooth)[..., None], 3, axis=2)


def _noisy(image: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    return np.clip(np.rint(image + rng.normal(0, sigma, image.shape)), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("shift", [2.0, 6.0, 12.0])
def test_translation_is_measured_as_a_fraction_of_the_width(shift):
    rng = np.random.default_rng(1)
    scene = _texture(rng)
    a = scene[100:292, 100:356]  # 256 x 192
    b = scene[100:292, 100 + int(shift) * 4 : 356 + int(shift) * 4]  # the view moved shift thumbnail pixels
    ta, tb = thumbnail(a, 64), thumbnail(b, 64)
    assert ta.shape == (48, 64)
    assert apparent_motion(ta, tb) == pytest.approx(shift / 64, rel=0.15)


def test_rotation_is_measured_as_the_median_pixel_displacement():
    scene = _texture(np.random.default_rng(2))[:192, :256]
    angle = 6.0
    rotated = cv2.warpAffine(scene, cv2.getRotationMatrix2D((127.5, 95.5), angle, 1.0), (256, 192))
    ys, xs = np.mgrid[0:192, 0:256]
    radius = np.hypot(xs - 127.5, ys - 95.5)
    expected = np.median(2 * radius * np.sin(np.radians(angle) / 2)) / 256
    measured = apparent_motion(thumbnail(scene, 96), thumbnail(rotated, 96))
    assert measured == pytest.approx(expected, rel=0.25)


def _flight(tmp_path, sigma: float) -> tuple:
    """Frames 0-19 hovering, 20-59 panning 3 px a frame, 60-79 hovering; 192x128, noisy."""
    rng = np.random.default_rng(3)
    scene = _texture(rng, (200, 400))
    folder = tmp_path / "hover_pan_hover"
    folder.mkdir()
    x = 0
    for i in range(80):
        x += 3 if 20 <= i < 60 else 0
        write_image(folder / f"frame_{i:03d}.png", _noisy(scene[30:158, x : x + 192], sigma, rng))
    (folder / "meta.json").write_text('{"fps": 20}')
    return folder


def test_keyframes_follow_the_motion_not_the_clock_even_in_noise(tmp_path):
    folder = _flight(tmp_path, sigma=40.0)
    gate = MotionGate(threshold=0.1, size=96)
    got = list(open_recording(folder, RecordingOptions(burst=5, motion=gate)).bursts())
    keys = [k.index for k, _ in got]
    assert keys[0] == 0
    assert all(k >= 20 for k in keys[1:]), keys  # nothing while hovering
    assert max(keys) <= 62, keys  # nor after the pan stops
    steps = np.diff(keys[1:])
    assert len(keys) >= 5 and np.all((steps >= 6) & (steps <= 7)), keys  # 0.1 x 192 px at 3 px a frame: 6.4
    for key, burst in got:  # the burst is centred on its keyframe, as with --every
        assert burst.shape == (5, 128, 192, 3)
        _, same = next(open_recording(folder, RecordingOptions(burst=5, every=1, start=key.index)).bursts())
        assert np.array_equal(burst, same)


def test_motion_options_are_checked(tmp_path):
    with pytest.raises(ValueError, match="--motion"):
        MotionGate(threshold=0.0)
    with pytest.raises(ValueError, match="--motion"):
        MotionGate(threshold=0.6)
    with pytest.raises(ValueError, match="different shapes"):
        apparent_motion(np.zeros((4, 6), np.float32), np.zeros((6, 4), np.float32))
    assert RecordingOptions(motion=MotionGate(0.1)).signature() != RecordingOptions(motion=MotionGate(0.2)).signature()


def test_views_with_nothing_to_measure_make_no_keyframes():
    rng = np.random.default_rng(4)
    black = np.zeros((72, 96), np.float32)
    noise = [rng.normal(100, 30, (72, 96)).astype(np.float32) for _ in range(30)]
    scene = thumbnail(_texture(rng)[:192, :256], 96)
    tracker = MotionTracker(MotionGate(0.1))
    assert [tracker.is_keyframe([black]) for _ in range(10)] == [True] + [False] * 9  # a lens cap
    assert not any(tracker.is_keyframe([n]) for n in noise)  # nothing but noise
    assert [tracker.is_keyframe([scene]) for _ in range(3)] == [False, True, False]  # a view again: one keyframe
