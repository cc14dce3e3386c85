"""Keypoints and matches on dark DNG keyframes with and without the RAW normalisation.

For keyframes 64, 96 and 128 of the simulated night flight (bursts of 5 frames), extract
features from the DNG frames as ``lburst.burst.raw`` delivers them under several
normalisations (and from the same keyframes of the flight's video), match the pairs
64-96, 96-128 and 64-128 with mutual nearest neighbours, and count the matches within
4 px of the true epipolar geometry (the flight's exact poses and camera)::

    lburst simulate flight --video flight.mp4 --dng flight_dng --noise lowlight:moonless
    python scripts/raw_gain_check.py flight_dng flight.mp4

Prints one line per variant: gain, mean and percentiles of the keyframe (0..255), mean
keypoints, and ``matches/correct`` per pair.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from lburst.burst.raw import LUMA, Normalisation, normalise, read_dng
from lburst.burst.sources import RecordingOptions, open_recording
from lburst.matching import create as create_matcher
from lburst.methods import create
from lburst.noise import noise_from_spec
from lburst.scenes.flight_recording import BLACK_LEVEL, camera
from lburst.scenes.night_flight import NightFlightConfig, camera_pose
from lburst.sfm.metrics import epipolar_distances

KEYS = (64, 96, 128)
PAIRS = ((64, 96), (96, 128), (64, 128))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dng", type=Path, help="the flight as DNG frames (lburst simulate flight --dng)")
    p.add_argument("video", type=Path, nargs="?", help="the same flight as a video (optional)")
    p.add_argument("--method", default="lburst")
    args = p.parse_args()
    meta = json.loads((args.dng / "meta.json").read_text())
    cfg = NightFlightConfig.from_dict(meta["night_flight"])
    cam, fps = camera(cfg), float(meta["fps"])

    def frames(indices) -> np.ndarray:
        return np.stack([read_dng(args.dng / f"frame_{max(j, 0):06d}.dng") for j in indices])

    dng = {k: frames(range(k - 2, k + 3)) for k in KEYS}
    first = frames([0, 0, 0, 1, 2])  # the recording's first burst, as lburst.burst.sources fills it
    sensor = noise_from_spec(cfg.noise)  # the scene's white in linear units: its counts over the ADC's range
    white = sensor.photons * sensor.quantum_efficiency / sensor.gain_e_per_adu / (2**sensor.adc_bits - 1 - BLACK_LEVEL)
    single = float(np.percentile(np.asarray(first, np.float32) / 65535 @ LUMA, 99.5))
    target = Normalisation().target
    auto = Normalisation().estimate_gain(first)
    print(
        f"99.5th luminance percentile: single pixels {single / white:.2f} x white, "
        f"binned burst mean {target / auto / white:.2f} x white"
    )
    variants: dict[str, tuple[float | None, str] | None] = {
        "none (linear uint16)": (None, "linear"),
        "srgb, gain 0.8/P(pixels)": (0.8 / single, "srgb"),
        "linear, gain 0.8/P(pixels)": (0.8 / single, "linear"),
        "linear, gain 0.8/P(binned)": (auto * 0.8 / target, "linear"),
        f"linear, gain auto ({target:g}/P(binned))": (auto, "linear"),
        f"srgb, gain auto ({target:g}/P(binned))": (auto, "srgb"),
    }
    bursts: dict[str, dict[int, np.ndarray]] = {}
    if args.video:
        bursts["video"] = {}
        for keyframe, burst in open_recording(args.video, RecordingOptions(burst=5, every=32)).bursts():
            if keyframe.index in KEYS:
                bursts["video"][keyframe.index] = burst
            if keyframe.index >= max(KEYS):
                break
    for name, (gain, curve) in variants.items():
        bursts[f"dng {name} gain={gain or 0:.1f}"] = {k: normalise(dng[k], gain, curve) for k in KEYS}
    extract, match = create(args.method), create_matcher("mnn")
    for name, by_key in bursts.items():
        feats = {k: extract(b) for k, b in by_key.items()}
        img = by_key[KEYS[0]][2].astype(np.float32) / (257.0 if by_key[KEYS[0]].dtype == np.uint16 else 1.0)
        counts = []
        for a, b in PAIRS:
            m = match(feats[a], feats[b])
            d = (
                epipolar_distances(
                    feats[a]["keypoints"][m[:, 0]] + 0.5,
                    feats[b]["keypoints"][m[:, 1]] + 0.5,
                    cam,
                    cam,
                    camera_pose(cfg, a / fps),
                    camera_pose(cfg, b / fps),
                )
                if len(m)
                else []
            )
            counts.append(f"{len(m)}/{int(np.sum(np.asarray(d) <= 4))}")
        kp = np.mean([len(f["keypoints"]) for f in feats.values()])
        print(
            f"{name:45s} mean {img.mean():5.1f} p50 {np.percentile(img, 50):3.0f} p99 {np.percentile(img, 99):3.0f}"
            f" | keypoints {kp:5.0f} | matches/correct {' '.join(counts)}",
            flush=True,
        )


if __name__ == "__main__":
    main()
