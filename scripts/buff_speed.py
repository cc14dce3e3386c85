"""Time BuFF on a synthetic 5-frame 1024x768 burst (median of a few runs).

Prints a table (stage timings come from ``--profile``), writes JSON with ``--out``::

    python scripts/buff_speed.py --runs 3 --out buff_speed.json --profile

The burst is scikit-image's astronaut photo resized to 1024x768, moving at a constant
(1.3, -0.6) px/frame with Gaussian noise (std 25 of 255); ``--threads`` sets OpenCV's
and torch's thread counts (default 2, this project's CI machine).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import platform
import pstats
import statistics
import time

import cv2
import numpy as np

from lburst.burst.io import atomic_path
from lburst.methods.buff import Buff, BuffConfig


def synthetic_burst(
    width: int = 1024, height: int = 768, frames: int = 5, velocity=(1.3, -0.6), noise: float = 25.0, seed: int = 0
) -> np.ndarray:
    """uint8 ``(frames, height, width, 3)``: a photo translated by ``t * velocity`` plus Gaussian noise."""
    from skimage import data

    rng = np.random.default_rng(seed)
    margin = 16
    photo = cv2.resize(data.astronaut(), (width + 2 * margin, height + 2 * margin)).astype(np.float32)
    out = []
    for t in np.arange(frames) - frames // 2:
        m = np.float32([[1, 0, t * velocity[0]], [0, 1, t * velocity[1]]])
        moved = cv2.warpAffine(photo, m, photo.shape[1::-1], flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        moved = moved[margin:-margin, margin:-margin] + rng.normal(0, noise, (height, width, 3))
        out.append(np.clip(np.rint(moved), 0, 255).astype(np.uint8))
    return np.stack(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--width", type=int, default=1024)
    parser.add_argument("--height", type=int, default=768)
    parser.add_argument("--slope-step", type=float, default=BuffConfig.slope_step)
    parser.add_argument("--out", help="write the results as JSON here")
    parser.add_argument("--profile", action="store_true", help="print a cProfile summary of one more run")
    args = parser.parse_args(argv)
    cv2.setNumThreads(args.threads)
    try:
        import torch

        torch.set_num_threads(args.threads)
    except ImportError:
        pass
    burst = synthetic_burst(args.width, args.height)
    extractor = Buff(BuffConfig(slope_step=args.slope_step))
    extractor(burst)  # warm-up
    seconds, counts = [], []
    for _ in range(args.runs):
        start = time.perf_counter()
        features = extractor(burst)
        seconds.append(time.perf_counter() - start)
        counts.append(len(features["keypoints"]))
    slopes = features["slopes"]
    accuracy = float(np.mean(np.linalg.norm(slopes - np.array([1.3, -0.6]), axis=1) < 0.25)) if len(slopes) else 0.0
    result = {
        "burst": list(burst.shape),
        "slopes": len(extractor.slopes),
        "threads": args.threads,
        "runs": args.runs,
        "seconds_median": statistics.median(seconds),
        "seconds": seconds,
        "keypoints": counts[-1],
        "slope_within_0.25": accuracy,
        "machine": platform.processor() or platform.machine(),
    }
    print(f"{'burst':>18} {'slopes':>6} {'threads':>7} {'median s':>9} {'min s':>7} {'keypoints':>9} {'slope ok':>8}")
    print(
        f"{'x'.join(map(str, burst.shape)):>18} {result['slopes']:>6} {args.threads:>7} "
        f"{result['seconds_median']:>9.2f} {min(seconds):>7.2f} {result['keypoints']:>9} {accuracy:>8.3f}"
    )
    if args.profile:
        profiler = cProfile.Profile()
        profiler.runcall(extractor, burst)
        text = io.StringIO()
        pstats.Stats(profiler, stream=text).sort_stats("tottime").print_stats(15)
        print(text.getvalue())
    if args.out:
        with atomic_path(args.out) as tmp:
            tmp.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
