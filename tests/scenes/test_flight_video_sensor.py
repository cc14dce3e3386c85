"""A low-light flight's video is the in-camera processing of the very raw frames its DNG version
stores: same Bayer sensor, same noise draw, so the two recordings hold the same light."""

import numpy as np
import pytest

from lburst.noise import LowLightNoise
from lburst.scenes.flight_recording import camera_isp, raw_frame
from lburst.scenes.night_flight import NightFlightConfig


def test_camera_isp_restores_the_colour_and_brightness_of_a_bright_flat_scene():
    cfg = NightFlightConfig(noise="lowlight:3000")  # white at 3,600 of the 4,095 counts; noise about 2%
    radiance = np.empty((32, 32, 3), np.float32)
    radiance[:] = (200.0, 100.0, 50.0)
    rgb = camera_isp(raw_frame(cfg, radiance, np.random.default_rng(0))[0], LowLightNoise(3000.0))
    assert rgb.dtype == np.uint8 and rgb.shape == (32, 32, 3)
    # the RGGB mosaic demosaiced back to the right channels (a wrong Bayer code swaps red and blue)
    assert np.abs(rgb[2:-2, 2:-2].mean((0, 1)) - (200, 100, 50)).max() < 2


def test_camera_isp_keeps_the_mean_of_moonless_noise():
    cfg = NightFlightConfig(noise="lowlight:moonless")
    radiance = np.full((32, 32, 3), 128.0, np.float32)
    frames = [
        camera_isp(raw_frame(cfg, radiance, np.random.default_rng(i))[0], LowLightNoise.preset("moonless"))
        for i in range(20)
    ]
    mean = np.mean(frames, dtype=np.float64)
    assert mean == pytest.approx(128.0, abs=8.0)  # a few grey levels of clipping bias at most
    assert 60 < np.std(frames) < 130  # noisy, as 3 photo-electrons at white are


def test_the_low_light_video_is_the_dng_flights_raw_frames_through_the_camera(tmp_path):
    pytest.importorskip("av")
    import av

    from lburst.scenes.flight_recording import _rendered, write_flight_video

    cfg = NightFlightConfig(n_bursts=2, width=128, height=96, noise="lowlight:night", burst_spacing=1.0)
    video = write_flight_video(tmp_path / "f.mp4", cfg, crf=0, progress=False)
    with av.open(str(video)) as container:
        decoded = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    j, _, radiance = next(_rendered(cfg, False, "", [3]))
    sensor = LowLightNoise.preset("night")
    same = camera_isp(raw_frame(cfg, radiance, np.random.default_rng([cfg.seed, 3, j]))[0], sensor)
    other = camera_isp(raw_frame(cfg, radiance, np.random.default_rng([cfg.seed, 9, j]))[0], sensor)
    error = np.abs(decoded[j].astype(int) - same).mean()
    assert error < 0.5 * np.abs(decoded[j].astype(int) - other).mean()  # the same draw, up to yuv420p


def test_the_video_is_the_same_whatever_cpus_the_encoder_may_use(tmp_path):
    pytest.importorskip("av")
    import os

    from lburst.scenes.flight_recording import write_flight_video

    cpus = os.sched_getaffinity(0)
    if len(cpus) < 2:
        pytest.skip("needs two CPUs to compare against one")
    cfg = NightFlightConfig(n_bursts=2, width=320, height=240, noise="lowlight:moonless")
    many = write_flight_video(tmp_path / "many.mp4", cfg, progress=False).read_bytes()
    os.sched_setaffinity(0, {min(cpus)})
    try:
        one = write_flight_video(tmp_path / "one.mp4", cfg, progress=False).read_bytes()
    finally:
        os.sched_setaffinity(0, cpus)
    assert one == many  # x264 picks its thread count from the CPUs: the writer fixes it
