"""Noise parameters are finite and bounded, refused where the spec is parsed with one line naming
the spec and the value: gaussian:nan wrote black frames and exited 0, gaussian:inf saturated,
lowlight:nan and photons=1e30 ended in NumPy's 'lam value too large'."""

import math

import numpy as np
import pytest

from lburst.cli import main
from lburst.noise import (
    MAX_PHOTONS,
    MAX_STD,
    MAX_VARIANCE,
    GaussianNoise,
    LowLightNoise,
    SensorNoise,
    noise_from_spec,
)
from lburst.scenes.night_flight import NightFlightConfig

BAD = [
    ("gaussian:nan", "nan"),
    ("gaussian:inf", "inf"),
    ("gaussian:-inf", "-inf"),
    ("gaussian:-5", "-5"),
    ("gaussian:1e300", "1e+300"),
    ("gaussian-var:nan", "nan"),
    ("gaussian-var:inf", "inf"),
    ("gaussian-var:-0.1", "-0.1"),
    ("gaussian-var:1e30", "1e+30"),
    ("lowlight:nan", "nan"),
    ("lowlight:inf", "inf"),
    ("lowlight:1e30", "1e+30"),
    ("lowlight:0", "0"),
    ("sensor:imx686@6400,photons=1e30", "1e+30"),
    ("sensor:imx686@6400,photons=nan", "nan"),
    ("sensor:a7s2@6400,photons=inf", "inf"),
    ("lowlight:imx686@6400,photons=1e20", "1e+20"),
]


@pytest.mark.parametrize("spec, value", BAD)
def test_a_non_finite_or_absurd_noise_parameter_is_refused_naming_spec_and_value(spec, value):
    with pytest.raises(ValueError) as err:
        noise_from_spec(spec)
    message = str(err.value)
    assert message.startswith(f"bad noise spec {spec!r}: ") and message.endswith(f"got {value}"), message
    assert "\n" not in message


@pytest.mark.parametrize("spec", ["lowlight:1e30", "sensor:imx686@6400,photons=1e30", "gaussian:1e300"])
def test_the_refusal_of_a_finite_value_names_the_bound(spec):
    with pytest.raises(ValueError, match=r"<= (1e\+06|10000)"):
        noise_from_spec(spec)


def test_the_bounds_are_usable_values():
    image = np.full((8, 8, 3), 128.0, np.float32)
    for spec in (f"gaussian:{MAX_STD:g}", f"gaussian-var:{MAX_VARIANCE:g}", f"lowlight:{MAX_PHOTONS:g}"):
        assert np.isfinite(noise_from_spec(spec)(image, np.random.default_rng(0))).all()
    assert np.isfinite(
        noise_from_spec(f"sensor:a7s2@50,photons={MAX_PHOTONS:g}")(image, np.random.default_rng(0))
    ).all()


def test_the_models_refuse_non_finite_parameters_in_python_too():
    for make in (
        lambda: GaussianNoise(math.nan),
        lambda: GaussianNoise((1.0, math.inf, 2.0)),
        lambda: GaussianNoise.from_normalized_variance(math.nan),
        lambda: LowLightNoise(math.nan),
        lambda: LowLightNoise(20.0, quantum_efficiency=math.nan),
        lambda: LowLightNoise(20.0, gamma=math.inf),
        lambda: SensorNoise.preset("imx686", 6400, photons=1e30),
    ):
        with pytest.raises(ValueError, match="must be"):
            make()


@pytest.mark.parametrize("spec", ["lowlight:night", "sensor:imx686@6400,photons=20", "sensor:a7s2@50,read=tl"])
def test_an_image_far_brighter_than_white_saturates_instead_of_failing(spec):
    """An exposure gain of 1e30 asked NumPy for a Poisson mean it refuses ('lam value too large')."""
    noisy = noise_from_spec(spec)(np.full((4, 4, 3), 255e30, np.float32), np.random.default_rng(0))
    assert np.isfinite(noisy).all()


def test_a_flight_with_nan_noise_is_refused_before_the_city_is_built():
    with pytest.raises(ValueError, match="bad noise spec 'gaussian:nan'"):
        NightFlightConfig(noise="gaussian:nan")


@pytest.mark.parametrize("command", [["simulate", "burst"], ["simulate", "flight", "--bursts", "2"]])
def test_simulate_with_nan_noise_is_one_line_and_writes_nothing(tmp_path, capsys, command):
    out = tmp_path / "out"
    assert main([*command, "--noise", "gaussian:nan", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(
        "bad noise spec 'gaussian:nan': the standard deviation must be a finite number >= 0 and <= 10000, got nan"
    )
    assert "\n" not in err and not out.exists()
