"""``lburst bench reconstruction``: every method on every scene, the paper's table.

For each (method, scene) :func:`lburst.sfm.reconstruct_scene` runs in
``OUT/<method>/<scene>/`` unless that folder already holds a finished ``result.json``
of the same run (so an interrupted benchmark resumes; ``--force`` reruns).  The same run
means the same method (the folder is named after its spec and weights' SHA-1) and the
key in ``bench_key.json`` (:func:`run_key`): the scene's content and the options.  A
scene whose bursts changed under the same names is run again; the features of unchanged
bursts come from the features store (:mod:`lburst.store`).  A ``result.json`` without
``bench_key.json`` (written before the key was kept) is taken as finished.  With several
``seeds`` each (method, scene) runs once per seed of COLMAP's RANSAC and mapper (seed 0 in
``OUT/<method>/<scene>/``, seed S in ``OUT/<method>/<scene>-seedS/``, the later seeds reading
the first one's features and matches), since single runs on a small scene can swing as much as the gaps
between methods; :func:`lburst.sfm.metrics.seed_summary`
gives each (method, scene)'s median and range.  A photo scene whose clean-SIFT reference
was remade under other seeds (``lburst simulate scene --reference-seeds``) adds that spread
to the report (``reference_spread``): ATE differences below it do not rank methods.  A finished
run is evaluated again against the scene's ``reference.json`` if that appeared or changed
since (its SHA-1 is kept in the metrics as ``reference_sha1``), so a remade reference needs
no rerun of the methods; so is one that lacks a metric added since (the pose AUC, the ATE's
rotation part, the fitted camera: :data:`ADDED_KEYS`), from its saved poses and cameras.  The table
(:mod:`lburst.sfm.metrics`: one row per method and scene, and each method's mean over
scenes) is printed as markdown and written to ``OUT/table.md`` and ``OUT/results.json``.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from lburst.burst.io import atomic_path, file_sha1
from lburst.errors import LBurstValueError
from lburst.methods import Method
from lburst.scenes.photo_scene import REFERENCE_DIR
from lburst.scenes.reference_spread import load_spread
from lburst.sfm.inputs import open_input
from lburst.sfm.metrics import POSE_AUC_KEYS, aggregate, camera_metrics, evaluate_against_reference, seed_summary
from lburst.sfm.options import RECORDING_OVERLAP, SCENE_OVERLAP, ReconstructOptions
from lburst.sfm.reconstruct import reconstruct_scene
from lburst.sfm.result import RESULT_FILE, ReconstructionError, ReconstructionResult
from lburst.sfm.scene import REFERENCE_FILE
from lburst.store import files_sha1

KEY_FILE = "bench_key.json"
#: options that do not change a run's result, left out of its key: ``matches`` gives the matches
#: that the run would compute (:func:`lburst.sfm.match.match_or_reuse`)
UNKEYED = ("progress", "matches")

REFERENCE_KEYS = ("reference_source", "reference_sha1", "precision", "precision_matches", "num_poses", *POSE_AUC_KEYS)
#: metrics added after some results were saved (the first with a reference, the second without):
#: computed for those from their poses and cameras
ADDED_KEYS = ("pose_auc_5", "points3D")


def evaluate(result, reference: Path | None) -> None:
    """Replace ``result``'s reference metrics by those against ``reference`` (a ``reference.json``;
    ``None``: none), add the metrics it lacks (:data:`ADDED_KEYS`), and save it."""
    result.metrics = {
        k: v for k, v in result.metrics.items() if k not in REFERENCE_KEYS and not k.startswith(("ate_", "rpe_"))
    }
    if "points3D" not in result.metrics:
        result.metrics["points3D"] = result.metrics.get("points3D_per_image", 0.0) * len(result.registered)
    result.metrics.update(camera_metrics(result.cameras))
    if reference is not None:
        result.metrics.update(evaluate_against_reference(result, reference))
    result.save()


def outdated(result, reference: Path) -> bool:
    """Whether a finished ``result`` is to be evaluated again: its scene's reference was added or
    remade since, or it lacks a metric added since (:data:`ADDED_KEYS`)."""
    if result.failed:
        return False
    has_reference = reference.is_file()
    if has_reference and result.metrics.get("reference_sha1") != file_sha1(reference):
        return True
    return any(k not in result.metrics for k in (ADDED_KEYS if has_reference else ADDED_KEYS[1:]))


def scene_sha1(scene: Path) -> str:
    """SHA-1 of a scene's content: a recording file's bytes, or every non-hidden file under a
    scene folder (paths and bytes) except its ``reference.json``, which is evaluated, not run."""
    if scene.is_file():
        return files_sha1([scene])
    files = sorted(
        p
        for p in scene.rglob("*")
        if p.is_file()
        and p.relative_to(scene) != Path(REFERENCE_FILE)
        and not any(part.startswith(".") for part in p.relative_to(scene).parts)
    )
    return files_sha1(files, root=scene)


def run_key(scene: Path, options: dict[str, Any]) -> dict[str, Any]:
    """What a finished run depends on besides the method: the scene's content and the options.
    An automatic ``overlap`` (``None``) is keyed by the value it takes, 10 for a scene and 2 for
    a recording (as :func:`lburst.sfm.pairs.pair_plan` sets it), so a scene's finished runs
    from when ``--overlap`` defaulted to 10 are still the same run."""
    if "overlap" in options and options["overlap"] is None:
        time_ordered = open_input(scene, options.get("recording")).time_ordered
        options = {**options, "overlap": RECORDING_OVERLAP if time_ordered else SCENE_OVERLAP}
    return {"scene": scene_sha1(scene), "options": {k: str(v) for k, v in sorted(options.items()) if k not in UNKEYED}}


def _stored_key(out: Path) -> dict[str, Any] | None:
    try:
        return json.loads((out / KEY_FILE).read_text())
    except (OSError, ValueError):
        return None


def run_spec(scene: Path, method: Method, options: dict[str, Any]) -> Method:
    """The method a run of ``method`` on ``scene`` records in ``result.json``: with the keypoints
    that :func:`lburst.sfm.reconstruct.reconstruct_scene` gives a learned method whose spec sets
    none (8,000 for a scene, 4,000 for a recording)."""
    if not scene.exists():
        return method
    return method.with_default("top_k", open_input(scene, options.get("recording")).keypoints)


def run_one(scene: Path, method: Method, out: Path, force: bool, options: dict[str, Any]) -> dict[str, Any]:
    """The table row of one method on one scene (from ``result.json`` when already done)."""
    spec = str(method)
    row: dict[str, Any] = {"method": spec, "scene": scene.name, "out": str(out)}
    done = out / RESULT_FILE
    key = run_key(scene, options) if scene.exists() else None
    if done.is_file() and not force:
        previous = ReconstructionResult.load(done)
        stored = _stored_key(out) if (out / KEY_FILE).exists() else key
        if (
            previous.method in (spec, str(run_spec(scene, method, options)))
            and previous.metrics.get("matcher", "mnn") == options.get("matcher", "mnn")
            and stored == key
        ):
            reference = scene / REFERENCE_FILE
            if outdated(previous, reference):
                evaluate(previous, reference if reference.is_file() else None)
            return {**row, **previous.metrics, "registered": len(previous.registered), "error": colmap_error(previous)}
    try:
        # vision alone: a photo set's EXIF GPS (lund's) would otherwise be held as priors
        result = reconstruct_scene(scene, method, out, ReconstructOptions(**{"input_positions": False, **options}))
        with atomic_path(out / KEY_FILE) as tmp:
            tmp.write_text(json.dumps(key, indent=1))
    except ReconstructionError as err:
        print(f"{spec} on {scene}: {err}", file=sys.stderr)
        return {**row, "converged": 0.0, "error": str(err)}
    if result.failed:
        print(f"{spec} on {scene}: {result.error}", file=sys.stderr)
    return {**row, **result.metrics, "registered": len(result.registered), "error": colmap_error(result)}


def colmap_error(result: ReconstructionResult) -> str | None:
    """The table's ``error``: why COLMAP failed (a recording that stopped early but made a model is no error there)."""
    return result.error if result.failed else None


def run_name(scene: Path, seed: int) -> str:
    """The run's folder under ``OUT/<method>/``: the scene's name, with ``-seedS`` for a seed other than 0."""
    return scene.name if seed == 0 else f"{scene.name}-seed{seed}"


def _shared_features(scene: Path, first: Path, options: dict[str, Any]) -> dict[str, Any]:
    """A scene folder's runs with the other seeds take the features from the first seed's run
    ``first`` (its ``features/``, :attr:`ReconstructOptions.features`), which the features store
    serves when their key matches, and its matches of those features
    (:attr:`ReconstructOptions.matches`), so only COLMAP runs again."""
    if options.get("features") is not None or not scene.is_dir():
        return {}
    if open_input(scene, options.get("recording")).folder:  # a recording's keyframes: computed again
        return {}
    return {"features": str(first / "features"), "matches": str(first)}


def _features_from(scene: Path, folder: Path, options: dict[str, Any]) -> dict[str, Any]:
    """The options of a scene folder's runs that read the features of another benchmark's run in
    ``folder`` (``OTHER/<method>/<scene>``): its ``features/``, served by the store when their key
    matches (same method and bursts), else computed, and its matches of the same features."""
    if options.get("features") is not None or not scene.is_dir() or open_input(scene, options.get("recording")).folder:
        return {}
    return {"features": str(folder / "features"), "matches": str(folder)}


def reference_spreads(scenes: Sequence[str | Path]) -> dict[str, dict[str, Any]]:
    """Scene name -> the spread of its clean-SIFT reference under other seeds, for the scenes
    whose current reference has one (:mod:`lburst.scenes.reference_spread`)."""
    found = {}
    for scene in map(Path, scenes):
        record = load_spread(scene, REFERENCE_DIR) if scene.is_dir() else None
        if record is not None:
            found[scene.name] = record
    return found


def run_benchmark(
    scenes: list[str | Path],
    methods: Sequence[str | Method],
    out_dir: str | Path,
    force: bool = False,
    seeds: Sequence[int] = (0,),
    features_from: str | Path | None = None,
    **options: Any,
) -> dict[str, Any]:
    """Run every method on every scene (once per seed); return ``{"rows": [...], "means": [...],
    "seeds": [...]}`` (also written to ``OUT/results.json``); ``means`` average every run of a method.
    ``features_from``: another benchmark's output folder whose runs' features every run reads
    (those of the same method and bursts; e.g. a second camera protocol on the same scenes)."""
    out_dir = Path(out_dir)
    seeds = list(dict.fromkeys(seeds))
    if not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
        raise LBurstValueError(f"seeds: non-negative integers, got {seeds}")
    if "seed" in options:
        raise LBurstValueError("pass COLMAP's seeds as seeds=[...], not seed=")
    methods = [Method.of(method) for method in methods]
    rows = []
    for method in methods:
        folder = out_dir / method.slug()  # hashes the weights once per method
        for scene in map(Path, scenes):
            shared = _shared_features(scene, folder / run_name(scene, seeds[0]), options) if len(seeds) > 1 else {}
            first = {}
            if features_from is not None:  # every seed's run reads the other benchmark's seed-0 features
                other = Path(features_from) / folder.name / run_name(scene, 0)
                first = shared = _features_from(scene, other, options)
            for seed in seeds:  # seed 0 is ReconstructOptions' default: its runs keep their folder and key
                extra = {} if seed == 0 else {"seed": seed}
                extra.update(shared if seed != seeds[0] else first)
                out = folder / run_name(scene, seed)
                rows.append({**run_one(scene, method, out, force, {**options, **extra}), "seed": seed})
    specs = [str(method) for method in methods]
    means = [
        {"method": spec, "scene": f"mean ({len(scenes)})", **aggregate([r for r in rows if r["method"] == spec])}
        for spec in specs
    ]
    report = {
        "scenes": [str(s) for s in scenes],
        "methods": specs,
        "options": options if features_from is None else {**options, "features_from": str(features_from)},
        "seeds": seeds,
        "rows": rows,
        "means": means,
        "by_seed": seed_summary(rows) if len(seeds) > 1 else [],
        "reference_spread": reference_spreads(scenes),
    }
    with atomic_path(out_dir / "results.json") as tmp:
        tmp.write_text(json.dumps(report, indent=1))
    return report
