"""``lburst bench reconstruction``: every method on every scene (:mod:`lburst.bench.reconstruction`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.bench.reconstruction import run_benchmark
from lburst.burst.io import atomic_path
from lburst.cli.numbers import integer
from lburst.cli.options import add_matcher_argument
from lburst.scenes.reference_spread import summary
from lburst.sfm.colmap import DEFAULT_THREADS
from lburst.sfm.metrics import markdown_table, seed_table
from lburst.sfm.options import RECORDING_OVERLAP, SCENE_OVERLAP


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenes", nargs="+", help="scene folders (see lburst reconstruct)")
    parser.add_argument(
        "--methods",
        nargs="+",
        default=["sift", "merge+sift", "lburst"],
        help="method specs (a learned method keeps 8000 keypoints per image unless the spec sets top_k=N)",
    )
    parser.add_argument("--out", required=True, help="output folder: OUT/<method>/<scene>/, table.md, results.json")
    parser.add_argument("--pairs", choices=("auto", "exhaustive", "sequential", "positions"), default="auto")
    parser.add_argument(
        "--overlap",
        type=integer(1),
        help=f"sequential pairs: neighbours on each side (default {SCENE_OVERLAP} for a scene, "
        f"{RECORDING_OVERLAP} for a recording, as in lburst reconstruct)",
    )
    parser.add_argument("--fallback-exhaustive", action="store_true")
    parser.add_argument("--mapper", choices=("incremental", "global"), default="incremental")
    parser.add_argument(
        "--camera",
        choices=("auto", "default", "reference", "reference-focal"),
        default="auto",
        help="intrinsics prior, as in lburst reconstruct; reference-focal: COLMAP's default camera "
        "(SIMPLE_RADIAL, centred) at the reference.json cameras' focal length, refined unless --fix-intrinsics",
    )
    parser.add_argument(
        "--fix-intrinsics",
        action="store_true",
        help="hold the cameras' intrinsics fixed (with --camera reference: the scenes' calibration)",
    )
    parser.add_argument(
        "--single-camera",
        action="store_const",
        const=True,
        help="one camera for all images of a scene (a recording has one by default)",
    )
    parser.add_argument("--threads", type=integer(1, 1024), default=DEFAULT_THREADS)
    parser.add_argument(
        "--seeds",
        nargs="+",
        type=integer(0),
        default=[0],
        help="run each method on each scene once per seed of COLMAP's RANSAC and mapper, and add a table of "
        "medians and ranges (default: 0); runs are repeatable for one seed and thread count",
    )
    parser.add_argument(
        "--features-from",
        metavar="OTHER",
        help="read the features of another benchmark's output folder (OTHER/<method>/<scene>/features) where "
        "they are of the same method and bursts, e.g. to run a second camera protocol without extracting again",
    )
    add_matcher_argument(parser)
    parser.add_argument("--force", action="store_true", help="rerun finished (method, scene) pairs")


def main(args: argparse.Namespace) -> int:
    report = run_benchmark(
        args.scenes,
        args.methods,
        args.out,
        force=args.force,
        seeds=args.seeds,
        features_from=args.features_from,
        pairs=args.pairs,
        overlap=args.overlap,
        fallback_exhaustive=args.fallback_exhaustive,
        mapper=args.mapper,
        camera=args.camera,
        single_camera=args.single_camera,
        **({"fix_intrinsics": True} if args.fix_intrinsics else {}),  # unset: the key of earlier runs
        num_threads=args.threads,
        matcher=args.matcher,
    )
    rows = report["rows"]
    if len(report["seeds"]) > 1:  # one row per run: say which seed
        rows = [{**r, "scene": f"{r['scene']} (seed {r['seed']})"} for r in rows]
    table = markdown_table(rows + report["means"])
    if report["by_seed"]:
        table += "\n\nOver the seeds " + ", ".join(map(str, report["seeds"])) + ":\n\n" + seed_table(report["by_seed"])
    if report["reference_spread"]:
        table += "\n\nHow precise the references are (ATE below this does not rank methods):\n\n" + "\n".join(
            f"- {scene}: {summary(record)}" for scene, record in report["reference_spread"].items()
        )
    with atomic_path(Path(args.out) / "table.md") as tmp:
        tmp.write_text(table + "\n")
    print(table)
    return 0
