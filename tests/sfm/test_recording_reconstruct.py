"""A simulated flight recorded as a video and as DNG frames reconstructs from the recording itself,
and its TUM trajectory agrees with evo."""

import json

import h5py
import numpy as np
import pytest

from lburst.burst.sources import RecordingOptions
from lburst.scenes.night_flight import NightFlightConfig
from lburst.sfm import reconstruct_scene
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.result import Status
from lburst.tum import read_tum

pytest.importorskip("av")
CFG = NightFlightConfig.daylight(n_bursts=4, width=256, height=192, noise="none")
SIFT = "sift,max_features=1500"
FAST = {"max_num_trials": 2000}


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    from lburst.scenes.flight_recording import write_flight_video

    return write_flight_video(tmp_path_factory.mktemp("rec") / "flight.mp4", CFG, progress=False)


def test_simulated_video_has_per_frame_ground_truth(video):
    from lburst.scenes.flight_recording import frame_count
    from lburst.scenes.night_flight import camera_pose

    times, poses = read_tum(video.with_name("flight.gt.txt"))
    assert len(times) == frame_count(CFG) == 97 and times[1] == pytest.approx(0.05)
    R, t = camera_pose(CFG, times[40])
    assert np.allclose(poses[40][0], R, atol=1e-8) and np.allclose(poses[40][1], t, atol=1e-6)


def test_video_reconstructs_and_evo_agrees(video, tmp_path):
    result = reconstruct_scene(
        video,
        SIFT,
        tmp_path / "out",
        ReconstructOptions(progress=False, extra=FAST, recording=RecordingOptions(burst=3, every=16)),
    )
    assert result.names == [f"f{i:06d}_t{i / 20:.3f}s" for i in range(0, 97, 16)]
    assert result.registered == result.names and result.status == Status.COMPLETE and result.error is None
    assert result.metrics["ate_percent"] < 1.0
    out = tmp_path / "out"
    times, _ = read_tum(out / "trajectory.tum")
    assert np.allclose(times, np.arange(0, 97, 16) / 20)
    for name in ("colmap/model/images.bin", "colmap/model.ply", "report.md", "trajectory.png", "registration.png"):
        assert (out / name).stat().st_size > 0
    shared = result.metrics["first_last_points3D"]  # counted in the model: tests/sfm/test_loop_pairs.py
    assert isinstance(shared, int) and f"keyframes share {shared} 3D points" in (out / "report.md").read_text()
    timing = json.loads((out / "colmap" / "output.json").read_text())
    assert timing["verify_seconds"] >= 0 and timing["map_seconds"] > 0  # the COLMAP stages' wall times
    with h5py.File(out / "features.h5") as f, h5py.File(out / "matches.h5") as m:
        first, second = f"{result.names[0]}.png", f"{result.names[1]}.png"
        assert set(f) == {f"{n}.png" for n in result.names}
        m0 = m[first][second]["matches0"][()]
        assert len(m0) == len(f[first]["keypoints"]) and (m0 >= 0).sum() > 50
    evo = pytest.importorskip("evo")
    del evo
    from evo.core import metrics, sync
    from evo.tools import file_interface

    ref = file_interface.read_tum_trajectory_file(str(video.with_name("flight.gt.txt")))
    est = file_interface.read_tum_trajectory_file(str(out / "trajectory.tum"))
    ref, est = sync.associate_trajectories(ref, est)
    est.align(ref, correct_scale=True)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    assert ape.get_statistic(metrics.StatisticsType.rmse) == pytest.approx(result.metrics["ate_rmse"], abs=1e-6)


def test_truncated_video_keeps_the_keyframes_before_the_cut(video, tmp_path):
    cut = tmp_path / "cut.mp4"
    data = video.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.8)])
    result = reconstruct_scene(
        cut,
        SIFT,
        tmp_path / "out",
        ReconstructOptions(progress=False, extra=FAST, recording=RecordingOptions(burst=3, every=16)),
    )
    assert result.status == Status.PARTIAL and "cut.mp4" in result.error and "truncated" in result.error
    assert 2 <= len(result.names) < 7 and result.registered == result.names


def test_dng_recording_reconstructs(tmp_path):
    pytest.importorskip("rawpy")
    from lburst.scenes.flight_recording import write_flight_dng

    cfg = NightFlightConfig.daylight(n_bursts=3, width=256, height=192, noise="lowlight:2000")
    folder = write_flight_dng(tmp_path / "dng", cfg, progress=False)
    assert len(list(folder.glob("*.dng"))) == 65
    result = reconstruct_scene(
        folder,
        SIFT,
        tmp_path / "out",
        ReconstructOptions(progress=False, extra=FAST, recording=RecordingOptions(burst=1, every=16)),
    )
    assert result.registered == result.names and len(result.names) == 5
    assert result.metrics["ate_percent"] < 1.0


def test_the_light_network_reconstructs_a_recording(video, tmp_path):
    """`lburst reconstruct REC --method lburst-lite`: the shipped light weights on the CPU's own
    runtime, from the video's keyframe bursts to a registered trajectory."""
    result = reconstruct_scene(
        video,
        "lburst-lite",
        tmp_path / "out",
        ReconstructOptions(progress=False, extra=FAST, recording=RecordingOptions(burst=5, every=16)),
    )
    assert result.registered == result.names and len(result.names) == 7
    assert result.metrics["ate_percent"] < 1.0
