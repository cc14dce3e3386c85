"""``lburst export weights``: a training run's checkpoint as shippable weights
(:func:`lburst.train.export.export_weights`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from lburst.errors import LBurstValueError
from lburst.train.export import export_weights


def _meta(text: str) -> tuple[str, object]:
    """``KEY=VALUE``, the value read as JSON where it is JSON (numbers, true, null), else text."""
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("checkpoint", type=Path, help="a run's last.pt or one of its snapshots/step_*.pt")
    p.add_argument("--out", type=Path, required=True, help="weights to write ({'net', 'state_dict', 'meta'})")
    p.add_argument(
        "--meta",
        nargs="+",
        type=_meta,
        default=[],
        metavar="KEY=VALUE",
        help="more entries of the weights' meta, e.g. teacher_sha1=... (values read as JSON where they are)",
    )


def main(args: argparse.Namespace) -> int:
    if not args.checkpoint.is_file():
        raise LBurstValueError(f"{args.checkpoint}: no such checkpoint")
    out = export_weights(args.checkpoint, args.out, **dict(args.meta))
    print(f"wrote {out} (from {args.checkpoint})")
    return 0
