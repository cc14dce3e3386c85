"""``lburst bench reconstruction``: every method on every scene (:mod:`lburst.bench.reconstruction`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.bench.reconstruction import run_benchmark
from lburst.burst.io import atomic_path
from lburst.cli.numbers import integer
from lburst.cli.options import parse_method
from lburst.cli.reconstruct_options import BENCH_OPTIONS, add_reconstruct_arguments, bench_options
from lburst.scenes.reference_spread import summary
from lburst.sfm.metrics import markdown_table, seed_table


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenes", nargs="+", help="scene folders (see lburst reconstruct)")
    parser.add_argument(
        "--methods",
        nargs="+",
        type=parse_method,
        default=["sift", "merge+sift", "lburst"],
        help="method specs (a learned method keeps 8000 keypoints per image unless the spec sets top_k=N)",
    )
    parser.add_argument("--out", required=True, help="output folder: OUT/<method>/<scene>/, table.md, results.json")
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
    parser.add_argument("--force", action="store_true", help="rerun finished (method, scene) pairs")
    reconstruction = parser.add_argument_group("each run's reconstruction (as in lburst reconstruct)")
    add_reconstruct_arguments(reconstruction, BENCH_OPTIONS)


def main(args: argparse.Namespace) -> int:
    report = run_benchmark(
        args.scenes,
        args.methods,
        args.out,
        force=args.force,
        seeds=args.seeds,
        features_from=args.features_from,
        **bench_options(args),
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
