"""RAW and 16-bit linear frames: reading DNG, and the brightness normalisation of dark recordings.

**Reading** (:func:`read_dng`): LibRaw (``rawpy``) subtracts the DNG's black level per
channel, scales by its white level (``value = (raw - black) / (white - black)``; LibRaw's
automatic maximum adjustment and auto-brightening are off), applies the as-shot white
balance and the DNG colour matrix, and demosaics (AHD).  The result is **linear** RGB
``(H, W, 3)`` uint16, 0..65535 for black..white.

**Normalisation** (:class:`Normalisation`): the networks were trained on 8-bit sRGB
photos, so a linear 16-bit frame is turned into what they saw:

1. ``x = linear / 65535`` (0..1, linear);
2. ``y = min(gain * x, 1)`` with one ``gain`` for the whole recording:
   ``gain = target / P`` where ``P`` is the ``percentile``-th percentile of the
   luminance (Rec. 709 weights) of the first burst's temporal mean, averaged over
   ``binning`` x ``binning`` pixel blocks, clamped to ``[1, max_gain]``; fixed for the
   recording, so every burst (and a resumed run) gets the same brightness.  The mean
   and the blocks average the noise away (a burst of N frames and 4x4 blocks: its
   standard deviation / sqrt(16 N)), so ``P`` is the scene's bright end and not the
   noise's: on a moonless frame (about 6 counts at white) the 99.5th percentile of
   single pixels is 2.1 times white, of the binned mean 1.0 times.  ``target`` is 0.94,
   the median of the same statistic over the training photos (``scripts/bright_end.py`` in the git history,
   ``git show 86fe777:scripts/bright_end.py``:
   0.938 over the 680 photos, a quarter of them under 0.83), so the bright end of a
   normalised recording sits where that of a typical training photo does;
3. ``curve='linear'`` (default): no tone curve, the gain alone, which is what a
   mean-preserving noisy 8-bit frame (the training noise, the video path) looks like;
   ``curve='srgb'``: the sRGB transfer curve (IEC 61966-2-1), whose steep foot (slope
   12.92) amplifies the read noise of the shadows; then rounding to uint8.

This is what the feature methods and COLMAP's images get.  8-bit frames (video,
8-bit PNG/JPEG) are already display-referred and pass unchanged.  ``gain='none'``
keeps the linear uint16 frames as they are (the extractors scale uint16 by
1/65535), which is what a dark RAW frame looks like without normalisation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lburst.burst.io import BurstError
from lburst.errors import LBurstValueError
from lburst.extras import require
from lburst.numbers import check_real

RAW_SUFFIXES = (".dng",)
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)


def read_dng(path: str | Path) -> np.ndarray:
    """A DNG file as linear RGB ``(H, W, 3)`` uint16 (module docstring); ``BurstError`` naming the file."""
    rawpy = require("rawpy", "reading DNG frames")

    path = Path(path)
    if not path.is_file():
        raise BurstError(f"{path}: no such file")
    problem = dng_problem(path)
    if problem:
        raise BurstError(f"{path}: {problem}")
    try:
        with rawpy.imread(str(path)) as raw:
            return raw.postprocess(
                gamma=(1, 1),
                no_auto_bright=True,
                output_bps=16,
                use_camera_wb=True,
                adjust_maximum_thr=0.0,
                user_flip=0,
                demosaic_algorithm=rawpy.DemosaicAlgorithm.AHD,
            )
    except BurstError:
        raise
    except (rawpy.LibRawError, OSError, ValueError) as err:
        raise BurstError(f"{path}: not a readable DNG ({type(err).__name__}: {err})") from err


def dng_problem(path: Path) -> str | None:
    """Why ``path`` is not a DNG LibRaw can develop as documented, or ``None``: it needs a
    ``DNGVersion`` tag and a raw image (main IFD or SubIFD) that is a CFA mosaic
    (``PhotometricInterpretation`` 32803 with ``CFARepeatPatternDim``/``CFAPattern``) or
    linear raw (34892).  LibRaw itself would guess a Bayer pattern for any grey TIFF."""
    tifffile = require("tifffile", "reading DNG frames")

    try:
        with tifffile.TiffFile(path) as tif:
            pages = list(tif.pages)
            for page in list(pages):
                pages += list(getattr(page, "pages", None) or [])
            if not pages or 50706 not in pages[0].tags:
                return "not a DNG (no DNGVersion tag)"
            for page in pages:
                photometric = int(page.tags[262].value) if 262 in page.tags else None
                if photometric == 34892 or (photometric == 32803 and 33421 in page.tags and 33422 in page.tags):
                    return None
            return (
                "DNG without a CFA image: no PhotometricInterpretation 32803 with CFARepeatPatternDim/CFAPattern tags"
            )
    except (tifffile.TiffFileError, OSError, ValueError, KeyError) as err:
        return f"not a readable DNG/TIFF ({err})"


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve of linear values in [0, 1] (float32 in, float32 out)."""
    linear = np.clip(linear, 0.0, 1.0)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(linear, 1 / 2.4) - 0.055).astype(np.float32)


@dataclass(frozen=True)
class Normalisation:
    """Brightness normalisation of linear 16-bit frames (module docstring).

    Attributes:
        gain: ``'auto'`` (from the percentile of the first burst), ``'none'`` (keep linear
            uint16) or a number (a fixed gain).
        percentile: which luminance percentile is mapped to ``target``.
        target: the linear value (0..1) the percentile is mapped to.
        max_gain: largest automatic gain.
        curve: ``'linear'`` or ``'srgb'`` tone curve after the gain.
        binning: block size (pixels) the burst's mean luminance is averaged over before
            the percentile (1: single pixels).
    """

    gain: str | float = "auto"
    percentile: float = 99.5
    target: float = 0.94
    max_gain: float = 4096.0
    curve: str = "linear"
    binning: int = 4

    def __post_init__(self) -> None:
        if isinstance(self.gain, str) and self.gain not in ("auto", "none"):
            try:
                object.__setattr__(self, "gain", float(self.gain))
            except ValueError:
                raise LBurstValueError(f"gain must be 'auto', 'none' or a number, got {self.gain!r}") from None
        if not isinstance(self.gain, str):
            check_real(self.gain, "raw gain", 0, low_open=True)
        if self.curve not in ("srgb", "linear"):
            raise LBurstValueError(f"curve must be 'srgb' or 'linear', got {self.curve!r}")
        if not 0 < self.percentile <= 100 or not 0 < self.target <= 1 or self.max_gain < 1:
            raise LBurstValueError("need 0 < percentile <= 100, 0 < target <= 1 and max_gain >= 1")
        if not isinstance(self.binning, int) or self.binning < 1:
            raise LBurstValueError(f"binning must be a positive integer, got {self.binning!r}")

    def estimate_gain(self, frames: np.ndarray) -> float | None:
        """The recording's gain from a burst of linear uint16 frames ``(N, H, W, 3)`` (or one frame
        ``(H, W, 3)``); ``None`` for ``gain='none'``."""
        if self.gain == "none":
            return None
        if not isinstance(self.gain, str):
            return float(self.gain)
        frames = np.asarray(frames)
        mean = frames.reshape(-1, *frames.shape[-3:]).mean(0, dtype=np.float32) / np.float32(65535.0)
        luma = binned(mean @ LUMA, self.binning)
        level = float(np.percentile(luma, self.percentile))
        return float(np.clip(self.target / max(level, 1e-12), 1.0, self.max_gain))


def binned(image: np.ndarray, size: int) -> np.ndarray:
    """The mean of ``image`` (H, W) over ``size`` x ``size`` blocks (the last partial rows and columns
    dropped; the image itself when it is smaller than a block)."""
    h, w = (image.shape[0] // size) * size, (image.shape[1] // size) * size
    if size == 1 or not h or not w:
        return image
    return image[:h, :w].reshape(h // size, size, w // size, size).mean((1, 3))


def normalise(frames: np.ndarray, gain: float | None, curve: str = "linear") -> np.ndarray:
    """Linear uint16 frames ``(..., 3)`` to sRGB uint8 with ``gain`` (module docstring); unchanged for ``None``
    or for frames that are already uint8."""
    if gain is None or frames.dtype == np.uint8:
        return frames
    linear = np.asarray(frames, np.float32) * np.float32(gain / 65535.0)
    encoded = srgb_encode(linear) if curve == "srgb" else np.clip(linear, 0.0, 1.0)
    return np.rint(encoded * 255.0).astype(np.uint8)
