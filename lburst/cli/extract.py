"""``lburst extract``: features of many bursts, one ``.npz`` each (and an hloc ``features.h5``):
the options of :func:`lburst.extraction.extract`, which does the work (its docstring says what
it writes), and its summary."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from lburst.cli.numbers import integer
from lburst.cli.options import add_cluster_argument, add_recording_arguments, parse_method, recording_options
from lburst.extraction import DEFAULT_TOP_K, extract
from lburst.methods import Method
from lburst.model.network import AUTOCAST_DTYPES
from lburst.model.runtimes import RUNTIMES


def chosen_method(method: Method | None, weights: str | None, frame_order: str | None = None) -> Method:
    """The method of ``--method``/``--weights``/``--frame-order``: ``lburst`` (shipped weights) by
    default; ``--weights`` (else ``$LBURST_WEIGHTS``) is the checkpoint of a method that names none."""
    method = (method or Method("lburst")).with_weights(weights or os.environ.get("LBURST_WEIGHTS"))
    return method.with_option("frame_order", frame_order) if frame_order else method


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "bursts",
        nargs="+",
        type=Path,
        help="burst folders, images or videos (a whole video, or a folder of frames without meta.json, is one "
        "burst unless --every or --motion is given), or recordings: features of each keyframe burst go to "
        "OUT/<recording>/<keyframe>.npz",
    )
    p.add_argument("--out", type=Path, required=True, help="output folder for <burst>.npz")
    p.add_argument("--weights", help="checkpoint (default: $LBURST_WEIGHTS, else the shipped lburst-b5)")
    p.add_argument(
        "--method", type=parse_method, help="any method spec, e.g. sift, orb, merge+sift, buff (default: lburst)"
    )
    p.add_argument(
        "--frame-order",
        choices=["temporal", "published"],
        help="frame order for burst networks ('published' for the published LBurst weights)",
    )
    p.add_argument(
        "--top-k",
        type=integer(1),
        help=f"keypoints per burst of a learned method (default: the spec's top_k=N, else {DEFAULT_TOP_K}); "
        "an explicit --top-k that disagrees with the spec's top_k is refused",
    )
    p.add_argument("--h5", action="store_true", help="also write an hloc-style features.h5 in --out")
    p.add_argument("--overwrite", action="store_true", help="recompute bursts that are already done")
    p.add_argument("--device", help="cpu or cuda (default: cuda if available)")
    p.add_argument(
        "--precision",
        choices=list(AUTOCAST_DTYPES),
        default="fp32",
        help="backbone precision of learned methods: bf16 is faster on CPUs with AVX512-BF16 or AMX "
        "(heads stay fp32; about 99%% of keypoints within 1 px of fp32), fp16 on a GPU",
    )
    p.add_argument(
        "--runtime",
        choices=["auto", *RUNTIMES],
        help="what runs a learned network on the CPU (default: auto, the fastest this CPU has, for the light "
        "network lburst-lite; torch for the others); the bf16 and int8 runtimes move some keypoints",
    )
    p.add_argument(
        "--threads",
        type=integer(1, 1024),
        help="torch threads per burst (default: torch's own in one process, 1 per worker with --cluster); "
        "the features of lburst-b5 equal byte for byte only at equal thread counts",
    )
    add_cluster_argument(p, "the bursts")
    add_recording_arguments(p)


def main(args: argparse.Namespace) -> int:
    report = extract(
        args.bursts,
        args.out,
        chosen_method(args.method, args.weights, args.frame_order),
        top_k=args.top_k,
        overwrite=args.overwrite,
        h5=args.h5,
        device=args.device,
        precision=args.precision,
        runtime=args.runtime,
        threads=args.threads,
        recording=recording_options(args),
        cluster=args.cluster,
    )
    print(f"{report.done} bursts extracted to {args.out}, {report.already} already done, {len(report.failed)} failed")
    for path, why in report.failed:
        print(f"  failed: {why if why.startswith(str(path)) else f'{path}: {why}'}", file=sys.stderr)
    return 1 if report.failed else 0
