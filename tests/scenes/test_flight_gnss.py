"""The simulated flight as a drone and a robot record it: JPEG frames with EXIF GPS, a video's
DJI subtitles and a ROS 2 bag, each read back to the exact camera centres."""

import numpy as np
import pytest

pytest.importorskip("pyproj")
pytest.importorskip("piexif")
pytest.importorskip("rosbags")

from lburst.burst.sources import RecordingOptions, open_recording  # noqa: E402
from lburst.scenes import flight_recording as recording  # noqa: E402
from lburst.scenes.flight_gnss import (  # noqa: E402
    FLIGHT_ORIGIN,
    frame_fixes,
    write_flight_bag,
    write_flight_jpg,
    write_flight_srt,
)
from lburst.scenes.night_flight import NightFlightConfig, camera_pose  # noqa: E402

CFG = NightFlightConfig(n_bursts=2, width=64, height=48)


def centres(times) -> np.ndarray:
    return np.array([-R.T @ t for R, t in (camera_pose(CFG, float(time)) for time in times)])


def test_a_fix_is_the_camera_centre_on_the_earth():
    times = recording.frame_times(CFG)[[0, 10, 32]]
    fixes = frame_fixes(CFG, times)
    np.testing.assert_allclose(FLIGHT_ORIGIN.to_enu(*fixes.T), centres(times), atol=1e-6)


def test_jpeg_frames_carry_their_exact_positions(tmp_path):
    folder = write_flight_jpg(tmp_path / "jpg", CFG, progress=False)
    rec = open_recording(folder, RecordingOptions(burst=1, every=1))
    track = rec.gnss_track()
    assert len(track.fixes) == recording.frame_count(CFG) == 33 and not track.notes
    got = FLIGHT_ORIGIN.to_enu(*np.array([(f.lat, f.lon, f.alt) for f in track.fixes]).T)
    np.testing.assert_allclose(got, centres(recording.frame_times(CFG)), atol=0.005)  # EXIF's 1/10000 arc second
    assert [f.time for f in track.fixes] == pytest.approx(list(recording.frame_times(CFG)))


def test_subtitles_beside_the_video_carry_every_frames_position(tmp_path):
    pytest.importorskip("av")
    video = recording.write_flight_video(tmp_path / "flight.mp4", CFG, progress=False)
    srt = write_flight_srt(video, CFG)
    assert srt == tmp_path / "flight.SRT"
    track = open_recording(video).gnss_track()
    got = FLIGHT_ORIGIN.to_enu(*np.array([(f.lat, f.lon, f.alt) for f in track.fixes]).T)
    np.testing.assert_allclose(got, centres(recording.frame_times(CFG)), atol=0.002)


def test_a_ros2_bag_holds_the_frames_the_camera_and_the_fixes(tmp_path):
    bag = write_flight_bag(tmp_path / "flight", CFG, progress=False)
    rec = open_recording(bag, RecordingOptions(burst=5, every=8))
    assert rec.camera == recording.camera(CFG) and rec.ground_truth == bag / "gt.txt"
    keyframes = [k for k, _ in rec.bursts()]
    assert [k.index for k in keyframes] == [0, 8, 16, 24, 32]
    assert [k.time for k in keyframes] == pytest.approx([0.0, 0.4, 0.8, 1.2, 1.6])
    track = rec.gnss_track()
    assert [f.time for f in track.fixes] == pytest.approx([0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6])
    with pytest.raises(FileExistsError, match="exists"):
        write_flight_bag(bag, CFG, progress=False)
