"""Reliability and detectable pixels by distance to the image border, per network.

For each network (a checkpoint or a shipped name) and each burst, the dense maps
(:meth:`lburst.LBurst.dense`) are split into rings by distance to the nearest border
(0-8, 8-16, 16-32, 32-64 and over 64 px); the table gives, per ring, the mean reliability
and the share of pixels where both maps pass the 0.7 keypoint thresholds, averaged over the
bursts.  A network whose reliability falls at the border puts few keypoints there, and COLMAP
then fits the lens distortion from the image centre alone.  ``--pad N`` runs every network with
N px of reflected image around the burst (default: each network's own ``meta['pad']``, 0 for
the shipped and the published weights; :class:`lburst.model.extractor.MultiScaleConfig`).

    python scripts/border_reliability.py lburst-b5 $S/anchors/RoBLo_N16_B5.pt \
        --bursts outputs/scenes/lund_g100/0[1-4] --out outputs/border.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from lburst.burst.io import load_burst
from lburst.model.extractor import LBurst

RINGS = ((0, 8), (8, 16), (16, 32), (32, 64), (64, None))
THRESHOLD = 0.7


def ring_statistics(rep: np.ndarray, rel: np.ndarray) -> list[tuple[float, float]]:
    """(mean reliability, share of pixels with both maps over the threshold) per ring of :data:`RINGS`."""
    h, w = rel.shape
    yy, xx = np.mgrid[:h, :w]
    distance = np.minimum(np.minimum(xx, w - 1 - xx), np.minimum(yy, h - 1 - yy))
    rows = []
    for low, high in RINGS:
        ring = (distance >= low) & (distance < (high if high is not None else np.inf))
        rows.append((float(rel[ring].mean()), float(((rep[ring] > THRESHOLD) & (rel[ring] > THRESHOLD)).mean())))
    return rows


def load(spec: str) -> LBurst:
    return LBurst.from_checkpoint(spec) if spec.endswith(".pt") else LBurst.pretrained(spec)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("networks", nargs="+", help="checkpoints (.pt) or shipped names")
    p.add_argument("--bursts", nargs="+", required=True, help="burst folders")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--pad", type=int, help="reflected border in px (default: each network's own)")
    p.add_argument("--out", type=Path, help="also write the table as JSON")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    table = {}
    for spec in args.networks:
        model = load(spec)
        per_burst = []
        for folder in args.bursts:
            maps = model.dense(load_burst(folder), pad=args.pad)
            per_burst.append(ring_statistics(maps["repeatability"], maps["reliability"]))
        table[spec if args.pad is None else f"{spec}, pad {args.pad}"] = np.mean(per_burst, axis=0).tolist()
    names = [f"{lo}-{hi}" if hi else f"{lo}+" for lo, hi in RINGS]
    print("| network | " + " | ".join(f"{n} px: rel / detectable" for n in names) + " |")
    print("|---|" + "---|" * len(names))
    for spec, rows in table.items():
        print(f"| {spec} | " + " | ".join(f"{r:.2f} / {d:.3f}" for r, d in rows) + " |")
    if args.out:
        args.out.write_text(json.dumps({"rings": names, "bursts": args.bursts, "table": table}, indent=1))


if __name__ == "__main__":
    main()
