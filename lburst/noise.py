"""Noise models for simulated low-light images.

A noise model is a callable ``noise(image, rng) -> noisy`` taking a float32 image on
the 0..255 scale (any shape ``(..., 3)``) and a ``numpy.random.Generator``, and
returning a noisy float32 image on the same scale, *not* clipped or rounded (the
caller does that).  Models are named by spec strings (:func:`noise_from_spec`):
``none``, ``gaussian:STD``, ``gaussian-var:V``, ``lowlight:PHOTONS``, a preset name
such as ``lowlight:night``, or a calibrated camera sensor, ``sensor:SENSOR@ISO`` such as
``sensor:imx686@6400,photons=20`` (:class:`SensorNoise`, ``docs/noise.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from lburst.errors import LBurstValueError
from lburst.normalization import IMAGENET_MEAN, IMAGENET_STD  # noqa: F401  (re-exported: gaussian-var:V is in that space)
from lburst.numbers import check_real

#: the largest standard deviation of ``gaussian:STD`` on the 0..255 scale: 40 times the whole
#: range, far past noise that leaves nothing of the image (float32 would overflow near 1e38)
MAX_STD = 10_000.0
#: the largest variance of ``gaussian-var:V`` (a std of 7,400 on the 0..255 scale)
MAX_VARIANCE = 1_000.0
#: the most photons at white of ``lowlight:PHOTONS`` and ``photons=P``: daylight gives a pixel about
#: 1e4-1e5 in a short frame, and the sensors clip (full well, converter) from a few thousand on; a
#: bound keeps NumPy's Poisson draw (which fails near 1e19) and the arithmetic finite
MAX_PHOTONS = 1e6
#: the largest mean of a Poisson draw of photo-electrons: a brighter pixel (an ``exposure`` gain
#: far above 1) saturates the sensor long before, and NumPy refuses means near 1e19
MAX_ELECTRONS = 1e12


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

    def __post_init__(self) -> None:
        for std in self.std if isinstance(self.std, tuple) else (self.std,):
            check_real(std, "the standard deviation", 0, MAX_STD)

    @classmethod
    def from_normalized_variance(cls, variance: float) -> "GaussianNoise":
        """The paper's noise: variance ``variance`` on ImageNet-normalised values
        ``(x / 255 - mean) / std_c``, i.e. std ``sqrt(variance) * std_c * 255`` per channel."""
        variance = check_real(variance, "the noise variance", 0, MAX_VARIANCE)
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
        check_real(self.photons, "photons", 0, MAX_PHOTONS, low_open=True)
        check_real(self.quantum_efficiency, "quantum_efficiency", 0, 1, low_open=True)
        for name in ("read_noise_e", "full_well_e", "gain_e_per_adu", "gamma"):
            check_real(getattr(self, name), name, 0, low_open=name != "read_noise_e")

    @classmethod
    def preset(cls, name: str) -> "LowLightNoise":
        """``dusk`` (200 photons at white), ``night`` (20) or ``moonless`` (5)."""
        if name not in cls.PRESETS:
            raise LBurstValueError(f"unknown low-light preset {name!r}; presets: {', '.join(cls.PRESETS)}")
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
        mean = np.clip(linear * np.float32(self._electrons_per_unit()), 0, MAX_ELECTRONS)
        electrons = rng.poisson(mean).astype(np.float32)
        electrons += rng.standard_normal(electrons.shape, dtype=np.float32) * self.read_noise_e
        electrons = np.minimum(electrons, self.full_well_e)
        return np.minimum(np.round(electrons / self.gain_e_per_adu), 2**self.adc_bits - 1)

    def __call__(self, image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        adu = self.raw_counts(image, rng)
        out = adu / self.counts_at_white
        if self.gamma != 1.0:
            out = np.clip(out, 0, None) ** (1.0 / self.gamma)
        return (out * 255.0).astype(np.float32)


def tukey_lambda(rng: np.random.Generator, shape: tuple[int, ...], lam: float) -> np.ndarray:
    """Standard Tukey-lambda samples (shape ``lam``, scale 1) by inversion of ``u`` uniform in
    (0, 1): ``Q(u) = (u**lam - (1 - u)**lam) / lam``, ``log(u / (1 - u))`` (logistic) for ``lam = 0``."""
    u = np.clip(rng.random(shape), 2.0**-53, 1.0 - 2.0**-53)
    low, high = np.log(u), np.log1p(-u)
    if lam == 0:
        return (low - high).astype(np.float32)
    return ((np.expm1(lam * low) - np.expm1(lam * high)) / lam).astype(np.float32)


def tukey_lambda_variance(lam: float) -> float:
    """Variance of the standard Tukey-lambda distribution (finite for ``lam > -1/2``):
    ``pi**2 / 3`` at 0, else ``2 / lam**2 * (1 / (1 + 2 lam) - Gamma(lam + 1)**2 / Gamma(2 lam + 2))``."""
    if lam <= -0.5:
        return math.inf
    if abs(lam) < 1e-6:
        return math.pi**2 / 3.0
    ratio = math.exp(2.0 * math.lgamma(lam + 1.0) - math.lgamma(2.0 * lam + 2.0))
    return 2.0 / lam**2 * (1.0 / (1.0 + 2.0 * lam) - ratio)


@dataclass(frozen=True)
class SensorFigures:
    """Published noise figures of one camera at one ISO, in digital numbers (DN) of its raw files.

    Attributes:
        gain: system gain K, DN per photo-electron.
        read_std: Gaussian read noise (the Gaussian alternative to the Tukey-lambda fit), DN rms.
        tl_shape: Tukey-lambda read-noise shape lambda.
        tl_scale: Tukey-lambda read-noise scale sigma_TL, DN.
        row_std: row (banding) noise, DN rms of a row's common offset.
        black_bias: mean error of the black level, DN (the dark level is ``black_level + black_bias``).
        bias_std: spread of the black-level error, drawn per frame and Bayer channel, DN.
    """

    gain: float
    read_std: float
    tl_shape: float
    tl_scale: float
    row_std: float
    black_bias: float = 0.0
    bias_std: float = 0.0


@dataclass(frozen=True)
class SensorPreset:
    """A calibrated camera: its converter, black level, default read-noise law and figures per ISO."""

    adc_bits: int
    black_level: int
    read: str
    isos: dict[int, SensorFigures]
    source: str


def _imx686(gain: float, read_std: float) -> SensorFigures:
    """The IMX686 at system gain ``gain`` (DN/e-) with measured Gaussian read noise ``read_std``:
    row noise and the Tukey-lambda read noise from PMN's log-linear fits against log K
    (``get_camera_noisy_params()['IMX686']``, fitted over ISO 640-6400), the black-level error
    from ``get_camera_noisy_params_max()['IMX686_6400']['bias']``."""
    log_k = math.log(gain)
    return SensorFigures(
        gain=gain,
        read_std=read_std,
        tl_shape=0.102,
        tl_scale=math.exp(0.85187 * log_k + 0.07991),
        row_std=math.exp(0.87611 * log_k - 2.11455),
        black_bias=-0.56896687,
    )


def _a7s2(gain, lam, read_std, tl_scale, row_std, bias_std) -> SensorFigures:
    return SensorFigures(gain, read_std, lam, tl_scale, row_std, 0.0, bias_std)


#: Calibrated sensors for ``sensor:NAME@ISO`` (:class:`SensorNoise`).  Every figure is quoted from a
#: public calibration; the sources:
#:
#: - **imx686**: Sony IMX686, the 1/1.7" 64 MP phone sensor (a small drone's camera class): 10-bit
#:   raw, black level 64, white level 1023.  ISO 6400: K = 8.7425333 DN/e-, Gaussian read noise
#:   14.3036 DN (measured), from PMN: Feng, Wang, Xu, Fan, Liu, "Learnability Enhancement for
#:   Low-light Raw Denoising: Where Paired Real Data Meets Noise Modeling", ACM MM 2022, code
#:   github.com/megvii-research/PMN, ``data_process/process.py``, ``get_specific_noise_params()``
#:   (``'IMX686'['6400']``: ``K``, ``sigGs``; bit depth, white and black level from
#:   ``get_camera_noisy_params()['IMX686']``: ``q = 1/2**10``, ``wp = 1023``, ``bl = 64``).  Row
#:   noise sigma_r = exp(0.87611 ln K - 2.11455) = 0.807 DN and the Tukey-lambda read noise
#:   (lambda = 0.102, sigma_TL = exp(0.85187 ln K + 0.07991) = 6.87 DN) from the log-linear fits of
#:   the same file (``get_camera_noisy_params()['IMX686']``, ``sigRk/sigRb``, ``sigTLk/sigTLb``,
#:   ``lam``); black-level error -0.569 DN (``get_camera_noisy_params_max()['IMX686_6400']['bias']``).
#:   Default read noise: Gaussian (the measured figure).
#: - **a7s2**: Sony A7S II, full frame: 14-bit raw, black level 512, white level 16383.  Per ISO
#:   (50-25600, in third stops, with the dual-gain switch between ISO 1600 and 2000): K, the
#:   Tukey-lambda shape and scale, the Gaussian read noise, the row noise and the spread of the
#:   black-level error (``Kmax``, ``lam``, ``sigTL``, ``sigGs``, ``sigR``, ``biassig``; mean
#:   ``bias`` 0), from PMN's per-ISO calibration of the A7S2 with the model of ELD (Wei, Fu, Yang,
#:   Huang, "A Physics-based Noise Formation Model for Extreme Low-light Raw Denoising", CVPR 2020,
#:   github.com/Vandermode/ELD), ``data_process/process.py``, ``get_camera_noisy_params_max()``
#:   (``'SonyA7S2_<ISO>'``).  ELD's own fits (``camera_params/release/SonyA7S2_params.npy``) are a
#:   binary file not quoted here.  Default read noise: Tukey-lambda (ELD's model).
SENSORS: dict[str, SensorPreset] = {
    "imx686": SensorPreset(
        adc_bits=10,
        black_level=64,
        read="gauss",
        isos={6400: _imx686(8.7425333, 14.303619546153575)},
        source="PMN (Feng et al., ACM MM 2022), megvii-research/PMN data_process/process.py",
    ),
    "a7s2": SensorPreset(
        adc_bits=14,
        black_level=512,
        read="tl",
        # ISO: K, lambda, sigma_gauss, sigma_TL, sigma_row, bias spread (PMN get_camera_noisy_params_max)
        isos={
            50: _a7s2(0.047815, 0.1474653, 1.0164667, 0.70727646, 0.13997398, 0.010093017),
            64: _a7s2(0.0612032, 0.13243394, 1.0509665, 0.71535635, 0.14346549, 0.008690166),
            80: _a7s2(0.076504, 0.1121489, 1.180899, 0.7799473, 0.19540153, 0.0107246125),
            100: _a7s2(0.09563, 0.14875287, 1.0067395, 0.70181876, 0.1391465, 0.007235429),
            125: _a7s2(0.1195375, 0.12904578, 1.0279676, 0.6961967, 0.14485553, 0.008026363),
            160: _a7s2(0.153008, 0.094135, 1.1293099, 0.7258587, 0.19755602, 0.0101351),
            200: _a7s2(0.19126, 0.07902429, 1.2926387, 0.8117464, 0.22815849, 0.011413908),
            250: _a7s2(0.239075, 0.051688068, 1.4345995, 0.8630922, 0.26271912, 0.013569083),
            320: _a7s2(0.306016, 0.040700804, 1.7481371, 1.0334468, 0.3097104, 0.017825918),
            400: _a7s2(0.38252, 0.0222538, 2.0595572, 1.1816813, 0.36209714, 0.021005306),
            500: _a7s2(0.47815, -0.0031342343, 2.3956928, 1.31772, 0.42528257, 0.02981831),
            640: _a7s2(0.612032, 0.002566592, 2.9662898, 1.6474211, 0.48839623, 0.10000693),
            800: _a7s2(0.76504, -0.008199721, 3.5475867, 1.9346539, 0.5723769, 0.025339302),
            1000: _a7s2(0.9563, -0.021061005, 4.2727833, 2.2795107, 0.6845563, 0.027911892),
            1250: _a7s2(1.195375, -0.032423194, 5.177596, 2.708437, 0.8177013, 0.03293372),
            1600: _a7s2(1.53008, -0.0441045, 6.29925, 3.2283993, 0.988786, 0.03877672),
            2000: _a7s2(1.9126, -0.012963797, 2.653871, 1.4356787, 0.33124214, 0.01570677),
            2500: _a7s2(2.39075, -0.027097283, 3.200225, 1.6897862, 0.38264316, 0.018728448),
            3200: _a7s2(3.06016, -0.034863412, 3.9193838, 2.0417721, 0.44543457, 0.021355819),
            4000: _a7s2(3.8252, -0.043700505, 4.8015847, 2.4629273, 0.52347374, 0.026152484),
            5000: _a7s2(4.7815, -0.053150143, 5.8995814, 2.9761007, 0.6190265, 0.058574405),
            6400: _a7s2(6.12032, -0.07517104, 7.1163535, 3.4502964, 0.7218788, 0.059074216),
            8000: _a7s2(7.6504, -0.08208357, 8.916516, 4.269624, 0.87760293, 0.084842026),
            10000: _a7s2(9.563, -0.073289566, 11.291476, 5.495318, 1.0522343, 0.107438326),
            12800: _a7s2(12.24064, -0.06495205, 14.245901, 7.038261, 1.2749791, 0.0944684),
            16000: _a7s2(15.3008, -0.060692135, 17.833515, 8.877547, 1.5559287, 0.09725099),
            20000: _a7s2(19.126, -0.060213074, 22.084776, 11.002351, 1.8810822, 0.4984733),
            25600: _a7s2(24.48128, -0.09089118, 25.853043, 12.175712, 2.2760193, 0.37568903),
        },
        source="PMN (Feng et al., ACM MM 2022) per-ISO calibration with ELD's model (Wei et al., CVPR 2020)",
    ),
}

READ_LAWS = ("gauss", "tl")
#: Photons at white of ``sensor:NAME@ISO`` without ``photons=``: ``lowlight:night``'s.
DEFAULT_SENSOR_PHOTONS = LowLightNoise.PRESETS["night"]


@dataclass(frozen=True)
class SensorNoise:
    """The raw noise of a calibrated camera sensor, after ELD's physics-based model (Wei et al.,
    CVPR 2020) with published figures (:data:`SENSORS`, ``docs/noise.md``).

    The 0..255 input is linear scene radiance relative to white (after decoding a display gamma
    ``gamma`` when it is not 1), ``photons`` photons at white during the exposure, as for
    :class:`LowLightNoise`.  A raw value, in digital numbers (DN), per pixel and channel::

        D = round(black_level + bias_c + K * Poisson(photons * QE * I) + N_read + N_row), clipped to [0, white]

    - shot noise through the system gain ``gain`` (K, DN per photo-electron);
    - read noise ``N_read``: Tukey-lambda of shape ``tl_shape`` and scale ``tl_scale``
      (``read='tl'``) or Gaussian of std ``read_std`` (``read='gauss'``), independent per pixel;
    - row noise ``N_row``: Gaussian of std ``row_std``, one value per row (and per colour
      channel of an RGB image);
    - black level ``black_level`` plus the per-channel black bias ``bias_c`` = ``black_bias[c]``
      + Gaussian of std ``bias_std`` drawn per frame and channel (Bayer channels R, G1, G2, B);
    - quantisation to whole DN of an ``adc_bits`` converter, clipped at 0 and at the white level
      ``2**adc_bits - 1`` (a bright exposure saturates: white radiance is ``counts_at_white`` DN
      above black).

    :meth:`raw_dn` gives these raw values (a Bayer mosaic for a DNG, or per RGB channel);
    calling the model gives the 8-bit-scale frame the simple camera processing of
    :class:`LowLightNoise` makes of them: ``(D - black_level) / counts_at_white * 255`` (the
    nominal black level subtracted, so the black bias stays in), gamma re-applied.  All
    randomness comes from the generator passed in.

    Attributes:
        gain, read_std, tl_shape, tl_scale, row_std, black_bias, bias_std: see
            :class:`SensorFigures` (``black_bias``: one value, or four for R, G1, G2, B).
        read: ``'tl'`` (Tukey-lambda) or ``'gauss'`` read noise.
        adc_bits: converter resolution (white level ``2**adc_bits - 1``).
        black_level: nominal black level, DN.
        photons: mean photons reaching a pixel at white during the exposure.
        quantum_efficiency: fraction of photons converted to electrons.
        gamma: display gamma of the input and output (1 = linear).
        shot_noise: ``False`` records the mean photo-electrons without their Poisson noise (an
            ablation; every other term can be dropped by zeroing its figure).
        sensor, iso: the preset it was made from (``sensor:SENSOR@ISO``), if any.
    """

    gain: float
    read_std: float
    tl_shape: float
    tl_scale: float
    row_std: float
    adc_bits: int
    black_level: int
    read: str = "gauss"
    black_bias: float | tuple[float, float, float, float] = 0.0
    bias_std: float = 0.0
    photons: float = DEFAULT_SENSOR_PHOTONS
    quantum_efficiency: float = 0.6
    gamma: float = 1.0
    shot_noise: bool = True
    sensor: str = ""
    iso: int = 0

    def __post_init__(self) -> None:
        bias = self.black_bias
        bias = (float(bias),) * 4 if np.ndim(bias) == 0 else tuple(float(b) for b in bias)
        object.__setattr__(self, "black_bias", bias)
        if len(bias) != 4 or not all(math.isfinite(b) for b in bias):
            raise LBurstValueError(f"black_bias must be one finite value or four (R, G1, G2, B), got {self.black_bias}")
        check_real(self.photons, "photons", 0, MAX_PHOTONS, low_open=True)
        if not 0 < self.quantum_efficiency <= 1 or not (math.isfinite(self.gain) and self.gain > 0):
            raise LBurstValueError("need 0 < quantum_efficiency <= 1 and a positive gain")
        if self.read not in READ_LAWS:
            raise LBurstValueError(f"read noise must be one of {', '.join(READ_LAWS)}, got {self.read!r}")
        for name in ("read_std", "tl_scale", "row_std", "bias_std"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise LBurstValueError(f"{name} must be a finite number >= 0, got {value}")
        if not self.tl_shape > -0.5:
            raise LBurstValueError(f"the Tukey-lambda shape must be > -0.5 (finite variance), got {self.tl_shape}")
        if not 1 <= self.adc_bits <= 16 or not 0 <= self.black_level < 2**self.adc_bits - 1:
            raise LBurstValueError("need 1 <= adc_bits <= 16 and 0 <= black_level < 2**adc_bits - 1")

    @classmethod
    def preset(
        cls, sensor: str, iso: int, photons: float = DEFAULT_SENSOR_PHOTONS, read: str | None = None
    ) -> "SensorNoise":
        """The calibrated ``sensor`` (a key of :data:`SENSORS`) at ``iso``, exposed with ``photons``
        photons at white; ``read`` (``'tl'`` or ``'gauss'``) defaults to the sensor's."""
        name = sensor.lower()
        if name not in SENSORS:
            raise LBurstValueError(f"unknown sensor {sensor!r}; sensors: {', '.join(SENSORS)}")
        preset = SENSORS[name]
        if iso not in preset.isos:
            raise LBurstValueError(f"{name} has no calibration at ISO {iso}; ISOs: {', '.join(map(str, preset.isos))}")
        figures = preset.isos[iso]
        return cls(
            gain=figures.gain,
            read_std=figures.read_std,
            tl_shape=figures.tl_shape,
            tl_scale=figures.tl_scale,
            row_std=figures.row_std,
            adc_bits=preset.adc_bits,
            black_level=preset.black_level,
            read=preset.read if read is None else read,
            black_bias=figures.black_bias,
            bias_std=figures.bias_std,
            photons=float(photons),
            sensor=name,
            iso=iso,
        )

    @property
    def spec(self) -> str:
        """``sensor:NAME@ISO,photons=P`` (``,read=...`` when not the sensor's default); ``repr`` when
        the figures are not a preset's."""
        if self.sensor in SENSORS and self.iso in SENSORS[self.sensor].isos:
            if SensorNoise.preset(self.sensor, self.iso, self.photons, self.read) == self:
                photons = f"{self.photons:g}" if float(f"{self.photons:g}") == self.photons else repr(self.photons)
                read = "" if self.read == SENSORS[self.sensor].read else f",read={self.read}"
                return f"sensor:{self.sensor}@{self.iso},photons={photons}{read}"
        return repr(self)

    @property
    def white_level(self) -> int:
        return 2**self.adc_bits - 1

    @property
    def counts_at_white(self) -> float:
        """Mean DN above the black level of a white pixel (before clipping)."""
        return self.photons * self.quantum_efficiency * self.gain

    @property
    def read_variance(self) -> float:
        """Variance of the read noise alone, DN^2: ``read_std**2`` or ``tl_scale**2`` times the
        standard Tukey-lambda variance."""
        if self.read == "gauss":
            return self.read_std**2
        return self.tl_scale**2 * tukey_lambda_variance(self.tl_shape)

    def expected_mean_var(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of the 8-bit-scale output (gamma 1, no clipping) of a flat 0..255
        ``image``: mean = image + mean bias; variance = (K^2 e + read + row^2 + bias_std^2 + 1/12)
        scaled by ``(255 / counts_at_white)^2``, ``e`` the mean photo-electrons."""
        image = np.asarray(image, np.float64)
        scale = 255.0 / self.counts_at_white
        electrons = self.photons * self.quantum_efficiency * image / 255.0
        dark = self.read_variance + self.row_std**2 + self.bias_std**2 + 1.0 / 12.0
        shot = self.gain**2 * electrons if self.shot_noise else 0.0
        return image + float(np.mean(self.black_bias)) * scale, (shot + dark) * scale**2

    def raw_dn(self, image: np.ndarray, rng: np.random.Generator, bayer: bool = False) -> np.ndarray:
        """The raw values (float32 whole DN, black level included, in ``[0, white_level]``) the sensor
        records of a 0..255 ``image``: a Bayer mosaic ``(..., H, W)`` (RGGB; ``bayer=True``, one
        colour per pixel, as a DNG stores it) or an RGB image ``(..., H, W, C)`` (one value per
        channel).  Leading axes are frames: each gets its own black bias draw."""
        image = np.asarray(image, np.float32)
        if image.ndim < (2 if bayer else 3):
            raise LBurstValueError(
                f"need a {'(..., H, W) mosaic' if bayer else '(..., H, W, C) image'}, got {image.shape}"
            )
        linear = image / np.float32(255.0)
        if self.gamma != 1.0:
            linear = np.clip(linear, 0, 1) ** self.gamma
        electrons = np.clip(linear * np.float32(self.photons * self.quantum_efficiency), 0, MAX_ELECTRONS)
        if self.shot_noise:
            electrons = rng.poisson(electrons)
        dn = electrons.astype(np.float32) * np.float32(self.gain)
        if self.read == "tl":
            if self.tl_scale:
                dn += tukey_lambda(rng, dn.shape, self.tl_shape) * np.float32(self.tl_scale)
        elif self.read_std:
            dn += rng.standard_normal(dn.shape, dtype=np.float32) * np.float32(self.read_std)
        if bayer:
            lead, (h, w) = dn.shape[:-2], dn.shape[-2:]
            if self.row_std:
                dn += rng.standard_normal(lead + (h, 1), dtype=np.float32) * np.float32(self.row_std)
            bias = np.broadcast_to(np.asarray(self.black_bias, np.float32), lead + (4,))
            if self.bias_std:
                bias = bias + rng.standard_normal(lead + (4,), dtype=np.float32) * np.float32(self.bias_std)
            rows, cols = np.indices((h, w))
            dn += bias[..., 2 * (rows % 2) + cols % 2]  # RGGB: R, G1 / G2, B
        else:
            lead, (h, channels) = dn.shape[:-3], (dn.shape[-3], dn.shape[-1])
            if self.row_std:
                dn += rng.standard_normal(lead + (h, 1, channels), dtype=np.float32) * np.float32(self.row_std)
            r, g1, g2, b = self.black_bias
            rgb = (r, (g1 + g2) / 2, b) if channels == 3 else (float(np.mean(self.black_bias)),) * channels
            bias = np.broadcast_to(np.asarray(rgb, np.float32), lead + (channels,))
            if self.bias_std:
                bias = bias + rng.standard_normal(lead + (channels,), dtype=np.float32) * np.float32(self.bias_std)
            dn += bias[..., None, None, :]
        dn += np.float32(self.black_level)
        return np.clip(np.round(dn), 0, self.white_level)

    def __call__(self, image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        dn = self.raw_dn(image, rng)
        out = (dn - np.float32(self.black_level)) / np.float32(self.counts_at_white)
        if self.gamma != 1.0:
            out = np.clip(out, 0, None) ** (1.0 / self.gamma)
        return (out * 255.0).astype(np.float32)


def sensor_from_spec(arg: str) -> SensorNoise:
    """``NAME@ISO[,photons=P][,read=tl|gauss]`` (``P`` a number or a ``lowlight`` preset name)."""
    head, *options = arg.split(",")
    name, at, iso = head.partition("@")
    if not at or not name or not iso.strip().isdigit():
        raise LBurstValueError(f"a sensor is NAME@ISO (sensors: {', '.join(SENSORS)}), got {head!r}")
    kwargs: dict = {}
    for option in options:
        key, eq, value = option.partition("=")
        key, value = key.strip(), value.strip()
        if not eq or key not in ("photons", "read") or key in kwargs:
            raise LBurstValueError(f"bad option {option!r}: use photons=P and read=tl|gauss, each at most once")
        if key == "photons":
            value = LowLightNoise.PRESETS.get(value) or float(value)
        kwargs[key] = value
    return SensorNoise.preset(name.strip(), int(iso), **kwargs)


def _lowlight(arg: str) -> NoiseModel:
    if "@" in arg:
        return sensor_from_spec(arg)
    return LowLightNoise.preset(arg) if arg in LowLightNoise.PRESETS else LowLightNoise(float(arg))


def noise_from_spec(spec: str) -> NoiseModel:
    """Parse ``none``, ``gaussian:STD``, ``gaussian-var:V``, ``lowlight:PHOTONS``,
    ``lowlight:PRESET`` (presets: see :meth:`LowLightNoise.preset`) or a calibrated sensor,
    ``sensor:NAME@ISO[,photons=P][,read=tl|gauss]`` (also written ``lowlight:NAME@ISO...``;
    :class:`SensorNoise`, :func:`sensor_from_spec`).  A bad spec is a one-line ``ValueError``
    naming it."""
    name, _, arg = spec.strip().partition(":")
    parsers: dict[str, Callable[[str], NoiseModel]] = {
        "gaussian": lambda a: GaussianNoise(float(a)),
        "gaussian-var": lambda a: GaussianNoise.from_normalized_variance(float(a)),
        "lowlight": _lowlight,
        "sensor": sensor_from_spec,
    }
    if name == "none" and not arg:
        return NoNoise()
    if name not in parsers or not arg:
        raise LBurstValueError(
            f"bad noise spec {spec!r}: use none, gaussian:STD, gaussian-var:V, lowlight:PHOTONS, "
            f"lowlight:{{{','.join(LowLightNoise.PRESETS)}}} or sensor:{{{','.join(SENSORS)}}}@ISO[,photons=P]"
        )
    try:
        return parsers[name](arg)
    except ValueError as exc:
        raise LBurstValueError(f"bad noise spec {spec!r}: {exc}") from exc
