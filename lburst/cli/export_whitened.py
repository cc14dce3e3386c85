"""``lburst export whitened``: weights with descriptor whitening measured on training photos
(:mod:`lburst.train.whitening`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.cli.numbers import integer, real
from lburst.paths import shared_dir
from lburst.train.whitening import sample_photos, whiten_checkpoint


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("checkpoint", help="weights to whiten (lburst layout; existing whitening is measured again)")
    p.add_argument("--out", type=Path, required=True, help="checkpoint to write")
    p.add_argument(
        "--photos",
        nargs="+",
        type=Path,
        help="photo folders (default: $LBURST_SHARED/data/train512); the validation tenth is left out",
    )
    p.add_argument("--count", type=integer(2), default=80, help="photos to sample, one synthetic burst each")
    p.add_argument("--power", type=real(0, 1), default=1.0, help="1: full whitening, 0: centring only")
    p.add_argument("--seed", type=integer(0), default=0, help="seed of the photo sample, shifts and noise")
    p.set_defaults(_default_photos=shared_dir() / "data" / "train512")


def main(args: argparse.Namespace) -> int:
    photos = sample_photos(args.photos or [args._default_photos], args.count, args.seed)
    whiten_checkpoint(args.checkpoint, args.out, photos, seed=args.seed, power=args.power)
    print(f"wrote {args.out} (descriptor statistics of {len(photos)} training photos)")
    return 0
