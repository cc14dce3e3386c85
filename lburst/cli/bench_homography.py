"""``lburst bench homography``: the noisy-burst homography benchmark (:mod:`lburst.bench.homography`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.bench.homography import BenchMethod, InputMode, MotionRange, markdown, run_homography_benchmark
from lburst.cli.numbers import integer, real
from lburst.cli.options import add_color_jitter_argument, add_matcher_argument


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("data", type=Path, help="folder of sequence folders (Oxford or HPatches layout)")
    p.add_argument(
        "--methods",
        nargs="+",
        default=["lburst", "sift", "orb", "merge+sift"],
        help="method specs; one may carry its own input mode: gold+SPEC (gold:CKPT: the single-image "
        "network of CKPT on the clean image), oracle-merge+SPEC",
    )
    p.add_argument(
        "--input",
        choices=[m.value for m in InputMode],
        default=InputMode.BURST.value,
        help="what every method spec without its own mode sees: the noisy burst, the clean image (gold), "
        "or the frames aligned with the true motion and averaged (oracle-merge)",
    )
    p.add_argument(
        "--sigma",
        type=real(0),
        nargs="*",
        default=[25, 50, 100],
        help="Gaussian noise std levels (0..255; none given: only the --noise specs)",
    )
    p.add_argument(
        "--noise",
        nargs="*",
        default=[],
        help="extra noise levels as lburst.noise specs (e.g. lowlight:night, sensor:imx686@6400,photons=20)",
    )
    p.add_argument("--max-side", type=integer(8))
    p.add_argument("--top-k", type=integer(1), default=5000)
    p.add_argument("--out", type=Path, default=Path("outputs/homography"))
    p.add_argument(
        "--burst-rotation",
        type=real(0, 180),
        default=0.0,
        metavar="DEG",
        help="largest in-burst rotation per frame (degrees; 0: translation only)",
    )
    p.add_argument(
        "--burst-zoom", type=real(0, 0.5), default=0.0, metavar="Z", help="largest in-burst zoom per frame (0.01: 1%%)"
    )
    p.add_argument(
        "--burst-flow",
        type=real(0),
        default=0.0,
        metavar="PX",
        help="largest std of the smooth non-uniform in-burst flow per frame (pixels)",
    )
    p.add_argument(
        "--every",
        type=integer(1),
        default=1,
        metavar="K",
        help="use every K-th sequence in name order (the first, the K+1-th, ...): a quicker, fixed subset",
    )
    p.add_argument(
        "--rotation",
        type=real(-360, 360),
        default=0.0,
        metavar="DEG",
        help="turn images 2-6 of every sequence in-plane by DEG degrees about their centre "
        "(counter-clockwise; the homographies follow): matching across rotated views",
    )
    add_color_jitter_argument(
        p,
        default=(0.0, 0.0, 0.0, 0.0),
        help="change the colours of images 2-6 of every sequence, each by a random brightness, contrast and "
        "saturation factor within 1 +- these and a hue turn up to HUE of the circle (seeded): views from "
        "other cameras or times of day (e.g. 0.2 0.2 0.2 0.1, R2D2's training jitter)",
    )
    add_matcher_argument(p)


def main(args: argparse.Namespace) -> int:
    motion = MotionRange(args.burst_rotation, args.burst_zoom, args.burst_flow)
    results = run_homography_benchmark(
        args.data,
        [BenchMethod.parse(m, args.input) for m in args.methods],
        args.sigma,
        args.out,
        args.noise,
        args.max_side,
        args.top_k,
        motion=motion,
        matcher=args.matcher,
        every=args.every,
        rotation=args.rotation,
        color_jitter=tuple(args.color_jitter),
    )
    print(markdown(results))
    print(f"results: {args.out / 'results.json'}, {args.out / 'results.md'}, {args.out / 'mma.png'}")
    return 0
