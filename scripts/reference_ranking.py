"""Whether two methods' ATE ranking on a photo scene survives another draw of its reference.

A photo scene's reference is one COLMAP run on the clean photos; ``lburst simulate scene
--reference-seeds`` adds the same run under other seeds (``SCENE/.reference/seed<S>/``).
This script measures each benchmark run (a ``result.json`` folder) against the reference
and against each of those reruns, with the benchmark's ATE (similarity alignment, RMSE),
and prints one row per run and one column per reference.  It also lists, per photo, how far
the reruns place it from the reference (median over the reruns), so a photo the reference
puts apart from every rerun shows.

    python scripts/reference_ranking.py outputs/scenes/lund_g50 \\
        outputs/recon_fixed8k_lund_g50/*/lund_g50* --out outputs/reference_ranking_lund_g50.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from lburst.scenes.photo_scene import REFERENCE_DIR
from lburst.scenes.reference_spread import rerun_folders
from lburst.sfm.poses import centre_errors, trajectory_errors
from lburst.sfm.reference import Reference
from lburst.sfm.result import RESULT_FILE, ReconstructionResult
from lburst.sfm.scene import REFERENCE_FILE


def ate(poses: dict, reference: dict) -> float | None:
    """ATE RMSE of ``poses`` against ``reference`` (name -> (R, t)) over their common photos."""
    common = [n for n in reference if n in poses]
    if len(common) < 3:
        return None
    return trajectory_errors([poses[n] for n in common], [reference[n] for n in common])["ate_rmse"]


def photo_offsets(poses: dict, reference: dict) -> dict[str, float]:
    """Per photo, its centre's distance from the reference's after the similarity alignment."""
    common = [n for n in reference if n in poses]
    errors = centre_errors([poses[n] for n in common], [reference[n] for n in common])
    return {n: float(d) for n, d in zip(common, np.linalg.norm(errors, axis=1))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene", type=Path, help="scene folder with reference.json and .reference/seed*/")
    parser.add_argument("runs", nargs="+", type=Path, help="benchmark run folders (each with result.json)")
    parser.add_argument("--out", type=Path, help="write the table as JSON here")
    args = parser.parse_args()
    references = {"reference": Reference.load(args.scene / REFERENCE_FILE).poses}
    for folder in rerun_folders(args.scene / REFERENCE_DIR).values():
        if (folder / RESULT_FILE).is_file():
            references[folder.name] = ReconstructionResult.load(folder / RESULT_FILE).poses
    rows = {}
    for run in args.runs:
        result = ReconstructionResult.load(run / RESULT_FILE)
        rows[f"{run.parent.name}/{run.name}"] = {k: ate(result.poses, ref) for k, ref in references.items()}
    reruns = [k for k in references if k != "reference"]
    print("| run | " + " | ".join(references) + " |")
    print("|---|" + "---|" * len(references))
    for name, row in [(k, {r: ate(references[k], references[r]) for r in references}) for k in reruns] + list(
        rows.items()
    ):
        print(f"| {name} | " + " | ".join("-" if v is None else f"{v:.4f}" for v in row.values()) + " |")
    offsets = {k: photo_offsets(references[k], references["reference"]) for k in reruns}
    names = list(references["reference"])
    median = {n: float(np.median([offsets[k][n] for k in reruns if n in offsets[k]])) for n in names}
    worst = sorted(median, key=median.get, reverse=True)[:5]
    print(
        "\nphotos the reruns place furthest from the reference (median over the reruns): "
        + ", ".join(f"{n} {median[n]:.3f}" for n in worst)
    )
    if args.out:
        args.out.write_text(json.dumps({"ate": rows, "photo_offsets": median}, indent=1))


if __name__ == "__main__":
    main()
