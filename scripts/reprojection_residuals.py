"""What a reconstruction says about its keypoints: reprojection residuals by radius and scale.

For each run folder of ``lburst reconstruct`` or ``lburst bench reconstruction``
(``RUN/colmap/model`` and ``RUN/features/<image>.npz``), every observation of a 3D point is
projected back with its image's pose and camera.  The table gives the fitted camera, the
3D points and track length, how much of the image the observations cover, and the
reprojection error split by the radius of the observation (a share of the half-diagonal)
and by the pyramid level its keypoint came from.  The mean *radial* part of the residual
by radius is what a radial distortion term absorbs: a detector whose keypoints lie
radially off shows it there, and a camera fitted to them shows a larger distortion.

    python scripts/reprojection_residuals.py NAME=RUN ... [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from lburst.burst.io import read_features_npz

BINS = (0.0, 0.25, 0.5, 0.75, 1.01)
GRID = (8, 6)


def observations(run: Path) -> tuple[dict, np.ndarray]:
    """The camera summary and rows (rho, radial residual, error, keypoint scale, cell) of every observation."""
    import pycolmap

    rec = pycolmap.Reconstruction(str(run / "colmap" / "model"))
    cams = {cid: cam for cid, cam in rec.cameras.items()}
    rows = []
    for image in rec.images.values():
        if not image.has_pose:
            continue
        cam = cams[image.camera_id]
        feats = read_features_npz(run / "features" / f"{Path(image.name).stem}.npz")
        pose = image.cam_from_world()
        centre = np.array([cam.principal_point_x, cam.principal_point_y])
        half_diag = np.hypot(cam.width / 2, cam.height / 2)
        for idx, p2 in enumerate(image.points2D):
            if not p2.has_point3D():
                continue
            xyz = rec.points3D[p2.point3D_id].xyz
            proj = cam.img_from_cam(pose * xyz)
            if proj is None:
                continue
            xy = np.asarray(p2.xy)
            e = xy - np.asarray(proj)
            d = xy - centre
            r = np.linalg.norm(d)
            cell = int(min(GRID[0] - 1, xy[0] / cam.width * GRID[0])) + GRID[0] * int(
                min(GRID[1] - 1, xy[1] / cam.height * GRID[1])
            )
            scale = float(feats["scales"][idx]) if idx < len(feats["scales"]) else np.nan
            rows.append((r / half_diag, float(e @ d / max(r, 1e-6)), float(np.linalg.norm(e)), scale, cell))
    camera = next(iter(cams.values()))
    tracks = [p.track.length() for p in rec.points3D.values()]
    summary = {
        "model": camera.model.name,
        "params": [round(float(v), 5) for v in camera.params],
        "images": rec.num_reg_images(),
        "points3D": rec.num_points3D(),
        "points_per_image": rec.num_points3D() / max(rec.num_reg_images(), 1),
        "track_length": float(np.mean(tracks)) if tracks else 0.0,
    }
    return summary, np.array(rows)


def summarize(summary: dict, t: np.ndarray) -> dict:
    rho, radial, error, scale, cell = t.T
    out = dict(summary)
    out["observations"] = len(t)
    out["mean_error"] = float(error.mean())
    cells = np.bincount(cell.astype(int), minlength=GRID[0] * GRID[1]) / max(summary["images"], 1)
    out["cells_covered"] = float((cells >= 1).mean())  # share of an 8x6 grid with >= 1 observation per image
    out["by_radius"] = []
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        sel = (rho >= lo) & (rho < hi)
        out["by_radius"].append(
            {
                "share": float(sel.mean()),
                "mean_radial": float(radial[sel].mean()) if sel.any() else None,
                "mean_error": float(error[sel].mean()) if sel.any() else None,
            }
        )
    out["by_scale"] = []
    levels = np.unique(np.round(scale[np.isfinite(scale)], 1))
    for s in levels if len(levels) <= 16 else []:  # pyramid levels of a learned detector, not SIFT's continuous scales
        sel = np.isclose(scale, s, atol=0.05)
        out["by_scale"].append({"scale": float(s), "share": float(sel.mean()), "mean_error": float(error[sel].mean())})
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="NAME=RUN (a reconstruction output folder)")
    p.add_argument("--out", type=Path)
    args = p.parse_args()
    results = {}
    for item in args.runs:
        name, folder = item.split("=", 1)
        results[name] = summarize(*observations(Path(folder)))
    print(
        "| run | camera params | 3D pts/img | track | cells | mean reproj. | radial residual by radius | error by radius |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, s in results.items():
        radial = " / ".join(f"{b['mean_radial']:+.3f}" for b in s["by_radius"] if b["mean_radial"] is not None)
        err = " / ".join(f"{b['mean_error']:.3f}" for b in s["by_radius"] if b["mean_error"] is not None)
        print(
            f"| {name} | {s['params']} | {s['points_per_image']:.0f} | {s['track_length']:.2f} | "
            f"{s['cells_covered']:.2f} | {s['mean_error']:.3f} | {radial} | {err} |"
        )
    print()
    for name, s in ((n, s) for n, s in results.items() if s["by_scale"]):
        levels = ", ".join(f"{b['scale']:.0f}: {b['mean_error']:.2f} ({b['share']:.2f})" for b in s["by_scale"])
        print(f"{name} error by keypoint scale (share): {levels}")
    if args.out:
        args.out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
