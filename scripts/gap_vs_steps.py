"""How the gap to a reference model moves with training steps, on the noisy-burst
homography protocol (``lburst bench homography``): every snapshot of the given runs, the
runs' current ``last.pt``, and the ``--also`` methods, all in one benchmark run.

    python scripts/gap_vs_steps.py training/lburst-b5-cpu training/lburst-b1-cpu \\
        --data ../shared/data/homography --sigma 50 100 --also lburst r2d2 sift \\
        --out outputs/gap_vs_steps

A run trained on aligned bursts (``--preset aligned``) is measured as ``align+lburst:CKPT``
with ``--wrap align+``.

The reference defaults to the published ``RoBLo_N16_B5.pt`` (in
``$LBURST_SHARED/anchors``) in the frame order it was trained with, its best setting.
Prints one row per checkpoint: MMA@3 and MMA@1 per noise level and the MMA@3 difference
to the reference (positive: ahead of it); writes ``OUT/gap_vs_steps.json`` and the
benchmark's own files in ``OUT``.  Features are cached in ``OUT/cache`` (keyed on the
weights' content), so a rerun after more training only runs the new checkpoints.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

from lburst.bench.homography import run_homography_benchmark
from lburst.burst.io import atomic_path
from lburst.methods.learned import weights_file
from lburst.paths import shared_dir


def checkpoint_step(path: Path) -> int | None:
    """The training step a checkpoint was saved at (run state, snapshot or shipped file;
    ``None`` for a published checkpoint)."""
    state = torch.load(path, map_location="cpu", weights_only=True)
    step = state.get("step", state.get("meta", {}).get("step"))
    return None if step is None else int(step)


def run_checkpoints(run: Path) -> list[tuple[int, Path]]:
    """``(step, file)`` of a run's snapshots and of its ``last.pt`` (if newer), by step."""
    found = {checkpoint_step(p): p for p in sorted((run / "snapshots").glob("step_*.pt"))}
    if (run / "last.pt").is_file():
        step = checkpoint_step(run / "last.pt")
        found.setdefault(step, run / "last.pt")
    if not found:
        raise FileNotFoundError(f"{run}: no snapshots/step_*.pt and no last.pt")
    return sorted(found.items())


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="*", type=Path, help="training run folders (snapshots/, last.pt)")
    p.add_argument(
        "--data", type=Path, default=None, help="homography sequences (default: $LBURST_SHARED/data/homography)"
    )
    p.add_argument("--sigma", type=float, nargs="+", default=[50, 100])
    p.add_argument("--reference", help="method spec to measure the gap to (default: the published RoBLo_N16_B5)")
    p.add_argument("--steps", type=int, nargs="*", help="only the runs' checkpoints at these steps")
    p.add_argument(
        "--wrap",
        default="",
        metavar="WRAPPER+",
        help="wrapper spec put before each run's checkpoint, e.g. 'align+' for a run trained on aligned bursts",
    )
    p.add_argument("--also", nargs="*", default=[], help="more method specs, as rows (e.g. lburst r2d2 sift)")
    p.add_argument("--out", type=Path, default=Path("outputs/gap_vs_steps"))
    args = p.parse_args()
    data = args.data or shared_dir() / "data" / "homography"
    reference = args.reference or f"lburst:{shared_dir() / 'anchors' / 'RoBLo_N16_B5.pt'},frame_order=published"
    try:
        rows = [
            (run.name, step, f"{args.wrap}lburst:{path}")
            for run in args.runs
            for step, path in run_checkpoints(run)
            if not args.steps or step in args.steps
        ]
        for spec in args.also:
            path = weights_file(spec)
            rows.append((spec, checkpoint_step(path) if path else None, spec))
        methods = list(dict.fromkeys([reference] + [spec for _, _, spec in rows]))
        results = run_homography_benchmark(data, methods, args.sigma, args.out)
    except (FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    levels = [f"sigma{s:g}" for s in args.sigma]

    def summary(spec: str, level: str) -> dict:
        return results["methods"][spec][level]["summary"]["all"]

    table = []
    for label, step, spec in [("reference", None, reference)] + rows:
        row = {"label": label, "step": step, "method": spec}
        for level in levels:
            mma = summary(spec, level)["mma"]
            row[level] = {"mma1": mma[0], "mma3": mma[2], "gap3": mma[2] - summary(reference, level)["mma"][2]}
        table.append(row)
    head = " | ".join(f"MMA@3 {lv} | MMA@1 {lv} | vs ref {lv}" for lv in levels)
    print(f"\nreference: {reference}\n\n| model | step | {head} |")
    print("|---|---|" + "---|" * (3 * len(levels)))
    for row in table:
        cells = " | ".join(f"{row[lv]['mma3']:.3f} | {row[lv]['mma1']:.3f} | {row[lv]['gap3']:+.3f}" for lv in levels)
        print(f"| {row['label']} | {'-' if row['step'] is None else row['step']} | {cells} |")
    with atomic_path(args.out / "gap_vs_steps.json") as tmp:
        tmp.write_text(
            json.dumps({"data": str(data), "sigmas": args.sigma, "reference": reference, "rows": table}, indent=1)
        )
    print(f"\nresults: {args.out / 'gap_vs_steps.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
