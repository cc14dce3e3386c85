"""The table's definitions on hand-made counts, averaging over scenes, and the benchmark's resume."""

import json

import numpy as np
import pytest

from lburst.bench.reconstruction import run_benchmark
from lburst.methods import Method, method_slug
from lburst.sfm.metrics import aggregate, markdown_table, scene_metrics
from lburst.sfm.result import ReconstructionResult


def test_scene_metrics_by_hand():
    summary = {"converged": True, "registered": {"a": {}, "b": {}, "c": {}}, "num_points3D": 300}
    m = scene_metrics(4, [100, 200, 300, 400], [50, 30, 20], [25, 15, 0], summary)
    assert m["converged"] == 1.0
    assert m["registered_pct"] == 75.0
    assert m["keypoints_per_image"] == 250.0
    assert m["putative_per_image"] == 25.0  # 100 matches / 4 images
    assert m["inliers_per_image"] == 10.0
    assert m["match_ratio"] == 0.4  # 40 / 100
    assert m["match_score"] == 0.04  # 40 / 1000
    assert m["points3D_per_image"] == 100.0  # 300 points / 3 registered images


def test_scene_metrics_without_a_model():
    m = scene_metrics(2, [10, 10], [0], [], {"converged": False, "registered": {}, "num_points3D": 0})
    assert m["converged"] == 0.0 and m["registered_pct"] == 0.0 and m["match_ratio"] == 0.0


def test_aggregate_trajectory_errors_over_converged_scenes_only():
    rows = [
        {"converged": 1.0, "registered_pct": 100.0, "ate_rmse": 2.0},
        {"converged": 0.0, "registered_pct": 0.0, "ate_rmse": 10.0},
    ]
    mean = aggregate(rows)
    assert mean["converged"] == 0.5 and mean["registered_pct"] == 50.0
    assert mean["ate_rmse"] == 2.0 and mean["trajectory_scenes"] == 1
    assert mean["precision"] is None
    table = markdown_table([{"method": "sift", "scene": "mean", **mean}])
    assert table.splitlines()[2].startswith("| sift | mean | 0.50 | 50.0 |") and "| - |" in table


def test_benchmark_skips_finished_runs(tmp_path):
    scene = tmp_path / "missing_scene"  # would fail if it were run again
    out = tmp_path / "bench" / method_slug("sift") / scene.name
    done = ReconstructionResult(
        str(scene), "sift", str(out), ["a", "b"], ["a", "b"], metrics={"converged": 1.0, "registered_pct": 100.0}
    )
    done.save()
    report = run_benchmark([scene], ["sift", "orb"], tmp_path / "bench", progress=False)
    sift, orb = report["rows"]
    assert sift["registered_pct"] == 100.0 and sift["error"] is None
    assert orb["converged"] == 0.0 and "not a folder" in orb["error"]
    assert json.loads((tmp_path / "bench" / "results.json").read_text())["means"][0]["registered_pct"] == 100.0


def test_method_slug_is_a_safe_unique_name():
    a, b = method_slug("r2d2:../shared/anchors/R2D2.pt"), method_slug("r2d2:/other/R2D2.pt")
    assert "/" not in a and a != b
    assert method_slug("sift") != method_slug("sift,root=true")


def test_benchmark_evaluates_again_when_the_reference_is_remade(tmp_path):
    import numpy as np

    from lburst.sfm.reference import Reference

    scene = tmp_path / "scene"
    scene.mkdir()
    names = ["a", "b", "c", "d"]
    poses = {n: (np.eye(3), np.array([-float(i), 0.0, 0.0])) for i, n in enumerate(names)}  # centres on a line
    camera = {"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 50.0, 32.0, 24.0]}
    Reference("sift-clean", camera, poses, 3.0).save(scene / "reference.json")
    out = tmp_path / "bench" / method_slug("sift") / scene.name
    ReconstructionResult(
        str(scene), "sift", str(out), names, names, poses=poses, metrics={"converged": 1.0, "registered_pct": 100.0}
    ).save()
    first = run_benchmark([scene], ["sift"], tmp_path / "bench", progress=False)["rows"][0]
    assert first["ate_rmse"] < 1e-9 and first["reference_sha1"]
    # the reference is remade (another path): the finished run is evaluated again, not left with the old numbers
    bent = {**poses, "d": (np.eye(3), np.array([-3.0, -1.0, 0.0]))}
    Reference("sift-clean", camera, bent, 3.4).save(scene / "reference.json")
    second = run_benchmark([scene], ["sift"], tmp_path / "bench", progress=False)["rows"][0]
    assert second["ate_rmse"] > 0.1 and second["reference_sha1"] != first["reference_sha1"]
    assert ReconstructionResult.load(out / "result.json").metrics["ate_rmse"] == second["ate_rmse"]


def _textured_scene(scene):
    """A scene folder of three 160x120 photos of blurred noise (seeded), enough texture for SIFT."""
    import cv2
    import numpy as np

    scene.mkdir()
    for i in range(3):
        image = np.random.default_rng(i).integers(0, 256, size=(120, 160, 3), dtype=np.uint8)
        cv2.imwrite(str(scene / f"{i}.png"), cv2.GaussianBlur(image, (0, 0), 1.0))
    return scene


def test_benchmark_runs_a_scene_again_when_its_bursts_change(tmp_path):
    import cv2
    import numpy as np

    scene = _textured_scene(tmp_path / "scene")

    def row(out):
        return run_benchmark([scene], ["sift"], tmp_path / out, progress=False, num_threads=1)["rows"][0]

    first = row("bench")
    assert row("bench")["keypoints_per_image"] == first["keypoints_per_image"]  # unchanged: finished
    cv2.imwrite(str(scene / "1.png"), np.zeros((120, 160, 3), np.uint8))  # the burst replaced by a black frame
    again, fresh = row("bench"), row("fresh")
    assert again["keypoints_per_image"] == fresh["keypoints_per_image"] < first["keypoints_per_image"]
    assert again["registered"] == fresh["registered"]
    assert row("bench")["keypoints_per_image"] == again["keypoints_per_image"]


def test_seed_summary_takes_medians_and_ranges_and_counts_failed_runs():
    from lburst.sfm.metrics import seed_summary, seed_table

    runs = [
        {
            "method": "m",
            "scene": "s",
            "converged": 1.0,
            "registered_pct": 100.0,
            "points3D_per_image": 90.0,
            "ate_rmse": 0.2,
        },
        {
            "method": "m",
            "scene": "s",
            "converged": 1.0,
            "registered_pct": 90.0,
            "points3D_per_image": 110.0,
            "ate_rmse": 2.0,
        },
        {"method": "m", "scene": "s", "converged": 0.0, "error": "no model", "ate_rmse": 9.0},
        {"method": "m", "scene": "t", "converged": 1.0, "registered_pct": 100.0, "points3D_per_image": 50.0},
    ]
    s, t = seed_summary(runs)
    assert (s["runs"], s["converged"]) == (3, 2)
    assert s["points3D_per_image"] == 90.0 and (s["points3D_per_image_min"], s["points3D_per_image_max"]) == (
        0.0,
        110.0,
    )
    assert s["registered_pct"] == 90.0
    assert s["ate_rmse"] == 1.1 and s["ate_rmse_max"] == 2.0  # the failed run's error is no trajectory
    assert t["runs"] == 1 and "ate_rmse" not in t
    table = seed_table([s, t]).splitlines()
    # no total of points (0), rotation error, pose AUC (no reference) or fitted k in these runs
    assert table[2] == "| m | s | 3 | 2 | 90.0 (0.0-100.0) | 90 (0-110) | 0 (0-0) | 1.1 (0.2-2) |" + " - |" * 5
    assert table[3].endswith("| 50 (50-50) | 0 (0-0) | - |" + " - |" * 5)


def test_benchmark_runs_each_seed_in_its_own_folder(tmp_path):
    import pytest

    scene = _textured_scene(tmp_path / "scene")
    report = run_benchmark([scene], ["sift"], tmp_path / "bench", seeds=[0, 7, 7], progress=False, num_threads=1)
    assert [r["seed"] for r in report["rows"]] == [0, 7] and report["seeds"] == [0, 7]
    folder = tmp_path / "bench" / method_slug("sift")
    assert sorted(p.name for p in folder.iterdir()) == ["scene", "scene-seed7"]
    keys = [json.loads((folder / n / "bench_key.json").read_text())["options"] for n in ("scene", "scene-seed7")]
    assert "seed" not in keys[0] and keys[1]["seed"] == "7"  # seed 0 keeps the key of runs made before seeds
    assert keys[1]["features"] == str(folder / "scene" / "features")  # seed 7 reads seed 0's features
    assert "matches" not in keys[1]  # and its matches, which are those it would compute: not in the key
    assert report["by_seed"][0]["runs"] == 2
    for bad in ([], [-1], [True]):
        with pytest.raises(ValueError, match="seeds"):
            run_benchmark([scene], ["sift"], tmp_path / "bench", seeds=bad)


def test_benchmark_reports_the_reference_spread_of_its_current_reference(tmp_path):
    import numpy as np

    from lburst.burst.io import file_sha1
    from lburst.sfm.reference import Reference

    scene = tmp_path / "scene"
    (scene / ".reference").mkdir(parents=True)
    names = ["a", "b", "c"]
    poses = {n: (np.eye(3), np.array([-float(i), 0.0, 0.0])) for i, n in enumerate(names)}
    camera = {"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 50.0, 32.0, 24.0]}
    Reference("sift-clean", camera, poses, 2.0).save(scene / "reference.json")
    runs = [{"seed": 1, "registered": 3, "ate_rmse": 0.2}, {"seed": 2, "registered": 2}]
    record = {"reference_sha1": file_sha1(scene / "reference.json"), "images": 3, "runs": runs}
    (scene / ".reference" / "spread.json").write_text(json.dumps(record))
    out = tmp_path / "bench" / method_slug("sift") / scene.name
    ReconstructionResult(str(scene), "sift", str(out), names, names, poses=poses, metrics={"converged": 1.0}).save()
    report = run_benchmark([scene], ["sift"], tmp_path / "bench", progress=False)
    assert report["reference_spread"] == {"scene": record}
    from lburst.scenes.reference_spread import summary

    assert summary(record) == (
        "the clean photos under COLMAP seeds 1, 2 lie 0.2 (0.2-0.2) ATE from the reference; seed 2 registers 2/3"
    )
    # another reference.json: the spread was not measured for it
    Reference("sift-clean", camera, poses, 3.0).save(scene / "reference.json")
    assert run_benchmark([scene], ["sift"], tmp_path / "bench", progress=False)["reference_spread"] == {}


def test_a_second_protocol_reads_the_features_of_another_benchmark(tmp_path):
    import numpy as np

    scene = _textured_scene(tmp_path / "scene")
    first = run_benchmark([scene], ["sift"], tmp_path / "refined", progress=False, num_threads=1)
    folder = method_slug("sift")
    features = tmp_path / "refined" / folder / "scene" / "features"
    # mark the stored features: a run that reads them keeps the mark, one that computes its own does not
    with np.load(features / "0.npz") as data:
        stored = dict(data)
    stored["scores"] = np.full_like(stored["scores"], 0.123)
    np.savez(features / "0.npz", **stored)
    report = run_benchmark(
        [scene],
        ["sift"],
        tmp_path / "fixed",
        seeds=[0, 3],
        features_from=tmp_path / "refined",
        progress=False,
        num_threads=1,
        fix_intrinsics=True,
    )
    for run in ("scene", "scene-seed3"):
        key = json.loads((tmp_path / "fixed" / folder / run / "bench_key.json").read_text())["options"]
        assert key["features"] == str(features)
        with np.load(tmp_path / "fixed" / folder / run / "features" / "0.npz") as data:
            assert np.all(data["scores"] == np.float32(0.123))
    assert report["options"]["features_from"] == str(tmp_path / "refined")
    assert first["rows"][0]["keypoints_per_image"] == report["rows"][0]["keypoints_per_image"]


def test_benchmark_skips_a_finished_learned_run_whose_spec_got_the_scenes_keypoints(tmp_path):
    from lburst.bench.reconstruction import KEY_FILE, run_key

    scene = _textured_scene(tmp_path / "scene")
    out = tmp_path / "bench" / Method.parse("lburst").slug() / scene.name
    done = ReconstructionResult(  # what reconstruct_scene saves for "lburst" on a scene: its 8,000 keypoints
        str(scene), "lburst,top_k=8000", str(out), ["0", "1", "2"], ["0", "1"], metrics={"registered_pct": 42.0}
    )
    done.save()
    (out / KEY_FILE).write_text(json.dumps(run_key(scene, {"num_threads": 1})))
    row = run_benchmark([scene], ["lburst"], tmp_path / "bench", progress=False, num_threads=1)["rows"][0]
    assert row["registered_pct"] == 42.0 and row["registered"] == 2  # taken as finished, not run again


def _placed(positions):
    """A reconstruction of four cameras 2 m above their true places, the reference, and ``positions``."""
    from types import SimpleNamespace

    import numpy as np

    from lburst.sfm.reference import Reference

    centres = {f"{i:04d}": np.array([10.0 * i, 3.0 * (i % 2), 0.0]) for i in range(4)}
    truth = {n: (np.eye(3), -c) for n, c in centres.items()}
    model = {n: (np.eye(3), -(c + [0.0, 0.0, 2.0 * (n == "0003")])) for n, c in centres.items()}
    reference = Reference(source="synthetic", camera={}, poses=truth)
    result = SimpleNamespace(names=list(centres), poses=model, positions=positions, match_data=lambda: None)
    return result, reference


def test_a_model_in_the_gnss_frame_is_measured_there_too():
    from lburst.sfm.metrics import evaluate_against_reference

    metrics = evaluate_against_reference(*_placed({"in_frame": True}))
    assert metrics["frame_rmse"] == pytest.approx(np.sqrt((3 * 0.5**2 + 1.5**2) / 4))
    assert metrics["frame_max"] == pytest.approx(1.5)
    for positions in (None, {"in_frame": False}):  # a model in COLMAP's own frame has no such error
        assert "frame_rmse" not in evaluate_against_reference(*_placed(positions))
