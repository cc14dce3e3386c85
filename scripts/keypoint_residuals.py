"""Where keypoints sit against the ground truth: residuals of correct matches by radius and scale.

For each method's cached benchmark features (``lburst bench homography ... --out OUT``), every
pair (1, K) is matched with mutual nearest neighbours; for matches within ``--max-error`` px of
the true homography the residual ``e = p2 - H p1`` is split into its radial part (along the
direction from image K's centre) and its size, grouped by the radius of ``p2`` (as a fraction of
the half-diagonal) and by the keypoint's pyramid level.  A keypoint detector that pulls points
radially, or whose coarse levels dominate, shows here before it shows in a camera model.

    python scripts/keypoint_residuals.py NAME=OUT/cache/METHOD/sigma50 ... --data $S/data/homography
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from lburst.bench.metrics import project
from lburst.bench.sequences import read_sequence
from lburst.burst.io import read_features_npz
from lburst.matching import create

BINS = (0.0, 0.25, 0.5, 0.75, 1.01)


def residuals(cache: Path, data: Path, max_error: float) -> dict[str, np.ndarray]:
    match = create("mnn")
    rows = []
    for seq_dir in sorted(p for p in cache.iterdir() if p.is_dir()):
        seq = read_sequence(data / seq_dir.name)
        feats = [read_features_npz(seq_dir / f"{i}.npz") for i in range(1, 7)]
        for k in range(5):
            a, b = feats[0], feats[k + 1]
            m = match(a, b)
            p1, p2 = a["keypoints"][m[:, 0]], b["keypoints"][m[:, 1]]
            e = p2 - project(seq.homographies[k], p1)
            ok = np.linalg.norm(e, axis=1) <= max_error
            h, w = seq.images[k + 1].shape[:2]
            centre = np.array([(w - 1) / 2, (h - 1) / 2])
            d = p2[ok] - centre
            r = np.linalg.norm(d, axis=1)
            radial = np.sum(e[ok] * d, 1) / np.maximum(r, 1e-6)
            rows.append(np.c_[r / np.hypot(w / 2, h / 2), radial, np.linalg.norm(e[ok], axis=1), b["scales"][m[ok, 1]]])
    t = np.concatenate(rows)
    return {"rho": t[:, 0], "radial": t[:, 1], "size": t[:, 2], "scale": t[:, 3]}


def summary(t: dict[str, np.ndarray]) -> dict:
    out = {"matches": len(t["size"]), "median_error": float(np.median(t["size"])), "by_radius": [], "by_scale": []}
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        sel = (t["rho"] >= lo) & (t["rho"] < hi)
        out["by_radius"].append(
            {
                "rho": f"{lo:.2f}-{min(hi, 1):.2f}",
                "share": float(sel.mean()),
                "mean_radial": float(t["radial"][sel].mean()) if sel.any() else None,
                "median_error": float(np.median(t["size"][sel])) if sel.any() else None,
            }
        )
    for scale in np.unique(np.round(t["scale"], 2)):
        sel = np.isclose(t["scale"], scale, atol=0.01)
        out["by_scale"].append(
            {"scale": float(scale), "share": float(sel.mean()), "median_error": float(np.median(t["size"][sel]))}
        )
    slope = np.polyfit(t["rho"], t["radial"], 1)[0]
    out["radial_slope_px"] = float(slope)  # mean radial residual gained from centre to corner
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("caches", nargs="+", help="NAME=FOLDER (a bench cache of one method and noise level)")
    p.add_argument("--data", type=Path, required=True, help="the sequences the caches were made from")
    p.add_argument("--max-error", type=float, default=3.0)
    p.add_argument("--out", type=Path)
    args = p.parse_args()
    results = {}
    for item in args.caches:
        name, folder = item.split("=", 1)
        results[name] = summary(residuals(Path(folder), args.data, args.max_error))
    print(
        "| method | correct matches | median error | mean radial error by radius (0-0.25 / -0.5 / -0.75 / -1) | share by radius | slope |"
    )
    print("|---|---|---|---|---|---|")
    for name, s in results.items():
        radial = " / ".join(f"{b['mean_radial']:+.3f}" for b in s["by_radius"])
        share = " / ".join(f"{b['share']:.2f}" for b in s["by_radius"])
        print(
            f"| {name} | {s['matches']} | {s['median_error']:.3f} | {radial} | {share} | {s['radial_slope_px']:+.3f} |"
        )
    print()
    for name, s in results.items():
        print(
            name,
            "error by scale:",
            ", ".join(f"{b['scale']:.1f}: {b['median_error']:.2f} ({b['share']:.2f})" for b in s["by_scale"]),
        )
    if args.out:
        args.out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
