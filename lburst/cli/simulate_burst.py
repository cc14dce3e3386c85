"""``lburst simulate burst``: a low-light robotic burst from one photo."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.burst.io import read_image, save_burst
from lburst.cli.numbers import integer, real
from lburst.extras import require
from lburst.noise import noise_from_spec
from lburst.simulate import simulate_burst


def default_photo():
    """A photo scikit-image ships (so the command runs with no data)."""
    return require("skimage.data", "the default photo (give IMAGE instead)").astronaut()


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("image", nargs="?", type=Path, help="photo (default: scikit-image's astronaut)")
    p.add_argument("--out", type=Path, required=True, help="folder for frame_000.png ...")
    p.add_argument("--frames", type=integer(1, 99), default=5)
    p.add_argument(
        "--motion",
        type=real(-1000, 1000),
        nargs=2,
        default=(2.0, 1.0),
        metavar=("DX", "DY"),
        help="apparent motion per frame, pixels",
    )
    p.add_argument(
        "--noise",
        default="gaussian:50",
        help="none, gaussian:STD, gaussian-var:V, lowlight:PHOTONS|night|... or sensor:imx686|a7s2@ISO[,photons=P]",
    )
    p.add_argument("--seed", type=integer(0), default=0)


def main(args: argparse.Namespace) -> int:
    noise = noise_from_spec(args.noise)  # a bad spec fails before any reading
    image = read_image(args.image) if args.image else default_photo()
    burst = simulate_burst(image, args.frames, tuple(args.motion), noise, rng=args.seed)
    paths = save_burst(burst, args.out)
    print(f"wrote {len(paths)} frames ({burst.shape[2]}x{burst.shape[1]}, noise {noise.spec}) to {args.out}")
    return 0
