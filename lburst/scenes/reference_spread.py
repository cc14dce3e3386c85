"""How far a photo scene's clean-SIFT reference can be trusted: the same run under other seeds.

A photo set has no ground-truth poses, so :mod:`lburst.scenes.photo_scene` takes one COLMAP
reconstruction of the clean photos as the reference.  That run is one draw of COLMAP's
RANSAC and mapper: under another seed the same photos, features and options give another
trajectory.  An ATE difference between two methods smaller than that spread says more about
the reference than about the methods.

:func:`reference_spread` reconstructs the clean photos again under each of ``seeds`` (the
reference's options otherwise, its SIFT features from the reference's features store, so
only matching and mapping run), each in ``SCENE/.reference/seed<S>/``, and writes
``SCENE/.reference/spread.json``::

    {"reference_sha1": SHA-1 of reference.json,
     "images": photos in the reference,
     "runs": [{"seed": S, "registered": n, "ate_rmse": m, "ate_percent": p, "ate_max": m}, ...]}

Each ATE is the run's trajectory against ``reference.json``'s, after a similarity
alignment, as the reconstruction benchmark measures a method (:func:`lburst.sfm.poses.trajectory_errors`;
a run that registers fewer than three reference photos has no ATE).  A run already in
its folder is read back, not made again: the reruns belong to the reference they were made
for, and :func:`drop_spread` removes them when the reference is made again (with other
options).  :func:`load_spread` returns the record only while it belongs to the scene's
current ``reference.json``.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lburst.burst.io import atomic_path, file_sha1
from lburst.errors import LBurstValueError
from lburst.numbers import check_integer
from lburst.sfm.metrics import reference_length
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.poses import trajectory_errors
from lburst.sfm.reconstruct import reconstruct_scene
from lburst.sfm.reference import Reference
from lburst.sfm.result import RESULT_FILE, ReconstructionResult
from lburst.sfm.scene import REFERENCE_FILE

SPREAD_FILE = "spread.json"
RERUN_PREFIX = "seed"  # a rerun's folder: <reference folder>/seed<S>


def rerun_folders(folder: str | Path) -> dict[int, Path]:
    """Seed -> folder of every rerun kept in the reference folder ``folder``, by seed."""
    found = {}
    for path in Path(folder).glob(f"{RERUN_PREFIX}*"):
        tail = path.name[len(RERUN_PREFIX) :]
        if path.is_dir() and tail.isdigit():
            found[int(tail)] = path
    return dict(sorted(found.items()))


def reference_spread(
    photos: str | Path,
    scene_dir: str | Path,
    seeds: Sequence[int],
    method: str,
    reference_dir: str,
    options: dict[str, Any],
    progress: bool = True,
) -> dict[str, Any]:
    """Reconstruct the clean ``photos`` under each of ``seeds`` and write ``spread.json`` (module docstring).

    ``method``, ``reference_dir`` and ``options`` are those the reference was made with
    (:mod:`lburst.scenes.photo_scene`); ``options`` must not hold ``seed``.
    """
    seeds = list(dict.fromkeys(check_integer(s, "a reference seed", low=0) for s in seeds))
    if not seeds:
        raise LBurstValueError("reference seeds: give at least one")
    scene_dir = Path(scene_dir)
    folder = scene_dir / reference_dir
    reference_file = scene_dir / REFERENCE_FILE
    reference = Reference.load(reference_file)
    names = list(reference.poses)
    length = reference_length(reference, names)
    runs = []
    for seed in seeds:
        out = folder / f"{RERUN_PREFIX}{seed}"
        if (out / RESULT_FILE).is_file():
            result = ReconstructionResult.load(out / RESULT_FILE)
        else:
            opts = ReconstructOptions(progress=progress, **options, seed=seed, features=str(folder / "features"))
            result = reconstruct_scene(photos, method, out, opts)
        common = [n for n in names if n in result.poses]
        run: dict[str, Any] = {"seed": seed, "registered": len(common)}
        if len(common) >= 3:
            errors = trajectory_errors(
                [result.poses[n] for n in common],
                [reference.poses[n] for n in common],
                length=length,
            )
            run.update({k: errors[k] for k in ("ate_rmse", "ate_percent", "ate_max") if k in errors})
        runs.append(run)
    record = {"reference_sha1": file_sha1(reference_file), "images": len(names), "runs": runs}
    with atomic_path(folder / SPREAD_FILE) as tmp:
        tmp.write_text(json.dumps(record, indent=1))
    return record


def drop_spread(scene_dir: str | Path, reference_dir: str) -> None:
    """Remove the reruns and ``spread.json`` of a reference that is about to be made again."""
    folder = Path(scene_dir) / reference_dir
    for run in rerun_folders(folder).values():
        shutil.rmtree(run)
    (folder / SPREAD_FILE).unlink(missing_ok=True)


def load_spread(scene_dir: str | Path, reference_dir: str) -> dict[str, Any] | None:
    """The scene's ``spread.json``, or ``None`` when absent or made for another ``reference.json``."""
    scene_dir = Path(scene_dir)
    path, reference_file = scene_dir / reference_dir / SPREAD_FILE, scene_dir / REFERENCE_FILE
    if not (path.is_file() and reference_file.is_file()):
        return None
    try:
        record = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise LBurstValueError(f"{path}: not valid JSON ({err})") from err
    return record if record.get("reference_sha1") == file_sha1(reference_file) else None


def summary(record: dict[str, Any]) -> str:
    """One line: the median and range of the runs' ATE against the reference, and failed runs."""
    ates = [r["ate_rmse"] for r in record["runs"] if "ate_rmse" in r]
    seeds = ", ".join(str(r["seed"]) for r in record["runs"])
    short = [r for r in record["runs"] if r["registered"] < record["images"]]
    line = f"the clean photos under COLMAP seeds {seeds} lie "
    if ates:
        line += f"{np.median(ates):.3g} ({min(ates):.3g}-{max(ates):.3g}) ATE from the reference"
    else:
        line += "nowhere comparable to the reference (fewer than 3 photos registered)"
    if short:
        line += "; " + ", ".join(f"seed {r['seed']} registers {r['registered']}/{record['images']}" for r in short)
    return line
