"""Calibrated sensor presets (``sensor:NAME@ISO``): the statistics a camera calibration measures,
recovered from simulated dark and flat frames, match the published figures within 10 %, and each
measurement misses its figure when the model's noise term behind it is dropped.

The measurements, as a calibration does them on raw frames (``docs/noise.md``):

- black level: the mean of dark frames (its offset from the nominal level: the black bias);
- row noise: the std of the row means of dark frames (less the read noise's share, var / W),
  after each frame's mean per row parity (two Bayer channels per row) is removed;
- Gaussian read noise: the std of dark frames with their row means removed (less 1/12 DN^2 of
  quantisation);
- Tukey-lambda read noise: shape and scale by the probability-plot correlation (PPCC) method on
  the same row-free dark frames: the shape whose probability plot is straightest, the scale its
  slope;
- system gain K: the slope of the variance against the mean (DN above black) of flat frames at
  several light levels (photon transfer).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import optimize

from lburst.noise import SENSORS, SensorNoise, noise_from_spec, tukey_lambda_variance

TOLERANCE = 0.10
DARK = (8, 512, 512)  # frames, rows, columns of the dark-frame stack


def dark_frames(model: SensorNoise, shape=DARK, seed: int = 0) -> np.ndarray:
    return model.raw_dn(np.zeros(shape, np.float32), np.random.default_rng(seed), bayer=True).astype(np.float64)


def black_level(dark: np.ndarray) -> float:
    return float(dark.mean())


def without_rows(dark: np.ndarray) -> np.ndarray:
    return dark - dark.mean(-1, keepdims=True)


def row_std(dark: np.ndarray) -> float:
    n, h, w = dark.shape
    rows = dark.mean(-1).reshape(n, h // 2, 2)  # a Bayer row holds two channels: one offset per parity
    rows = rows - rows.mean(1, keepdims=True)
    within = without_rows(dark).var(-1, ddof=1).mean()
    variance = rows.var() * rows.shape[1] / (rows.shape[1] - 1) - within / w
    return float(np.sqrt(max(variance, 0.0)))


def gaussian_std(dark: np.ndarray) -> float:
    w = dark.shape[-1]
    variance = without_rows(dark).var() * w / (w - 1) - 1.0 / 12.0
    return float(np.sqrt(max(variance, 0.0)))


def tukey_lambda_fit(dark: np.ndarray) -> tuple[float, float]:
    """(shape, scale) by the probability-plot correlation: sorted samples against the Tukey-lambda
    quantiles of their order statistics' medians (Filliben's approximation)."""
    x = np.sort(without_rows(dark).ravel())
    n = len(x)
    m = (np.arange(1, n + 1) - 0.3175) / (n + 0.365)
    m[-1] = 0.5 ** (1.0 / n)
    m[0] = 1.0 - m[-1]
    low, high = np.log(m), np.log1p(-m)

    def quantiles(lam: float) -> np.ndarray:
        return low - high if lam == 0 else (np.expm1(lam * low) - np.expm1(lam * high)) / lam

    def minus_r(lam: float) -> float:
        return -np.corrcoef(quantiles(lam), x)[0, 1]

    lam = optimize.minimize_scalar(minus_r, bounds=(-0.45, 1.0), method="bounded", options={"xatol": 1e-4}).x
    slope = np.polyfit(quantiles(lam), x, 1)[0]
    return float(lam), float(slope)


def photon_transfer_gain(model: SensorNoise, electrons: list[float], seed: int = 1) -> float:
    """K: the slope of variance against mean (DN above black) of flat frames of ``electrons`` mean
    photo-electrons each."""
    means, variances = [], []
    for i, level in enumerate(electrons):
        flat = replace(model, photons=level / model.quantum_efficiency)
        frames = flat.raw_dn(np.full((2, 256, 512), 255.0, np.float32), np.random.default_rng([seed, i]), bayer=True)
        frames = frames.astype(np.float64) - model.black_level
        means.append(frames.mean())
        variances.append(frames.var())
    return float(np.polyfit(means, variances, 1)[0])


def published(sensor: str, iso: int, read: str) -> dict[str, float]:
    """The figures of :data:`lburst.noise.SENSORS` a calibration of ``sensor`` at ``iso`` measures."""
    preset, figures = SENSORS[sensor], SENSORS[sensor].isos[iso]
    out = {
        "black level": preset.black_level + figures.black_bias,
        "row noise": figures.row_std,
        "gain K": figures.gain,
    }
    if read == "gauss":
        out["Gaussian read noise"] = figures.read_std
    else:
        out["Tukey-lambda shape"], out["Tukey-lambda scale"] = figures.tl_shape, figures.tl_scale
    if figures.black_bias:
        out["black bias"] = figures.black_bias
    return out


def calibrate(model: SensorNoise, figures: dict[str, float], dark_shape=DARK) -> dict[str, float]:
    """What a calibration measures of ``model``'s dark and flat frames (module docstring), for each
    of the published ``figures`` (which also set the flat frames' exposures: shot-noise variance 1,
    3, 10 and 30 times the dark variance)."""
    dark = dark_frames(model, dark_shape)
    if "Gaussian read noise" in figures:
        read_var = figures["Gaussian read noise"] ** 2
    else:
        read_var = figures["Tukey-lambda scale"] ** 2 * tukey_lambda_variance(figures["Tukey-lambda shape"])
    dark_var = read_var + figures["row noise"] ** 2
    electrons = [f * dark_var / figures["gain K"] ** 2 for f in (1.0, 3.0, 10.0, 30.0)]
    out = {
        "black level": black_level(dark),
        "row noise": row_std(dark),
        "gain K": photon_transfer_gain(model, electrons),
    }
    if "Gaussian read noise" in figures:
        out["Gaussian read noise"] = gaussian_std(dark)
    if "Tukey-lambda shape" in figures:
        out["Tukey-lambda shape"], out["Tukey-lambda scale"] = tukey_lambda_fit(dark)
    if "black bias" in figures:
        out["black bias"] = out["black level"] - model.black_level
    return out


def close(value: float, figure: float) -> bool:
    return abs(value - figure) <= TOLERANCE * abs(figure)


PRESETS = ["imx686@6400", "imx686@6400,read=tl", "a7s2@100", "a7s2@1600", "a7s2@6400", "a7s2@25600"]


@pytest.mark.parametrize("preset", PRESETS)
def test_a_calibration_of_the_simulated_sensor_recovers_the_published_figures(preset):
    model = noise_from_spec(f"sensor:{preset}")
    figures = published(model.sensor, model.iso, model.read)
    measured = calibrate(model, figures)
    off = {k: (measured[k], figures[k]) for k in figures if not close(measured[k], figures[k])}
    assert not off, f"{preset}: (recovered, published) more than 10 % apart: {off}"


@pytest.mark.parametrize("iso", [100, 1600, 6400, 25600])
def test_the_a7s2_gaussian_and_tukey_lambda_figures_describe_the_same_dark_frames(iso):
    """PMN's Gaussian read noise of the A7S2 is the std of the dark frames its Tukey-lambda fit draws."""
    model = SensorNoise.preset("a7s2", iso)
    assert model.read == "tl"
    assert close(gaussian_std(dark_frames(model, (2, 512, 512))), model.read_std)
    assert close(model.tl_scale * np.sqrt(tukey_lambda_variance(model.tl_shape)), model.read_std)


def _gaussian_instead_of_tukey_lambda(model: SensorNoise) -> SensorNoise:
    return replace(model, read="gauss", read_std=float(np.sqrt(model.read_variance)))  # the same variance


# (preset, term dropped, how, the measurement that must then miss its published figure)
ABLATIONS = [
    ("imx686@6400", "shot noise", dict(shot_noise=False), "gain K"),
    ("imx686@6400", "row noise", dict(row_std=0.0), "row noise"),
    ("imx686@6400", "Gaussian read noise", dict(read_std=0.0), "Gaussian read noise"),
    ("imx686@6400", "black bias", dict(black_bias=0.0), "black bias"),
    ("imx686@6400", "black level", dict(black_level=0), "black level"),
    ("a7s2@6400", "shot noise", dict(shot_noise=False), "gain K"),
    ("a7s2@6400", "row noise", dict(row_std=0.0), "row noise"),
    ("a7s2@6400", "Tukey-lambda read noise", dict(tl_scale=0.0), "Tukey-lambda scale"),
    ("a7s2@6400", "Tukey-lambda shape", _gaussian_instead_of_tukey_lambda, "Tukey-lambda shape"),
    ("a7s2@6400", "black level", dict(black_level=0), "black level"),
]


@pytest.mark.parametrize("preset, term, drop, measurement", ABLATIONS, ids=[f"{a[0]}-{a[1]}" for a in ABLATIONS])
def test_each_measurement_misses_its_figure_when_its_noise_term_is_dropped(preset, term, drop, measurement):
    model = noise_from_spec(f"sensor:{preset}")
    figures = published(model.sensor, model.iso, model.read)
    dropped = drop(model) if callable(drop) else replace(model, **drop)
    value = calibrate(dropped, figures, (2, 512, 512))[measurement]
    assert not close(value, figures[measurement]), f"{term} dropped, yet {measurement} {value:.4g} is within 10 %"


def test_raw_values_are_whole_dn_of_the_sensors_bit_depth_and_saturate_at_white():
    model = SensorNoise.preset("imx686", 6400, photons=400.0)  # white at 2,100 DN: beyond the 10-bit range
    raw = model.raw_dn(np.full((64, 64), 255.0, np.float32), np.random.default_rng(0), bayer=True)
    assert raw.dtype == np.float32 and np.array_equal(raw, np.round(raw))
    assert raw.max() == model.white_level == 1023 and raw.min() >= 0
    dark = model.raw_dn(np.zeros((64, 64, 3), np.float32), np.random.default_rng(0))
    assert dark.shape == (64, 64, 3) and abs(dark.mean() - 64) < 1.5


@pytest.mark.parametrize("spec", ["sensor:imx686@6400", "sensor:a7s2@6400,photons=5,read=gauss"])
def test_the_8_bit_frame_keeps_the_mean_and_has_the_model_variance(spec):
    model = noise_from_spec(spec)
    levels = np.array([40.0, 120.0, 200.0], np.float32)
    image = np.broadcast_to(levels, (2, 300, 300, 3)).copy()
    out = model(image, np.random.default_rng(3))
    mean, var = model.expected_mean_var(levels)
    np.testing.assert_allclose(out.reshape(-1, 3).mean(0), mean, rtol=0.02, atol=0.5)
    np.testing.assert_allclose(out.reshape(-1, 3).var(0), var, rtol=0.05)


def test_noise_comes_from_the_generator_alone():
    model = noise_from_spec("sensor:a7s2@3200,photons=10")
    img = np.random.default_rng(0).uniform(0, 255, (2, 40, 40, 3)).astype(np.float32)
    np.testing.assert_array_equal(model(img, np.random.default_rng(7)), model(img, np.random.default_rng(7)))
    assert not np.array_equal(model(img, np.random.default_rng(7)), model(img, np.random.default_rng(8)))


@pytest.mark.parametrize(
    "spec, canonical",
    [
        ("sensor:imx686@6400", "sensor:imx686@6400,photons=20"),
        ("lowlight:imx686@6400,photons=5", "sensor:imx686@6400,photons=5"),
        ("sensor:IMX686@6400,photons=night,read=tl", "sensor:imx686@6400,photons=20,read=tl"),
        ("sensor:a7s2@25600,photons=moonless", "sensor:a7s2@25600,photons=5"),
        ("sensor:a7s2@800,read=gauss,photons=12.5", "sensor:a7s2@800,photons=12.5,read=gauss"),
    ],
)
def test_sensor_specs_parse_to_a_canonical_spec(spec, canonical):
    model = noise_from_spec(spec)
    assert model.spec == canonical and noise_from_spec(canonical) == model


@pytest.mark.parametrize(
    "spec",
    [
        "sensor:imx686",
        "sensor:imx686@",
        "sensor:imx999@6400",
        "sensor:imx686@100",
        "sensor:a7s2@6400,photons=0",
        "sensor:a7s2@6400,photons=nan",
        "sensor:a7s2@6400,photons=abc",
        "sensor:a7s2@6400,read=poisson",
        "sensor:a7s2@6400,iso=3",
        "sensor:a7s2@6400,photons=5,photons=6",
        "sensor:a7s2@6400,photons",
        "sensor:",
    ],
)
def test_bad_sensor_specs_are_one_line_errors_naming_the_spec(spec):
    with pytest.raises(ValueError) as err:
        noise_from_spec(spec)
    message = str(err.value)
    assert spec in message and "\n" not in message


def test_every_preset_is_a_valid_model():
    for name, sensor in SENSORS.items():
        for iso in sensor.isos:
            model = SensorNoise.preset(name, iso)
            assert model.spec == f"sensor:{name}@{iso},photons=20"
            assert np.isfinite(model.read_variance) and model.counts_at_white > 0


def test_a_sensor_flights_dng_holds_the_sensors_raw_values_and_its_video_the_camera_processing(tmp_path, monkeypatch):
    pytest.importorskip("tifffile")
    rawpy = pytest.importorskip("rawpy")
    from lburst.burst.raw import read_dng
    from lburst.scenes import flight_recording
    from lburst.scenes.night_flight import NightFlightConfig

    radiance = np.random.default_rng(0).uniform(0, 200, (48, 64, 3)).astype(np.float32)

    def rendered(cfg, progress, desc, indices=None):  # a flat random scene instead of the city (fast)
        indices = range(flight_recording.frame_count(cfg)) if indices is None else indices
        return ((j, j / flight_recording.fps(cfg), radiance) for j in indices)

    monkeypatch.setattr(flight_recording, "_rendered", rendered)
    cfg = NightFlightConfig(n_bursts=2, width=64, height=48, noise="sensor:imx686@6400,photons=100", burst_spacing=1.0)
    sensor = noise_from_spec(cfg.noise)
    folder = flight_recording.write_flight_dng(tmp_path / "dng", cfg, progress=False)
    cfa, white = flight_recording.raw_frame(cfg, radiance, np.random.default_rng([cfg.seed, 3, 1]))
    with rawpy.imread(str(folder / "frame_000001.dng")) as raw:
        assert np.array_equal(raw.raw_image_visible, cfa)  # the very raw values, 10-bit, black level 64
        assert raw.white_level == white == 1023 and list(raw.black_level_per_channel) == [64] * 4
    assert read_dng(folder / "frame_000001.dng").dtype == np.uint16
    rgb = flight_recording.camera_isp(cfa, sensor)
    assert rgb.dtype == np.uint8 and abs(rgb.mean() - radiance.mean()) < 3  # white at 524 DN: no clipping
    assert np.array_equal(flight_recording.camera_frame(cfg, radiance, 1), rgb)  # the video's frame


def test_simulate_burst_takes_a_sensor_spec(tmp_path, capsys):
    from lburst.cli import main

    image = np.random.default_rng(0).integers(0, 255, (48, 64, 3), np.uint8)
    from lburst.burst.io import write_image

    write_image(tmp_path / "photo.png", image)
    code = main(
        [
            "simulate",
            "burst",
            str(tmp_path / "photo.png"),
            "--out",
            str(tmp_path / "b"),
            "--noise",
            "sensor:a7s2@6400,photons=30",
        ]
    )
    assert code == 0 and "noise sensor:a7s2@6400,photons=30" in capsys.readouterr().out
    assert (
        main(
            ["simulate", "burst", str(tmp_path / "photo.png"), "--out", str(tmp_path / "c"), "--noise", "sensor:a7s2@7"]
        )
        == 2
    )
    assert "bad noise spec 'sensor:a7s2@7'" in capsys.readouterr().err
