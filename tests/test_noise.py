"""Noise models: their statistics match their definitions."""

import numpy as np
import pytest

from lburst.noise import GaussianNoise, LowLightNoise, NoNoise, noise_from_spec


def test_gaussian_std_on_the_0_255_scale():
    rng = np.random.default_rng(0)
    img = np.full((200, 200, 3), 100.0, np.float32)
    out = GaussianNoise(25.0)(img, rng)
    assert out.std() == pytest.approx(25.0, rel=0.01) and out.mean() == pytest.approx(100.0, abs=0.2)


def test_normalized_variance_is_the_variance_after_imagenet_normalisation():
    rng = np.random.default_rng(1)
    img = np.full((300, 300, 3), 120.0, np.float32)
    out = GaussianNoise.from_normalized_variance(0.45)(img, rng)
    normalised = (out / 255.0 - np.array([0.485, 0.456, 0.406])) / np.array([0.229, 0.224, 0.225])
    np.testing.assert_allclose(normalised.reshape(-1, 3).var(0), 0.45, rtol=0.02)


@pytest.mark.parametrize("photons", [5.0, 200.0])
def test_low_light_mean_and_variance_match_the_formula(photons):
    model = LowLightNoise(photons=photons, read_noise_e=1.5)
    rng = np.random.default_rng(2)
    levels = np.array([60.0, 150.0, 240.0], np.float32)
    img = np.broadcast_to(levels, (400, 400, 3)).copy()
    out = model(img, rng)
    mean, var = model.expected_mean_var(levels)
    np.testing.assert_allclose(out.reshape(-1, 3).mean(0), mean, rtol=0.01)
    np.testing.assert_allclose(out.reshape(-1, 3).var(0), var, rtol=0.03)


def test_darker_scenes_are_noisier_relative_to_signal():
    dusk, night = LowLightNoise.preset("dusk"), LowLightNoise.preset("night")
    assert night.expected_mean_var(np.array([128.0]))[1] > dusk.expected_mean_var(np.array([128.0]))[1]


def test_noise_is_deterministic_given_a_seed():
    img = np.random.default_rng(0).uniform(0, 255, (50, 50, 3)).astype(np.float32)
    for model in (GaussianNoise(10.0), LowLightNoise.preset("night")):
        np.testing.assert_array_equal(model(img, np.random.default_rng(5)), model(img, np.random.default_rng(5)))


@pytest.mark.parametrize("spec", ["none", "gaussian:50", "gaussian-var:0.45", "lowlight:night", "lowlight:30"])
def test_specs_round_trip(spec):
    assert noise_from_spec(spec).spec == spec


@pytest.mark.parametrize("spec", ["gaussian", "gaussian:abc", "poisson:3", "lowlight:starlight", ""])
def test_bad_specs_are_errors(spec):
    with pytest.raises(ValueError, match="noise spec|preset"):
        noise_from_spec(spec)


def test_none_is_the_identity():
    img = np.arange(12, dtype=np.float32).reshape(2, 2, 3)
    np.testing.assert_array_equal(NoNoise()(img, np.random.default_rng(0)), img)
