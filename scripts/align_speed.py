"""Burst alignment speed and accuracy: seconds per 1024x768 5-frame burst and shift error
against the true shifts, per method of :func:`lburst.burst.align.estimate_shifts`, and for
``turning``: :func:`lburst.burst.align.estimate_warps`, the default of ``align_burst`` (the
pyramid's shifts plus the check whether the burst turns; these bursts do not).

Bursts are simulated (:func:`lburst.simulate.simulate_burst`) from textured photos
resized to ``--size`` (skimage's astronaut, coffee and chelsea, plus ``--photos`` photos
drawn from ``$LBURST_SHARED/data/train`` when that folder exists), each moving at
``--motions`` random constant velocities up to ``--max-motion`` px/frame in x and y
(``numpy.random.default_rng(--seed)``, the same velocities at every noise level), at
every noise level of ``--noise`` (Gaussian std on 0..255, or a noise spec of
:func:`lburst.noise.noise_from_spec` such as ``lowlight:night``).

Per method: the time of :func:`lburst.burst.align.align_burst` (shift estimation with
``--motion``, then the warp), median over every burst run ``--repeats`` times with
``--threads`` OpenCV threads, as wall-clock seconds (split into estimate and warp) and as
the process's CPU seconds (less sensitive to other processes on a busy machine); and the shift error ``|estimated - true|`` (px, Euclidean,
every frame but the common one) per noise level: mean, 95th percentile and max.
``simulate_burst`` puts the image content at ``(x, y)`` at ``(x + t u, y + t v)`` in
frame ``t``, which is the shift ``t (u, v)`` of :mod:`lburst.burst.align`'s convention.
The last column is the worst excess of the method's mean error over ``ecc``'s.

    taskset -c 0 python scripts/align_speed.py --out outputs/align_speed.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from lburst.burst.align import METHODS, align_burst, estimate_shifts, estimate_warps
from lburst.model.precision import cpu_name
from lburst.noise import GaussianNoise, noise_from_spec
from lburst.paths import shared_dir
from lburst.simulate import simulate_burst

SHARED = shared_dir()


def load_photos(count: int, size: tuple[int, int], seed: int) -> list[tuple[str, np.ndarray]]:
    """skimage's textured photos plus ``count`` photos of the shared training set, resized to ``size`` (w, h)."""
    import skimage.data

    photos = [(name, getattr(skimage.data, name)()) for name in ("astronaut", "coffee", "chelsea")]
    paths = sorted((SHARED / "data" / "train").glob("*/*.jpg")) if count > 0 else []
    if paths:
        for i in np.random.default_rng(seed).choice(len(paths), min(count, len(paths)), replace=False):
            image = cv2.imread(str(paths[i]), cv2.IMREAD_COLOR)
            if image is not None:
                photos.append((f"{paths[i].parent.name}/{paths[i].name}", image[..., ::-1]))
    out = []
    for name, image in photos:
        grow = image.shape[1] < size[0] or image.shape[0] < size[1]
        resized = cv2.resize(
            np.ascontiguousarray(image), size, interpolation=cv2.INTER_CUBIC if grow else cv2.INTER_AREA
        )
        out.append((name, resized))
    return out


def noise_model(spec: str):
    try:
        std = float(spec)
    except ValueError:
        return noise_from_spec(spec)
    return GaussianNoise(std) if std > 0 else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--methods", default="ecc,phase,pyramid,turning", help="comma-separated methods")
    parser.add_argument("--noise", default="0,25,50,100,lowlight:night", help="comma-separated noise levels")
    parser.add_argument("--photos", type=int, default=3, help="photos from the shared training set (if present)")
    parser.add_argument("--motions", type=int, default=2, help="random velocities per photo")
    parser.add_argument("--max-motion", type=float, default=3.0, help="px/frame, in x and in y")
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--size", default="1024x768", help="WxH")
    parser.add_argument("--dtype", choices=("uint8", "uint16"), default="uint8")
    parser.add_argument("--motion", choices=("free", "linear"), default="linear", help="motion model of the fit")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs of every burst")
    parser.add_argument("--threads", type=int, default=1, help="cv2.setNumThreads")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, help="write the results as JSON")
    args = parser.parse_args()

    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in methods if m not in (*METHODS, "turning")]
    if unknown:
        parser.error(f"unknown methods {unknown}: use {', '.join(METHODS)} or turning")
    noises = [n.strip() for n in args.noise.split(",") if n.strip()]
    width, height = (int(v) for v in args.size.lower().split("x"))
    cv2.setNumThreads(args.threads)

    photos = load_photos(args.photos, (width, height), args.seed)
    rng = np.random.default_rng(args.seed)
    velocities = rng.uniform(-args.max_motion, args.max_motion, (len(photos), args.motions, 2))
    t = (np.arange(args.frames) - args.frames // 2)[:, None]
    bursts = []  # (noise, photo, velocity, burst, true shifts)
    for noise in noises:
        model = noise_model(noise)
        for p, (name, photo) in enumerate(photos):
            image = photo.astype(np.uint16) * 257 if args.dtype == "uint16" else photo
            for velocity in velocities[p]:
                burst = simulate_burst(image, args.frames, tuple(velocity), model, rng=int(rng.integers(1 << 31)))
                bursts.append((noise, name, velocity, burst, t * velocity[None]))
    print(
        f"{len(bursts)} bursts {width}x{height}x{args.frames} {args.dtype} ({len(photos)} photos x "
        f"{args.motions} motions x {len(noises)} noise levels), {args.threads} OpenCV thread(s), "
        f"CPU {cpu_name()}",
        flush=True,
    )

    results = {}
    for method in methods:

        def estimate(burst: np.ndarray, method: str = method) -> np.ndarray:
            if method == "turning":
                return estimate_warps(burst, motion=args.motion)
            return estimate_shifts(burst, method=method, motion=args.motion)

        align_burst(bursts[0][3], estimate(bursts[0][3]))  # warm-up
        totals, cpu_totals, estimates, warps = [], [], [], []
        errors: dict[str, list[float]] = {noise: [] for noise in noises}
        for repeat in range(args.repeats):
            for noise, _, _, burst, truth in bursts:
                cpu_start, start = time.process_time(), time.perf_counter()
                motion = estimate(burst)
                middle = time.perf_counter()
                align_burst(burst, motion)
                shifts = motion[:, :, 2] if motion.ndim == 3 else motion
                end, cpu_end = time.perf_counter(), time.process_time()
                totals.append(end - start)
                cpu_totals.append(cpu_end - cpu_start)
                estimates.append(middle - start)
                warps.append(end - middle)
                if repeat == 0:
                    error = np.hypot(*(shifts - truth).T)
                    errors[noise].extend(np.delete(error, args.frames // 2).tolist())
        results[method] = {
            "seconds_per_burst": statistics.median(totals),
            "cpu_seconds_per_burst": statistics.median(cpu_totals),
            "estimate_seconds": statistics.median(estimates),
            "warp_seconds": statistics.median(warps),
            "runs": len(totals),
            "errors_px": {
                noise: {
                    "mean": float(np.mean(e)),
                    "p95": float(np.percentile(e, 95)),
                    "max": float(np.max(e)),
                    "frames": len(e),
                }
                for noise, e in errors.items()
            },
        }
        print(f"  {method}: {results[method]['seconds_per_burst']:.3f} s/burst", flush=True)

    reference = results.get("ecc")
    header = "| method | s/burst | CPU s/burst | estimate s | warp s | " + " | ".join(
        f"{n} mean / p95 px" for n in noises
    )
    header += " | worst mean - ecc |" if reference else " |"
    print()
    print(header)
    print("|" + "---|" * (header.count("|") - 1))
    for method, r in results.items():
        cells = [f"{r['errors_px'][n]['mean']:.3f} / {r['errors_px'][n]['p95']:.3f}" for n in noises]
        row = f"| {method} | {r['seconds_per_burst']:.3f} | {r['cpu_seconds_per_burst']:.3f} | "
        row += f"{r['estimate_seconds']:.3f} | {r['warp_seconds']:.4f} | "
        row += " | ".join(cells)
        if reference:
            excess = max(r["errors_px"][n]["mean"] - reference["errors_px"][n]["mean"] for n in noises)
            r["worst_mean_excess_over_ecc_px"] = excess
            row += f" | {excess:+.3f}"
        print(row + " |")

    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        config = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}
        config["photos_used"] = [name for name, _ in photos]
        env = {
            "cpu": cpu_name(),
            "opencv": cv2.__version__,
            "numpy": np.__version__,
            "python": platform.python_version(),
            "affinity": sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        }
        args.out.write_text(json.dumps({"config": config, "env": env, "results": results}, indent=2) + "\n")
        print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
