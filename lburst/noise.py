"""Noise models for simulated low-light images.

A noise model is a callable ``noise(image, rng) -> noisy`` taking a float32 image on
the 0..255 scale (any shape ``(..., 3)``) and a ``numpy.random.Generator``, and
returning a noisy float32 image on the same scale, *not* clipped or rounded (the
caller does that).  Models are named by spec strings (:func:`noise_from_spec`):
``none``, ``gaussian:STD``, ``gaussian-var:V``, ``lowlight:PHOTONS`` or a preset name
such as ``lowlight:night``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

#: The network's input normalisation (RGB on 0..1): ImageNet's mean and std.  Kept here,
#: free of torch, because ``gaussian-var:V`` noise is a variance in that normalised space.
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


class NoiseModel(Protocol):
    spec: str

    def __call__(self, image: np.ndarray, rng: np.random.Generator) -> np.ndarray: ...


@dataclass(frozen=True)
class NoNoise:
    """The identity: a clean image."""

    @property
    def spec(self) -> str:
        return "none"

    def __call__(self, image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return np.asarray(image, np.float32)


@dataclass(frozen=True)
class GaussianNoise:
    """Additive Gaussian noise of standard deviation ``std`` on the 0..255 scale
    (one value, or one per RGB channel)."""

    std: float | tuple[float, float, float]

    @classmethod
    def from_normalized_variance(cls, variance: float) -> "GaussianNoise":
        """The paper's noise: variance ``variance`` on ImageNet-normalised values
        ``(x / 255 - mean) / std_c``, i.e. std ``sqrt(variance) * std_c * 255`` per channel."""
        if variance < 0:
            raise ValueError(f"noise variance must be >= 0, got {variance}")
        return cls(tuple(float(np.sqrt(variance) * s * 255.0) for s in IMAGENET_STD))

    @property
    def spec(self) -> str:
        if isinstance(self.std, tuple):
            variances = {round((s / (c * 255.0)) ** 2, 9) for s, c in zip(self.std, IMAGENET_STD)}
            if len(variances) == 1:
                return f"gaussian-var:{variances.pop():g}"
            return "gaussian:" + "/".join(f"{s:g}" for s in self.std)
        return f"gaussian:{self.std:g}"

    def __call__(self, image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        image = np.asarray(image, np.float32)
        std = np.asarray(self.std, np.float32)
        return image + rng.standard_normal(image.shape, dtype=np.float32) * std


@dataclass(frozen=True)
class LowLightNoise:
    """Physically based sensor noise for a dim scene.

    The 0..255 input is taken as linear scene radiance relative to white (after
    decoding a display gamma ``gamma`` when it is not 1).  Per pixel and channel:
    photo-electrons ``e ~ Poisson(photons * quantum_efficiency * I)`` (shot noise),
    plus read noise ``Normal(0, read_noise_e)``, clipped at ``full_well_e``,
    quantised by an ``adc_bits`` converter of ``gain_e_per_adu`` electrons per
    digital number (above a black level, so read noise may go below zero until the
    caller clips the final image), then scaled back so that the mean signal is
    preserved: ``out = ADU * gain / (photons * QE) * 255`` (and the gamma re-applied).

    Attributes:
        photons: mean photons reaching a pixel at white during the exposure
            (about 10-50 for a short exposure at millilux).
        quantum_efficiency: fraction of photons converted to electrons.
        read_noise_e: read noise, electrons rms.
        full_well_e: full-well capacity, electrons.
        adc_bits: converter resolution.
        gain_e_per_adu: electrons per digital number (0.5: a high-ISO setting, as
            used at night).
        gamma: display gamma of the input and output (1 = linear).
    """

    photons: float
    quantum_efficiency: float = 0.6
    read_noise_e: float = 2.0
    full_well_e: float = 10000.0
    adc_bits: int = 12
    gain_e_per_adu: float = 0.5
    gamma: float = 1.0

    PRESETS = {  # photons at white during one short burst frame
        "dusk": 200.0,
        "night": 20.0,
        "moonless": 5.0,
    }

    def __post_init__(self) -> None:
        if self.photons <= 0 or self.quantum_efficiency <= 0:
            raise ValueError("photons and quantum_efficiency must be positive")

    @classmethod
    def preset(cls, name: str) -> "LowLightNoise":
        """``dusk`` (200 photons at white), ``night`` (20) or ``moonless`` (5)."""
        if name not in cls.PRESETS:
            raise ValueError(f"unknown low-light preset {name!r}; presets: {', '.join(cls.PRESETS)}")
        return cls(photons=cls.PRESETS[name])

    @property
    def spec(self) -> str:
        for name, photons in self.PRESETS.items():
            if self == LowLightNoise(photons):
                return f"lowlight:{name}"
        if self == LowLightNoise(self.photons):
            return f"lowlight:{self.photons:g}"
        return repr(self)  # non-default sensor parameters have no short spec

    def _electrons_per_unit(self) -> float:
        return self.photons * self.quantum_efficiency

    @property
    def counts_at_white(self) -> float:
        """Mean converter counts (above the black level) of a white pixel."""
        return self._electrons_per_unit() / self.gain_e_per_adu

    def expected_mean_var(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of the output on the 0..255 scale (gamma 1, no clipping):
        mean = image; variance = (e + read^2 + gain^2 / 12) * (255 / (photons * QE))^2."""
        image = np.asarray(image, np.float64)
        electrons = self._electrons_per_unit() * image / 255.0
        scale = 255.0 / self._electrons_per_unit()
        variance = (electrons + self.read_noise_e**2 + self.gain_e_per_adu**2 / 12.0) * scale**2
        return image, variance

    def raw_counts(self, image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The converter's digital numbers above the black level (float32, read noise can make
        them negative; at most ``2**adc_bits - 1``) for a 0..255 image: what a RAW file stores,
        before the black level is added."""
        linear = np.asarray(image, np.float32) / 255.0
        if self.gamma != 1.0:
            linear = np.clip(linear, 0, 1) ** self.gamma
        electrons = rng.poisson(np.clip(linear, 0, None) * self._electrons_per_unit()).astype(np.float32)
        electrons += rng.standard_normal(electrons.shape, dtype=np.float32) * self.read_noise_e
        electrons = np.minimum(electrons, self.full_well_e)
        return np.minimum(np.round(electrons / self.gain_e_per_adu), 2**self.adc_bits - 1)

    def __call__(self, image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        adu = self.raw_counts(image, rng)
        out = adu / self.counts_at_white
        if self.gamma != 1.0:
            out = np.clip(out, 0, None) ** (1.0 / self.gamma)
        return (out * 255.0).astype(np.float32)


def noise_from_spec(spec: str) -> NoiseModel:
    """Parse ``none``, ``gaussian:STD``, ``gaussian-var:V``, ``lowlight:PHOTONS`` or
    ``lowlight:PRESET`` (presets: see :meth:`LowLightNoise.preset`)."""
    name, _, arg = spec.strip().partition(":")
    parsers: dict[str, Callable[[str], NoiseModel]] = {
        "gaussian": lambda a: GaussianNoise(float(a)),
        "gaussian-var": lambda a: GaussianNoise.from_normalized_variance(float(a)),
        "lowlight": lambda a: LowLightNoise.preset(a) if a in LowLightNoise.PRESETS else LowLightNoise(float(a)),
    }
    if name == "none" and not arg:
        return NoNoise()
    if name not in parsers or not arg:
        raise ValueError(
            f"bad noise spec {spec!r}: use none, gaussian:STD, gaussian-var:V, lowlight:PHOTONS or "
            f"lowlight:{{{','.join(LowLightNoise.PRESETS)}}}"
        )
    try:
        return parsers[name](arg)
    except ValueError as exc:
        raise ValueError(f"bad noise spec {spec!r}: {exc}") from exc
