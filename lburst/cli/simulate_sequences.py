"""``lburst simulate sequences``: HPatches-style homography sequences from photos
(:mod:`lburst.bench.validation`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.bench.validation import make_validation_sequences
from lburst.cli.numbers import integer
from lburst.paths import shared_dir
from lburst.train.data import list_photos


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "photos",
        nargs="*",
        type=Path,
        help="photo folders (default: $LBURST_SHARED/data/train512); only their validation tenth is used",
    )
    p.add_argument("--out", type=Path, default=Path("data/validation"), help="folder of sequence folders")
    p.add_argument(
        "--split",
        choices=("validation", "all"),
        default="validation",
        help="which photos: the held-out tenth (never trained on) or all",
    )
    p.add_argument("--seed", type=integer(0), default=0, help="seed of every random draw")
    p.set_defaults(_default_photos=shared_dir() / "data" / "train512")


def main(args: argparse.Namespace) -> int:
    photos = list_photos(args.photos or [args._default_photos], split=args.split)
    folders = make_validation_sequences(photos, args.out, args.seed)
    print(f"{len(folders)} sequences in {args.out}")
    return 0
