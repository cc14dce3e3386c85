"""Which putative matches of a reconstruction are right, judged by the scene's reference poses.

For every putative match that ``lburst bench reconstruction`` stored (``matches.h5`` and
``features.h5`` of OUT/<method>/<scene>/), the Sampson distance to the epipolar geometry of
the scene's ``reference.json`` (its cameras, with their distortion, and poses) is its error in
pixels.  Tables, one row per method:

- errors: the share of putative matches under 0.5, 1, 2 and 4 px and over 8 px (a match
  under 4 px is counted right, one over 8 px wrong), and how bunched the keypoints are: the
  share of an image's keypoints in its densest tenth of 40-px cells, averaged over the images;
- by keypoint score: right and wrong matches among the keypoints of each score quartile of
  the method's own keypoints (a match's score: the lower of its two keypoints');
- by scale change: right matches summed over the pairs whose scale change (a similarity
  fitted to the right matches of all methods together) lies in each band;
- by gap (a sequence: a flight, a walk): right matches, and those under 1 px, summed over the
  pairs that lie 1, 2, ... images apart in name order, the baseline growing with the gap, and
  their coverage: the share of the later image's 40-px cells that hold a right match, averaged
  over the pairs (matches bunched in a few places hold a pose less well than as many spread out);
- relative pose: the essential matrix of every pair's putative matches (COLMAP's LO-RANSAC
  at ``POSE_PX`` px, once per RANSAC seed, ``--pose-seeds``) against the reference relative
  pose; a pair's error is the larger of the rotation's and the translation direction's
  angular errors (180 degrees where the estimate fails), summarised as the area under its
  cumulative curve to 5, 10 and 20 degrees (the pose AUC of SuperGlue's and LightGlue's
  evaluations): a measure of pose without COLMAP's run-to-run spread;
- on a rendered flight (a scene with ``night_flight.json``), the full image error as well:
  each keypoint of the earlier image goes to 3D at the renderer's depth and is projected into
  the later image, so a match that slides along its epipolar line, which the Sampson distance
  and a geometric verification cannot see, is counted (``along_line``: under 4 px from the
  line, over 8 px from the point), and the right matches of every pair are listed.

    python scripts/match_errors.py outputs/scenes/sacre_coeur_g50 \
        outputs/recon_seeds_g50/lburst_*/sacre_coeur_g50 outputs/recon_seeds_g50/B5.pt*/sacre_coeur_g50 \
        --labels lburst-b5 published --out outputs/match_errors_g50.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import h5py
import numpy as np
import pycolmap

from lburst.errors import LBurstValueError
from lburst.scenes.night_flight import CONFIG_FILE, NightFlightConfig, make_city, render_view
from lburst.scenes.raycast import intrinsics, transfer
from lburst.sfm.poses import AUC_DEG, pose_auc
from lburst.sfm.reference import Reference
from lburst.sfm.scene import reference_cameras

RIGHT_PX, WRONG_PX = 4.0, 8.0
ERROR_EDGES = (0.5, 1.0, 2.0, 4.0)
SCALE_BANDS = ((1.0, 1.2), (1.2, 1.5), (1.5, np.inf))
MIN_FIT = 30  # right matches needed to fit a pair's similarity
CELL_PX = 40  # the grid of the coverage: the share of these cells of the later image that hold a right match
POSE_PX = 1.0  # RANSAC threshold of the relative pose, in pixels
POSE_SEEDS = 5  # RANSAC seeds by default: every pair's pose is estimated once per seed
POSE_TRIALS = 10_000  # at most, per estimate (COLMAP: 100,000; a pair that needs more is lost anyway)


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def reference_geometry(scene: Path):
    """Cameras (pycolmap) and world-to-camera poses (R, t) by image name."""
    path = scene / "reference.json"
    cameras = {  # per-image cameras (a photo set) or the one camera (a synthetic flight)
        name: pycolmap.Camera(model=c["model"], width=c["width"], height=c["height"], params=c["params"])
        for name, c in reference_cameras(path).items()
    }
    return cameras, Reference.load(path).poses


def relative_pose(poses, a: str, b: str) -> tuple[np.ndarray, np.ndarray]:
    """The reference pose of camera ``b`` from camera ``a``: ``(R, t)``, ``x_b = R x_a + t``."""
    (ra, ta), (rb, tb) = poses[a], poses[b]
    rot = rb @ ra.T
    return rot, tb - rot @ ta


def sampson_px(cameras, poses, a: str, b: str, ka: np.ndarray, kb: np.ndarray) -> np.ndarray:
    """Sampson distance (px, at the geometric mean focal length) of matches ka <-> kb."""
    xa = np.c_[cameras[a].cam_from_img(ka.astype(np.float64)), np.ones(len(ka))]
    xb = np.c_[cameras[b].cam_from_img(kb.astype(np.float64)), np.ones(len(kb))]
    rot, t = relative_pose(poses, a, b)
    essential = skew(t) @ rot
    la, lb = xa @ essential.T, xb @ essential
    d2 = np.sum(xb * la, 1) ** 2 / (la[:, 0] ** 2 + la[:, 1] ** 2 + lb[:, 0] ** 2 + lb[:, 1] ** 2)
    return np.sqrt(d2) * np.sqrt(cameras[a].params[0] * cameras[b].params[0])


def rendered_depths(scene: Path, poses) -> dict | None:
    """Z-depth (H, W) of every reference image of a rendered flight, and its intrinsics;
    ``None`` for a scene without ``night_flight.json`` (a photo set)."""
    path = scene / CONFIG_FILE
    if not path.is_file():
        return None
    cfg = NightFlightConfig.from_dict(json.loads(path.read_text()))
    city = make_city(cfg)
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    depth = {name: render_view(city, K, R, t, cfg.width, cfg.height)[1] for name, (R, t) in poses.items()}
    return {"K": K, "depth": depth}


def transfer_px(truth: dict, poses, a: str, b: str, ka: np.ndarray, kb: np.ndarray) -> np.ndarray:
    """(N, 2): the full image error (px) of matches ka <-> kb, ``kb`` against ``ka`` taken to 3D
    at the renderer's depth and projected into ``b``; and its signed component along the
    epipolar line, the image of ``ka``'s ray, positive towards greater depth along that ray (a
    positive error reads as a farther point, that is a shorter baseline).  NaN where the depth
    is not one surface (the sky, or within 1 % of a depth edge in the 3x3 pixels around the
    keypoint)."""
    depth, K = truth["depth"][a], truth["K"]
    h, w = depth.shape
    x = np.clip(np.round(ka[:, 0]).astype(int), 1, w - 2)
    y = np.clip(np.round(ka[:, 1]).astype(int), 1, h - 2)
    z = depth[y, x]
    around = np.stack([depth[y + dy, x + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(z) & (np.abs(around - z).max(0) < 0.01 * z)
    # keypoint centres at integers, the renderer's at +0.5
    seen, z_b = transfer(K, ka + 0.5, np.where(valid, z, 1.0), poses[a], poses[b])
    true_b = seen - 0.5
    error = kb - true_b
    epipole = K @ relative_pose(poses, a, b)[1]  # camera a's centre, where the ray starts, seen from b (z < 0: behind)
    deeper = true_b - (epipole[:2] / epipole[2] - 0.5)
    deeper *= np.sign(epipole[2]) / np.maximum(np.linalg.norm(deeper, axis=1, keepdims=True), 1e-9)
    found = np.c_[np.linalg.norm(error, axis=1), np.sum(error * deeper, axis=1)]
    return np.where((valid & (z_b > 0))[:, None], found, np.nan)


def relative_pose_error(cameras, poses, a: str, b: str, ka: np.ndarray, kb: np.ndarray, seed: int = 0) -> float:
    """Degrees: the larger angular error of the rotation and of the translation direction of
    the pose that COLMAP's LO-RANSAC (``pycolmap.estimate_essential_matrix``, ``POSE_PX``,
    seeded) finds from ``ka <-> kb`` (180 when it finds none)."""
    if len(ka) < 5:
        return 180.0
    options = pycolmap.RANSACOptions(max_error=POSE_PX, random_seed=seed, max_num_trials=POSE_TRIALS)
    found = pycolmap.estimate_essential_matrix(
        ka.astype(np.float64), kb.astype(np.float64), cameras[a], cameras[b], options
    )
    if found is None:
        return 180.0
    pose = found["cam2_from_cam1"]
    rot, t = pose.rotation.matrix(), pose.translation
    rot_true, t_true = relative_pose(poses, a, b)
    cos_r = (np.trace(rot.T @ rot_true) - 1) / 2
    err_r = np.degrees(np.arccos(np.clip(cos_r, -1, 1)))
    cos_t = float(t @ t_true) / (np.linalg.norm(t) * np.linalg.norm(t_true) + 1e-12)
    err_t = np.degrees(np.arccos(np.clip(cos_t, -1, 1)))
    return float(max(err_r, min(err_t, 180 - err_t)))


def putative_matches(run: Path, cameras, poses, pose_seeds: int = POSE_SEEDS, truth: dict | None = None) -> dict:
    """Per pair (a, b): keypoints of both sides, the lower score, the error in px, and (with
    ``truth``, :func:`rendered_depths`) the full image error; and the relative pose errors of
    every pair under RANSAC seeds ``0 .. pose_seeds - 1``."""
    out, pose_errors = {}, []
    with h5py.File(run / "features.h5", "r") as feats:  # each image's keypoints and scores, read once
        kps = {name: feats[name]["keypoints"][()] for name in feats}
        scores = {name: feats[name]["scores"][()] for name in feats}
    with h5py.File(run / "matches.h5", "r") as matches:
        for a in matches:
            for b in matches[a]:
                m = matches[a][b]["matches0"][()]
                i = np.flatnonzero(m >= 0)
                ka, kb = kps[a][i], kps[b][m[i]]
                score = np.minimum(scores[a][i], scores[b][m[i]])
                na, nb = Path(a).stem, Path(b).stem
                if nb < na:  # the earlier image first, so the full error is measured in the later one
                    na, nb, ka, kb = nb, na, kb, ka
                full = None if truth is None else transfer_px(truth, poses, na, nb, ka, kb)
                out[(na, nb)] = (ka, kb, score, sampson_px(cameras, poses, na, nb, ka, kb), full)
                pose_errors += [relative_pose_error(cameras, poses, na, nb, ka, kb, seed) for seed in range(pose_seeds)]
    sizes = {name: (int(c.width), int(c.height)) for name, c in cameras.items()}
    bunching = float(np.mean([densest_tenth(kps[n], sizes[Path(n).stem]) for n in kps if Path(n).stem in sizes]))
    return {
        "pairs": out,
        "scores": np.concatenate(list(scores.values())),
        "pose_errors": pose_errors,
        "sizes": sizes,
        "densest_tenth": bunching,
    }


def densest_tenth(points: np.ndarray, size: tuple[int, int]) -> float:
    """The share of an image's keypoints that lie in its densest tenth of ``CELL_PX`` cells
    (0.1 for keypoints spread evenly)."""
    cols, rows = -(-size[0] // CELL_PX), -(-size[1] // CELL_PX)
    cell = np.clip(points[:, 0] // CELL_PX, 0, cols - 1) * rows + np.clip(points[:, 1] // CELL_PX, 0, rows - 1)
    counts = np.sort(np.bincount(cell.astype(int), minlength=cols * rows))[::-1]
    return float(counts[: max(1, round(0.1 * cols * rows))].sum() / max(1, len(points)))


def coverage(points: np.ndarray, size: tuple[int, int]) -> float:
    """The share of the ``CELL_PX`` cells of an image of ``size`` (width, height) holding a point."""
    cols, rows = -(-size[0] // CELL_PX), -(-size[1] // CELL_PX)
    cells = {(int(x // CELL_PX), int(y // CELL_PX)) for x, y in points}
    return len(cells) / (cols * rows)


def pair_scales(runs: list[dict]) -> dict:
    """Scale change per pair, from a similarity fitted to all runs' right matches."""
    scales = {}
    for pair in runs[0]["pairs"]:
        parts = [(r["pairs"][pair][0], r["pairs"][pair][1]) for r in runs if pair in r["pairs"]]
        right = [r["pairs"][pair][3] < RIGHT_PX for r in runs if pair in r["pairs"]]
        ka = np.concatenate([p[0][ok] for p, ok in zip(parts, right)])
        kb = np.concatenate([p[1][ok] for p, ok in zip(parts, right)])
        if len(ka) >= MIN_FIT:
            m, _ = cv2.estimateAffinePartial2D(ka, kb, ransacReprojThreshold=WRONG_PX)
            if m is not None:
                s = float(np.hypot(m[0, 0], m[1, 0]))
                scales[pair] = max(s, 1 / s)
    return scales


def by_gap(run: dict, order: list[str]) -> dict:
    """Right matches (and those under 1 px) summed over the pairs ``gap`` images apart in ``order``."""
    rank = {name: i for i, name in enumerate(order)}
    gaps: dict[int, dict] = {}
    for (a, b), (_, kb, _, errors, _) in run["pairs"].items():
        row = gaps.setdefault(abs(rank[a] - rank[b]), {"pairs": 0, "right": 0, "under_1px": 0, "coverage": 0.0})
        row["pairs"] += 1
        row["right"] += int(np.sum(errors < RIGHT_PX))
        row["under_1px"] += int(np.sum(errors < 1.0))
        row["coverage"] += coverage(kb[errors < RIGHT_PX], run["sizes"][b])
    for row in gaps.values():
        row["coverage"] /= row["pairs"]
    return {str(g): gaps[g] for g in sorted(gaps)}


def full_error_summary(run: dict, order: list[str]) -> dict:
    """On a rendered flight: matches judged by their full image error, by the pair's gap (with
    the mean of the right ones' error along the epipolar line, towards greater depth), and the
    right ones of every pair (``"a b"``)."""
    rank = {name: i for i, name in enumerate(order)}
    gaps: dict[int, dict] = {}
    pairs = {}
    for (a, b), (_, kb, _, sampson, truth) in run["pairs"].items():
        full, deeper = truth[:, 0], truth[:, 1]
        right = full < RIGHT_PX
        row = gaps.setdefault(
            abs(rank[a] - rank[b]), {"pairs": 0, "measured": 0, "right": 0, "under_1px": 0, "along_line": 0}
        )
        row["pairs"] += 1
        row["coverage"] = row.get("coverage", 0.0) + coverage(kb[right], run["sizes"][b])
        row["measured"] += int(np.isfinite(full).sum())
        row["right"] += int(right.sum())
        row["under_1px"] += int((full < 1.0).sum())
        row["along_line"] += int(((sampson < RIGHT_PX) & (full > WRONG_PX)).sum())
        row["deeper_px"] = row.get("deeper_px", 0.0) + float(deeper[right].sum())
        pairs[f"{a} {b}"] = int(right.sum())
    for row in gaps.values():
        row["coverage"] /= row["pairs"]
        row["deeper_px"] /= max(row["right"], 1)
    total = {k: sum(g[k] for g in gaps.values()) for k in ("measured", "right", "under_1px", "along_line")}
    return {**total, "by_gap": {str(g): gaps[g] for g in sorted(gaps)}, "by_pair": pairs}


def summary(run: dict, scales: dict, order: list[str]) -> dict:
    errors = np.concatenate([p[3] for p in run["pairs"].values()])
    score = np.concatenate([p[2] for p in run["pairs"].values()])
    edges = np.quantile(run["scores"], [0, 0.25, 0.5, 0.75, 1])
    edges[0], edges[-1] = -np.inf, np.inf
    quartile = np.clip(np.searchsorted(edges, score, side="right") - 1, 0, 3)
    by_scale = []
    for lo, hi in SCALE_BANDS:
        pairs = [k for k, s in scales.items() if lo <= s < hi and k in run["pairs"]]
        by_scale.append(
            {
                "band": [lo, hi],
                "pairs": len(pairs),
                "right": int(sum((run["pairs"][k][3] < RIGHT_PX).sum() for k in pairs)),
            }
        )
    return {
        "putative": int(len(errors)),
        "keypoints_in_densest_tenth": run["densest_tenth"],
        "putative_pairs": len(run["pairs"]),
        "share_under": {str(e): float(np.mean(errors < e)) for e in ERROR_EDGES},
        "share_wrong": float(np.mean(errors > WRONG_PX)),
        "right": int(np.sum(errors < RIGHT_PX)),
        "wrong": int(np.sum(errors > WRONG_PX)),
        "by_score_quartile": [
            {
                "right": int(np.sum((quartile == q) & (errors < RIGHT_PX))),
                "wrong": int(np.sum((quartile == q) & (errors > WRONG_PX))),
            }
            for q in range(4)
        ],
        "by_scale": by_scale,
        "by_gap": by_gap(run, order),
        **({"full_error": full_error_summary(run, order)} if next(iter(run["pairs"].values()))[4] is not None else {}),
        **(
            {"pose_auc": pose_auc(run["pose_errors"]), "pose_median_deg": float(np.median(run["pose_errors"]))}
            if run["pose_errors"]
            else {}
        ),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", type=Path, help="scene folder with reference.json")
    p.add_argument("runs", type=Path, nargs="+", help="OUT/<method>/<scene> folders of lburst bench reconstruction")
    p.add_argument("--labels", nargs="+", help="a name per run (default: the method folder's)")
    p.add_argument("--out", type=Path, help="write the tables as JSON")
    p.add_argument(
        "--pose-seeds",
        type=int,
        default=POSE_SEEDS,
        help=f"RANSAC seeds of each pair's relative pose (0: no pose table; default {POSE_SEEDS})",
    )
    args = p.parse_args()
    labels = args.labels or [r.parent.name for r in args.runs]
    if len(labels) != len(args.runs):
        p.error(f"{len(args.runs)} runs but {len(labels)} labels")
    for path in [args.scene / "reference.json"] + [
        r / name for r in args.runs for name in ("features.h5", "matches.h5")
    ]:
        if not path.is_file():
            p.error(f"{path}: no such file (a scene with reference.json, and runs of lburst bench reconstruction)")
    try:
        cameras, poses = reference_geometry(args.scene)
    except LBurstValueError as err:
        p.error(str(err))
    if args.pose_seeds < 0:
        p.error(f"--pose-seeds must be >= 0, got {args.pose_seeds}")
    truth = rendered_depths(args.scene, poses)
    runs = [putative_matches(r, cameras, poses, args.pose_seeds, truth) for r in args.runs]
    scales = pair_scales(runs)
    order = sorted(poses)
    results = {label: summary(run, scales, order) for label, run in zip(labels, runs)}

    print(
        "| method | putative | <0.5 px | <1 px | <2 px | <4 px (right) | >8 px (wrong) | keypoints in the densest "
        "tenth of cells |\n|---|---|---|---|---|---|---|---|"
    )
    for label, r in results.items():
        shares = " | ".join(f"{r['share_under'][str(e)]:.3f}" for e in ERROR_EDGES)
        bunching = r["keypoints_in_densest_tenth"]
        print(f"| {label} | {r['putative']} | {shares} | {r['share_wrong']:.3f} | {bunching:.3f} |")
    print("\nright / wrong matches by the score quartile of the method's keypoints (lowest first):\n")
    print("| method | Q1 | Q2 | Q3 | Q4 |\n|---|---|---|---|---|")
    for label, r in results.items():
        print(f"| {label} | " + " | ".join(f"{q['right']} / {q['wrong']}" for q in r["by_score_quartile"]) + " |")
    print("\nright matches by the pair's scale change:\n")
    bands = [f"{lo:g}-{hi:g}x" for lo, hi in SCALE_BANDS]
    print("| method | " + " | ".join(bands) + " |\n|---|" + "---|" * len(bands))
    for label, r in results.items():
        print(f"| {label} | " + " | ".join(f"{b['right']} ({b['pairs']} pairs)" for b in r["by_scale"]) + " |")
    gaps = sorted({g for r in results.values() for g in r["by_gap"]}, key=int)
    print(f"\nright matches (under 1 px), and their coverage of {CELL_PX}-px cells, by the pair's gap in name order:\n")
    print("| method | " + " | ".join(gaps) + " |\n|---|" + "---|" * len(gaps))
    for label, r in results.items():
        cells = [r["by_gap"].get(g, {"right": 0, "under_1px": 0, "coverage": 0.0}) for g in gaps]
        print(
            f"| {label} | " + " | ".join(f"{c['right']} ({c['under_1px']}), {c['coverage']:.3f}" for c in cells) + " |"
        )
    if truth is not None:
        print(
            "\nfull image error at the renderer's depth, by the pair's gap: right (under 1 px), coverage / along the"
            " line; mean error of the right ones along their line, towards greater depth (px)\n"
        )
        print("| method | " + " | ".join(gaps) + " |\n|---|" + "---|" * len(gaps))
        for label, r in results.items():
            cells = [r["full_error"]["by_gap"].get(g) for g in gaps]
            text = [
                f"{c['right']} ({c['under_1px']}), {c['coverage']:.3f} / {c['along_line']}; {c['deeper_px']:+.3f}"
                if c
                else ""
                for c in cells
            ]
            print(f"| {label} | " + " | ".join(text) + " |")
    if args.pose_seeds:
        print(f"\nrelative pose (LO-RANSAC at {POSE_PX:g} px, {args.pose_seeds} seeds a pair), AUC and median error:\n")
        print("| method | pairs | " + " | ".join(f"AUC@{d}" for d in AUC_DEG) + " | median (deg) |")
        print("|---|---|" + "---|" * (len(AUC_DEG) + 1))
        for label, r in results.items():
            aucs = " | ".join(f"{r['pose_auc'][str(d)]:.3f}" for d in AUC_DEG)
            print(f"| {label} | {r['putative_pairs']} | {aucs} | {r['pose_median_deg']:.2f} |")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(
            json.dumps({"scene": str(args.scene), "runs": [str(r) for r in args.runs], "results": results}, indent=1)
        )


if __name__ == "__main__":
    main()
