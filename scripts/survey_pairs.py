"""How well a reconstruction of a simulated survey ties its lines together.

For each run folder of ``lburst reconstruct`` on a scene made by ``lburst simulate flight
--survey`` (which writes ``survey.json``: the line of every burst), takes the verified
image pairs that reached the mapper (COLMAP's two-view geometry after lburst's loop test,
``RUN/colmap/verified.npz``) and checks each against the exact cameras of
``reference.json``: a pair is *true* when at least 80 % of its inliers lie within 4 px of
the reference epipolar lines.  Prints the true and false pairs, the true pairs whose
images lie on neighbouring lines (seen turned by 180 degrees against each other) with
their inliers, beside the registered images and the ATE of ``RUN/result.json``.

    python scripts/survey_pairs.py SURVEY NAME=RUN ... [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def cross_line_pairs(survey: Path, run: Path) -> dict:
    from lburst.burst.io import read_features_npz
    from lburst.sfm.metrics import epipolar_distances
    from lburst.sfm.reference import Reference

    lines = json.loads((survey / "survey.json").read_text())
    ref = Reference.load(survey / "reference.json")
    result = json.loads((run / "result.json").read_text())
    names = result["names"]
    keypoints = [read_features_npz(run / "features" / f"{n}.npz")["keypoints"] + 0.5 for n in names]  # COLMAP pixels
    true_pairs, false_pairs, across = 0, 0, []
    verified = run / "colmap" / "verified.npz"
    if verified.is_file():
        with np.load(verified) as data:
            for q, (a, b) in enumerate(data["pairs"].reshape(-1, 2)):
                m = data[f"inl_{q}"]
                e = epipolar_distances(
                    keypoints[a][m[:, 0]],
                    keypoints[b][m[:, 1]],
                    ref.camera,
                    ref.camera,
                    ref.poses[names[a]],
                    ref.poses[names[b]],
                )
                if not len(m) or np.mean(e <= 4) < 0.8:
                    false_pairs += 1
                    continue
                true_pairs += 1
                la, lb = lines[names[a]], lines[names[b]]
                if la >= 0 and lb >= 0 and abs(la - lb) == 1:
                    across.append(len(m))
    metrics = result.get("metrics") or {}
    return {
        "images": len(names),
        "registered": len(result.get("registered") or []),
        "true_pairs": true_pairs,
        "false_pairs": false_pairs,
        "cross_line_pairs": len(across),
        "cross_line_inliers": float(np.median(across)) if across else 0.0,
        "ate_m": metrics.get("ate_rmse"),
        "ate_percent": metrics.get("ate_percent"),
        "points3D_per_image": metrics.get("points3D_per_image"),
        "error": result.get("error"),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("survey", type=Path, help="the scene folder (with survey.json)")
    p.add_argument("runs", nargs="+", help="NAME=RUN (a reconstruction output folder)")
    p.add_argument("--out", type=Path)
    args = p.parse_args()
    rows = {}
    for item in args.runs:
        name, folder = item.split("=", 1)
        rows[name] = cross_line_pairs(args.survey, Path(folder))
    print(
        "| method | registered | true pairs | false pairs | true pairs across neighbouring lines "
        "| their median inliers | 3D pts/img | ATE | ATE % |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, r in rows.items():
        ate = f"{r['ate_m']:.3f} m" if r["ate_m"] is not None else "-"
        pct = f"{r['ate_percent']:.2f}" if r["ate_percent"] is not None else "-"
        pts = f"{r['points3D_per_image']:.0f}" if r["points3D_per_image"] is not None else "-"
        print(
            f"| {name} | {r['registered']}/{r['images']} | {r['true_pairs']} | {r['false_pairs']} | {r['cross_line_pairs']} | "
            f"{r['cross_line_inliers']:.0f} | {pts} | {ate} | {pct} |"
        )
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
