"""``lburst demo``: the synthetic night flight reconstructed with LBurst and with SIFT, and a report
(:mod:`lburst.demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.cli.numbers import integer
from lburst.cli.options import add_matcher_argument, parse_method
from lburst.demo import lburst_method, run_demo
from lburst.methods import Method


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, default=Path("outputs/demo"), help="report folder")
    p.add_argument("--weights", help="LBurst checkpoint (default: $LBURST_WEIGHTS, else the shipped lburst-b5)")
    p.add_argument(
        "--noise",
        default="lowlight:moonless",
        help="noise of the flight (lburst.noise spec, e.g. lowlight:night or sensor:imx686@6400,photons=20)",
    )
    p.add_argument("--bursts", type=integer(2), default=15)
    p.add_argument("--seed", type=integer(0), default=0)
    p.add_argument("--overlap", type=integer(1), default=4, help="match each burst with this many next ones")
    p.add_argument("--methods", nargs="+", type=parse_method, help="methods to compare (default: lburst and sift)")
    add_matcher_argument(p)


def main(args: argparse.Namespace) -> int:
    methods = args.methods or [lburst_method(args.weights), Method("sift")]
    run_demo(args.out, methods, args.noise, args.bursts, args.seed, args.overlap, args.matcher)
    return 0
