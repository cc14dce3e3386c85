"""Whether keypoints near the image border sit where the same content's keypoints sit away from it.

For each burst, a method's keypoints on the whole burst are compared with its keypoints on the
burst cut ``--cut`` px shorter on one side (each side in turn): content next to the new border
is interior in the whole burst.  Keypoints of the cut burst within 2 px of one of the whole
burst's are paired, and the table gives, by distance to the new border, how far the cut
burst's keypoint lies towards that border (px; positive: outwards).  A network that moved its
keypoints outwards near the border would bend straight lines like a pincushion lens, and
COLMAP would fit a positive radial distortion to it.

    python scripts/border_shift.py lburst "lburst:$S/anchors/RoBLo_N16_B5.pt,frame_order=published" \
        --bursts outputs/scenes/lund_g50/01 outputs/scenes/lund_g50/05 outputs/scenes/lund_g50/10
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch
from scipy.spatial import cKDTree

import lburst
from lburst.burst.io import load_burst

BANDS = ((0, 8), (8, 16), (16, 32), (32, 48))
SIDES = ("left", "right", "top", "bottom")
PAIR_PX = 2.0


def outward_shifts(method, burst: np.ndarray, cut: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per side: (distance of each paired keypoint to the new border, its outward shift), in px."""
    whole = method(burst)["keypoints"][:, :2]
    tree = cKDTree(whole)
    h, w = burst.shape[1:3]
    out = []
    for side in SIDES:
        crop = {
            "left": np.s_[:, :, cut:],
            "right": np.s_[:, :, : w - cut],
            "top": np.s_[:, cut:],
            "bottom": np.s_[:, : h - cut],
        }
        offset = np.array({"left": (cut, 0), "top": (0, cut)}.get(side, (0, 0)), np.float32)
        kp = method(np.ascontiguousarray(burst[crop[side]]))["keypoints"][:, :2] + offset
        dist, j = tree.query(kp, distance_upper_bound=PAIR_PX)
        ok = np.isfinite(dist)
        kp, delta = kp[ok], kp[ok] - whole[j[ok]]
        axis, sign, border = {
            "left": (0, -1, cut),
            "right": (0, 1, w - cut - 1),
            "top": (1, -1, cut),
            "bottom": (1, 1, h - cut - 1),
        }[side]
        out.append((np.abs(kp[:, axis] - border), sign * delta[:, axis]))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("methods", nargs="+", help="method specs (lburst, lburst:CKPT,frame_order=published, ...)")
    p.add_argument("--bursts", nargs="+", required=True, help="burst folders")
    p.add_argument("--cut", type=int, default=48, help="px cut off one side (default 48)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", type=Path, help="also write the table as JSON")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    table = {}
    for spec in args.methods:
        method = lburst.methods.create(spec)
        pairs = [s for path in args.bursts for s in outward_shifts(method, load_burst(path), args.cut)]
        dist, shift = (np.concatenate(parts) for parts in zip(*pairs))
        rows = []
        print(f"{spec}: outward shift near the new border (px)")
        for low, high in BANDS:
            v = shift[(dist >= low) & (dist < high)]
            sem = float(v.std() / np.sqrt(len(v))) if len(v) > 1 else float("nan")
            rows.append({"band": [low, high], "n": len(v), "mean": float(v.mean()) if len(v) else None, "sem": sem})
            mean = f"{v.mean():+.3f} (sem {sem:.3f})" if len(v) else "-"
            print(f"  {low:2d}-{high:2d} px: {len(v):5d} keypoints, mean {mean}")
        table[spec] = rows
    if args.out:
        args.out.write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
