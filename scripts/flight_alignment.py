"""How well a rendered flight's bursts are aligned: each frame's estimated warp
(:func:`lburst.burst.align.estimate_warps`) against the renderer's exact motion of every pixel
of the common frame (its depth and the frames' poses), for each warp model.

A translation cannot follow a camera that moves along its view: its frames zoom about the
focus of expansion, and buildings add parallax that no single warp follows.  The median
error is over the pixels that see a surface, per frame; the table gives each burst's worst
frame, and the JSON every frame.

With ``--features``, the keypoints that benchmark runs found on those bursts (their
``features.h5``) are counted by how far the first warp model leaves their pixel from where
it truly is, in the frame where that is furthest: a network that reads aligned bursts finds
fewer keypoints where the alignment leaves motion it was not trained on.  ``--still`` counts,
for each method spec, the keypoints of motionless bursts instead: each common frame rendered
without noise, under five independent draws of the scene's noise (seeded), so that nothing is
left to align and what remains is the content of those pixels.

    python scripts/flight_alignment.py outputs/scenes/flight_moonless --out outputs/flight_alignment.json \
        --features outputs/recon_flight_pad/lburst_*/flight_moonless outputs/recon_flight_pad/_order*/flight_moonless \
        --still lburst "lburst:$LBURST_SHARED/anchors/RoBLo_N16_B5.pt,frame_order=published"
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import h5py
import numpy as np

from lburst.burst.align import WARPS, estimate_warps
from lburst.burst.io import load_burst
from lburst.methods import create
from lburst.noise import noise_from_spec
from lburst.scenes.night_flight import (
    CONFIG_FILE,
    NightFlightConfig,
    burst_name,
    burst_poses,
    make_city,
    reference,
    render_view,
)
from lburst.scenes.raycast import intrinsics, transfer


def true_positions(cfg: NightFlightConfig, city, burst: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Where each pixel of the common frame lies in every frame of ``burst`` ((H*W, 2) each, pixel
    centres at integers), and which pixels see a surface."""
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    R, t = reference(cfg).poses[burst_name(burst)]
    _, depth = render_view(city, K, R, t, cfg.width, cfg.height)
    u, v = np.meshgrid(np.arange(cfg.width) + 0.5, np.arange(cfg.height) + 0.5)
    z = depth.reshape(-1)
    seen = np.isfinite(z)
    uv = np.c_[u.reshape(-1), v.reshape(-1)]
    positions = [transfer(K, uv, np.where(seen, z, 1.0), (R, t), pose)[0] - 0.5 for pose in burst_poses(cfg, burst)]
    return positions, seen


#: edges (px) of the residual-motion bands of ``--features``
RESIDUAL_BANDS = (0.0, 1.5, 2.5, 4.0, np.inf)


def keypoint_density(keypoints: dict[str, np.ndarray], residuals: dict[str, np.ndarray]) -> dict:
    """Keypoints per 1,000 pixels of each residual band (``residuals``: per image (H, W), NaN
    where no surface is seen), over the images of ``keypoints`` (image stem: (K, 2))."""
    found, area = np.zeros(len(RESIDUAL_BANDS) - 1), np.zeros(len(RESIDUAL_BANDS) - 1)
    for name, k in keypoints.items():
        residual = residuals[name]
        h, w = residual.shape
        at = residual[
            np.clip(np.round(k[:, 1]).astype(int), 0, h - 1), np.clip(np.round(k[:, 0]).astype(int), 0, w - 1)
        ]
        found += np.histogram(at[np.isfinite(at)], RESIDUAL_BANDS)[0]
        area += np.histogram(residual[np.isfinite(residual)], RESIDUAL_BANDS)[0]
    return {
        "bands_px": [float(b) for b in RESIDUAL_BANDS],
        "area_share": (area / area.sum()).round(4).tolist(),
        "keypoints_per_1000px": (1000 * found / np.maximum(area, 1)).round(3).tolist(),
    }


def run_keypoints(run: Path) -> dict[str, np.ndarray]:
    """The keypoints of every image of a benchmark run's ``features.h5``, by image stem."""
    with h5py.File(run / "features.h5", "r") as f:
        return {Path(name).stem: f[name]["keypoints"][()] for name in f}


def still_burst(cfg: NightFlightConfig, city, burst: int, frames: int = 5) -> np.ndarray:
    """A motionless burst of ``burst``'s common frame: the noise-free render under ``frames``
    independent draws of the scene's noise (seeded by the burst and the frame)."""
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    R, t = reference(cfg).poses[burst_name(burst)]
    image, _ = render_view(city, K, R, t, cfg.width, cfg.height, cfg.supersample)
    image = image * cfg.exposure
    noise = noise_from_spec(cfg.noise) if cfg.noise not in ("", "none") else None
    draws = [
        image if noise is None else noise(image, np.random.default_rng([cfg.seed, 7, burst, k])) for k in range(frames)
    ]
    return np.stack([np.clip(np.round(d), 0, 255).astype(np.uint8) for d in draws])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", type=Path, help=f"a rendered flight (with {CONFIG_FILE})")
    p.add_argument("--warps", nargs="+", default=list(WARPS), choices=WARPS)
    p.add_argument("--out", type=Path, help="write every frame's median error as JSON")
    p.add_argument(
        "--features", type=Path, nargs="+", default=[], help="OUT/<method>/<scene> runs of lburst bench reconstruction"
    )
    p.add_argument("--still", nargs="+", default=[], metavar="SPEC", help="method specs to run on motionless bursts")
    p.add_argument("--top-k", type=int, default=8000, help="keypoints per image of --still (default 8000)")
    args = p.parse_args()
    if not (args.scene / CONFIG_FILE).is_file():
        p.error(f"{args.scene / CONFIG_FILE}: no such file (a scene of lburst simulate flight)")
    cfg = NightFlightConfig.from_dict(json.loads((args.scene / CONFIG_FILE).read_text()))
    city = make_city(cfg)
    grid = np.stack(np.meshgrid(np.arange(cfg.width), np.arange(cfg.height)), -1).reshape(-1, 2).astype(float)
    for run in args.features:
        if not (run / "features.h5").is_file():
            p.error(f"{run / 'features.h5'}: no such file (a run of lburst bench reconstruction)")
    extractors = {spec: create(spec, top_k=args.top_k) for spec in args.still}
    still: dict[str, dict[str, np.ndarray]] = {spec: {} for spec in args.still}
    results, residuals = {}, {}
    print("| burst | " + " | ".join(f"{w}: worst frame's median error (px)" for w in args.warps) + " |")
    print("|---|" + "---|" * len(args.warps))
    for i in range(cfg.n_bursts):
        name = burst_name(i)
        positions, seen = true_positions(cfg, city, i)
        burst = load_burst(args.scene / name)
        row = {}
        for warp in args.warps:
            warps = estimate_warps(burst, warp=warp)
            errors = np.stack(
                [np.linalg.norm(grid @ w[:, :2].T + w[:, 2] - q, axis=1) for w, q in zip(warps, positions)]
            )
            row[warp] = [float(np.median(e[seen])) for e in errors]
            if warp == args.warps[0]:
                residuals[name] = np.where(seen, errors.max(0), np.nan).reshape(cfg.height, cfg.width)
        results[name] = row
        for spec, extract in extractors.items():
            still[spec][name] = extract(still_burst(cfg, city, i))["keypoints"]
        print(f"| {name} | " + " | ".join(f"{max(row[w]):.2f}" for w in args.warps) + " |")
    for warp in args.warps:
        worst = [max(results[name][warp]) for name in results]
        print(
            f"{warp}: median over bursts of the worst frame {np.median(worst):.2f} px (range {min(worst):.2f}-{max(worst):.2f})"
        )
    density = {str(run): keypoint_density(run_keypoints(run), residuals) for run in args.features}
    density.update({f"{spec} (still)": keypoint_density(found, residuals) for spec, found in still.items()})
    if density:
        bands = [f"{lo:g}-{hi:g} px" for lo, hi in zip(RESIDUAL_BANDS[:-1], RESIDUAL_BANDS[1:])]
        print(f"\nkeypoints per 1,000 px by the motion that '{args.warps[0]}' alignment leaves at them:\n")
        print("| run | " + " | ".join(bands) + " |\n|---|" + "---|" * len(bands))
        share = next(iter(density.values()))["area_share"]
        print("| (share of the image) | " + " | ".join(f"{a:.3f}" for a in share) + " |")
        for run, d in density.items():
            print(f"| {run} | " + " | ".join(f"{v:.2f}" for v in d["keypoints_per_1000px"]) + " |")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"bursts": results, "keypoint_density": density}, indent=1))


if __name__ == "__main__":
    main()
