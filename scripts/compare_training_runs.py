"""Loss curves of training runs side by side: window means per loss component, and a plot.

Made to check whether a change to training (e.g. ``--precision bf16``) leaves the loss
curve unchanged: run both from the same seed and preset (same data stream), then

    python scripts/compare_training_runs.py training/lburst-b1-cpu outputs/train_b1_bf16_check \\
        --labels fp32 bf16 --window 100 --out outputs/compare_b1_bf16.json --plot docs/bf16_training_curves.png

It prints, for each window of steps, each run's mean of every loss component, over the
steps that all runs have.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from lburst.train.curves import COMPONENTS, plot_curves, read_log


def window_means(logs: dict[str, dict[str, np.ndarray]], window: int) -> list[dict]:
    """Rows ``{"steps": "a-b", label: {component: mean}}`` over the steps common to all logs."""
    common = min(len(log["step"]) for log in logs.values())
    rows = []
    for start in range(0, common, window):
        stop = min(common, start + window)
        row = {"steps": f"{start + 1}-{stop}"}
        for label, log in logs.items():
            row[label] = {c: float(np.mean(log[c][start:stop])) for c in COMPONENTS}
        rows.append(row)
    return rows


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", type=Path, help="run folders (with log.csv)")
    p.add_argument("--labels", nargs="+", help="one label per run (default: folder names)")
    p.add_argument("--window", type=int, default=100, help="steps per row")
    p.add_argument("--out", type=Path, help="JSON results")
    p.add_argument("--plot", type=Path, help="PNG of the curves")
    args = p.parse_args()
    labels = args.labels or [r.name for r in args.runs]
    if len(labels) != len(args.runs):
        p.error("give one label per run")
    for run in args.runs:
        if not (run / "log.csv").is_file():
            p.error(f"{run}: no log.csv")
    logs = {label: read_log(run / "log.csv") for label, run in zip(labels, args.runs)}
    rows = window_means(logs, args.window)
    print("| steps | " + " | ".join(f"{c} ({label})" for c in COMPONENTS for label in labels) + " |")
    print("|---" * (1 + len(COMPONENTS) * len(labels)) + "|")
    for row in rows:
        cells = [f"{row[label][c]:.3f}" for c in COMPONENTS for label in labels]
        print(f"| {row['steps']} | " + " | ".join(cells) + " |")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(
            json.dumps({"runs": dict(zip(labels, map(str, args.runs))), "window": args.window, "rows": rows}, indent=1)
        )
    if args.plot:
        plot_curves(
            {label: run / "log.csv" for label, run in zip(labels, args.runs)},
            args.plot,
            smooth=max(1, args.window // 2),
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
