"""How bright the training photos' bright end is: the default ``target`` of :class:`lburst.burst.raw.Normalisation`.

For every ``--every``-th photo of a training folder, the statistic the RAW normalisation
maps to its target: the ``--percentile``-th percentile of the luminance (Rec. 709 weights,
0..1) averaged over ``--binning`` x ``--binning`` pixel blocks.  Prints its quantiles
over the photos and writes them as JSON::

    python scripts/bright_end.py "$LBURST_SHARED/data/train" --out outputs/bright_end.json

A dark recording normalised to the median of these looks, at its bright end, like a
typical photo the networks were trained on.  On the 680 photos of ``data/train``: 10 %
0.715, 25 % 0.829, median 0.938, 75 % 0.986, 90 % 0.998.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from lburst.burst.io import atomic_path
from lburst.burst.raw import LUMA, binned

SUFFIXES = {".jpg", ".jpeg", ".png"}


def bright_end(path: Path, percentile: float, binning: int) -> float | None:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        return None
    rgb = image[..., ::-1].astype(np.float32) / np.float32(255.0)
    return float(np.percentile(binned(rgb @ LUMA, binning), percentile))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="training photos (searched recursively)")
    parser.add_argument("--every", type=int, default=1, help="use every N-th photo in sorted order")
    parser.add_argument("--percentile", type=float, default=99.5)
    parser.add_argument("--binning", type=int, default=4)
    parser.add_argument("--out", type=Path, default=Path("outputs/bright_end.json"))
    args = parser.parse_args()
    photos = sorted(p for p in args.folder.rglob("*") if p.suffix.lower() in SUFFIXES)[:: args.every]
    if not photos:
        raise SystemExit(f"{args.folder}: no .jpg/.png photos")
    values = np.array([v for p in photos if (v := bright_end(p, args.percentile, args.binning)) is not None])
    quantiles = {f"q{q}": round(float(np.percentile(values, q)), 4) for q in (10, 25, 50, 75, 90)}
    print(f"{len(values)} photos of {args.folder}: P{args.percentile:g} of the {args.binning}x{args.binning}-binned")
    print("luminance, quantiles over the photos: " + ", ".join(f"{k} {v:.3f}" for k, v in quantiles.items()))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out) as tmp:
        settings = {"folder": str(args.folder), "every": args.every, "percentile": args.percentile}
        tmp.write_text(json.dumps({**settings, "binning": args.binning, "photos": len(values), **quantiles}, indent=1))


if __name__ == "__main__":
    main()
