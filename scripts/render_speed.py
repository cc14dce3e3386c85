"""Rendering speed of the synthetic night flight on the machine that runs it.

For each image size (and supersampling factor) it times: building the city (textures and
boxes), one frame (ray casting and shading, median of ``--repeats``), and the whole scene
written to a temporary folder by ``make_night_flight`` (frames, PNG files, reference),
and reports the overlap of consecutive common frames.  Single-threaded OpenCV.

    python scripts/render_speed.py --out outputs/render_speed.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np


def measure(width: int, height: int, supersample: int, bursts: int, frames: int, repeats: int, noise: str) -> dict:
    from lburst.scenes import night_flight as nf
    from lburst.scenes.city import shade
    from lburst.scenes.raycast import cast, intrinsics

    cfg = nf.NightFlightConfig(
        n_bursts=bursts, frames_per_burst=frames, width=width, height=height, supersample=supersample, noise=noise
    )
    start = time.perf_counter()
    city = nf.make_city(cfg)
    city_s = time.perf_counter() - start

    s = supersample
    K = np.diag([s, s, 1.0]) @ intrinsics(width, height, cfg.hfov_deg)
    R, t = nf.camera_pose(cfg, nf.frame_time(cfg, bursts // 2, frames // 2))
    cast_times, shade_times, frame_times = [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        hits = cast(K, R, t, width * s, height * s, city.lo, city.hi)
        t1 = time.perf_counter()
        shade(city, hits, K[0, 0])
        t2 = time.perf_counter()
        nf.render_view(city, K @ np.diag([1 / s, 1 / s, 1.0]), R, t, width, height, s)
        t3 = time.perf_counter()
        cast_times.append(t1 - t0)
        shade_times.append(t2 - t1)
        frame_times.append(t3 - t2)

    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        nf.make_night_flight(Path(tmp) / "scene", cfg, progress=False)
        scene_s = time.perf_counter() - start
    overlaps = nf.view_overlaps(cfg, city)
    return {
        "size": f"{width}x{height}",
        "supersample": s,
        "bursts": bursts,
        "frames": bursts * frames,
        "boxes": int(len(city.lo)),
        "ground_texels": list(city.ground.shape),
        "city_s": city_s,
        "cast_s": statistics.median(cast_times),
        "shade_s": statistics.median(shade_times),
        "frame_s": statistics.median(frame_times),
        "scene_s": scene_s,
        "overlap_min": float(overlaps.min()),
        "overlap_mean": float(overlaps.mean()),
        "config": dataclasses.asdict(cfg),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", default=["640x480", "320x240"], help="WIDTHxHEIGHT")
    parser.add_argument("--supersample", nargs="+", type=int, default=[1])
    parser.add_argument("--bursts", type=int, default=15)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--noise", default="none", help="noise spec of the written scene")
    parser.add_argument("--out", type=Path, help="JSON file for the results")
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)

    rows = []
    for size in args.sizes:
        width, height = (int(v) for v in size.lower().split("x"))
        for s in args.supersample:
            rows.append(measure(width, height, s, args.bursts, args.frames, args.repeats, args.noise))

    head = f"{'size':>9} {'ss':>2} {'frames':>6} {'city s':>7} {'cast s':>7} {'shade s':>7} {'frame s':>7} {'scene s':>8} {'overlap':>11}"
    print(head)
    print("-" * len(head))
    for r in rows:
        print(
            f"{r['size']:>9} {r['supersample']:>2} {r['frames']:>6} {r['city_s']:>7.2f} {r['cast_s']:>7.3f} "
            f"{r['shade_s']:>7.3f} {r['frame_s']:>7.3f} {r['scene_s']:>8.1f} {r['overlap_min']:>5.2f}/{r['overlap_mean']:.2f}"
        )
    print(
        "scene s: make_night_flight end to end (city, frames, PNG, reference); overlap: min/mean of consecutive common frames"
    )
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        result = {"machine": platform.platform(), "python": sys.version.split()[0], "rows": rows}
        args.out.write_text(json.dumps(result, indent=1))
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
