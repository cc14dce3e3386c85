"""The 3D table's pose columns: the ATE's rotation part, the relative pose AUC over every pair of
reference images (an unregistered image fails its pairs), the fitted radial distortion, and the
benchmark adding them to runs saved before they existed."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lburst.bench.reconstruction import run_benchmark
from lburst.methods import method_slug
from lburst.sfm.metrics import camera_metrics, evaluate_against_reference, seed_summary
from lburst.sfm.poses import pose_auc, relative_pose_errors, trajectory_errors
from lburst.sfm.reference import Reference
from lburst.sfm.result import ReconstructionResult

NAMES = ["a", "b", "c", "d"]


def ring_poses():
    """Four cameras on a circle looking at its centre (world-to-camera)."""
    poses = {}
    for i, name in enumerate(NAMES):
        R = Rotation.from_euler("y", 90 * i, degrees=True).as_matrix()
        poses[name] = (R, np.array([0.0, 0.0, 5.0]))  # centre -R^T t: on a circle of radius 5
    return poses


def turned(pose, degrees, axis="x"):
    """The camera turned about its own centre."""
    R, t = pose
    centre = -R.T @ t
    turned_R = Rotation.from_euler(axis, degrees, degrees=True).as_matrix() @ R
    return turned_R, -turned_R @ centre


def similar(poses, scale=2.0):
    """The same cameras in another frame: rotated, scaled and moved (what a reconstruction gives)."""
    G = Rotation.from_euler("zyx", [30, -20, 10], degrees=True).as_matrix()
    shift = np.array([1.0, -2.0, 3.0])
    out = {}
    for name, (R, t) in poses.items():
        C = -R.T @ t
        C2, R2 = scale * G @ C + shift, R @ G.T
        out[name] = (R2, -R2 @ C2)
    return out


def test_rotation_error_is_the_orientation_error_after_the_alignment():
    ref = ring_poses()
    est = similar(ref)
    exact = trajectory_errors([est[n] for n in NAMES], [ref[n] for n in NAMES])
    assert exact["ate_rmse"] < 1e-9 and exact["ate_rot_rmse_deg"] < 1e-6
    est["c"] = turned(est["c"], 3.0)  # one camera turned 3 degrees about its centre: centres unchanged
    errors = trajectory_errors([est[n] for n in NAMES], [ref[n] for n in NAMES])
    assert errors["ate_rmse"] < 1e-9  # the ATE cannot see it
    assert errors["ate_rot_max_deg"] == pytest.approx(3.0)
    assert errors["ate_rot_rmse_deg"] == pytest.approx(np.sqrt(9.0 / 4))


def test_relative_pose_errors_fail_the_pairs_of_an_unregistered_image():
    ref = ring_poses()
    est = similar(ref)
    assert np.all(relative_pose_errors(est, ref) < 1e-6)  # pose errors need no alignment
    est["b"] = turned(est["b"], 4.0)
    del est["d"]
    errors = relative_pose_errors(est, ref)  # pairs ab ac ad bc bd cd
    assert errors[[2, 4, 5]].tolist() == [np.inf] * 3
    assert errors[0] == pytest.approx(4.0, abs=1e-6) and errors[3] == pytest.approx(4.0, abs=1e-6)
    assert errors[1] < 1e-6


def test_pose_auc_by_hand():
    # errors 0, 2, inf, inf: the curve rises to 1/4 at 0 and to 1/2 at 2 degrees, then stays
    auc = pose_auc([0.0, 2.0, np.inf, np.inf])
    assert auc["5"] == pytest.approx((0.5 * (0.25 + 0.5) * 2 + 0.5 * 3) / 5)
    assert auc["20"] == pytest.approx((0.5 * (0.25 + 0.5) * 2 + 0.5 * 18) / 20)
    assert pose_auc([np.inf, np.inf]) == {"5": 0.0, "10": 0.0, "20": 0.0}
    assert pose_auc([0.0] * 3)["10"] == pytest.approx(1.0)


class Run:
    """What the metrics read of a reconstruction."""

    def __init__(self, poses):
        self.names, self.poses = NAMES, poses

    def match_data(self):
        return None


def test_evaluation_against_a_reference_gives_the_pose_auc_of_every_pair():
    ref = ring_poses()
    camera = {"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 50.0, 32.0, 24.0]}
    reference = Reference("strecha", camera, ref, calibrated=True)
    est = similar(ref)
    del est["d"]  # 3 of the 6 pairs lost
    out = evaluate_against_reference(Run(est), reference)
    assert out["pose_auc_5"] == pytest.approx(0.5) and out["pose_auc_20"] == pytest.approx(0.5)
    assert out["ate_rot_rmse_deg"] < 1e-6


def test_fitted_camera_metrics():
    cams = {
        "a": {"model": "SIMPLE_RADIAL", "width": 64, "height": 48, "params": [50.0, 32.0, 24.0, 0.01]},
        "b": {"model": "SIMPLE_RADIAL", "width": 64, "height": 48, "params": [52.0, 32.0, 24.0, 0.03]},
        "c": {"model": "OPENCV", "width": 64, "height": 48, "params": [60.0, 62.0, 32.0, 24.0, 0.02, 0.5, 0, 0]},
    }
    assert camera_metrics(cams) == {"fitted_focal": 52.0, "fitted_k": 0.02}
    pinhole = {"a": {"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 52.0, 32.0, 24.0]}}
    assert camera_metrics(pinhole) == {"fitted_focal": 51.0}  # no distortion term: no k
    assert camera_metrics({}) == {}


def test_seed_summary_counts_a_failed_run_as_auc_0_and_no_fitted_k():
    runs = [
        {"method": "m", "scene": "s", "converged": 1.0, "pose_auc_5": 0.6, "fitted_k": 0.02, "ate_rot_rmse_deg": 0.1},
        {"method": "m", "scene": "s", "converged": 1.0, "pose_auc_5": 0.4, "fitted_k": 0.04, "ate_rot_rmse_deg": 0.3},
        {"method": "m", "scene": "s", "converged": 0.0},
        {"method": "m", "scene": "no reference", "converged": 1.0, "fitted_k": 0.01},
    ]
    s, t = seed_summary(runs)
    assert (s["pose_auc_5"], s["pose_auc_5_min"], s["pose_auc_5_max"]) == (0.4, 0.0, 0.6)
    assert (s["fitted_k"], s["fitted_k_min"]) == (pytest.approx(0.03), 0.02)
    assert s["ate_rot_rmse_deg"] == pytest.approx(0.2)
    assert "pose_auc_5" not in t and t["fitted_k"] == 0.01


def test_the_benchmark_adds_the_new_columns_to_a_run_saved_without_them(tmp_path):
    scene = tmp_path / "scene"
    scene.mkdir()
    ref = ring_poses()
    camera = {"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 50.0, 32.0, 24.0]}
    Reference("strecha", camera, ref, calibrated=True).save(scene / "reference.json")
    out = tmp_path / "bench" / method_slug("sift") / scene.name
    fitted = {"model": "SIMPLE_RADIAL", "width": 64, "height": 48, "params": [51.0, 32.0, 24.0, 0.02]}
    ReconstructionResult(
        str(scene),
        "sift",
        str(out),
        NAMES,
        NAMES,
        poses=similar(ref),
        cameras={n: fitted for n in NAMES},
        metrics={"converged": 1.0, "registered_pct": 100.0, "points3D_per_image": 10.0},
    ).save()
    run_benchmark([scene], ["sift"], tmp_path / "bench", progress=False)  # evaluated against the reference
    saved = ReconstructionResult.load(out / "result.json")
    for key in ("pose_auc_5", "pose_auc_10", "points3D", "fitted_k"):  # as saved before they existed
        del saved.metrics[key]
    saved.save()
    row = run_benchmark([scene], ["sift"], tmp_path / "bench", progress=False)["rows"][0]
    assert row["pose_auc_5"] == pytest.approx(1.0) and row["fitted_k"] == 0.02 and row["points3D"] == 40.0
    assert ReconstructionResult.load(out / "result.json").metrics["pose_auc_10"] == pytest.approx(1.0)
