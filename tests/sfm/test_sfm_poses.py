"""ATE / RPE and the Sim3 alignment on hand-made trajectories with hand-computed errors."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lburst.sfm.pairs import exhaustive_pairs, make_pairs, sequential_pairs
from lburst.sfm.poses import Sim3, centre_errors, trajectory_errors, umeyama, yaw_shift_errors

SQUARE = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])


def pose_from(R_c2w: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera (R, t) of a camera with orientation R_c2w at ``centre``."""
    return R_c2w.T, -R_c2w.T @ centre


def test_umeyama_recovers_a_similarity():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(10, 3))
    R = Rotation.from_rotvec([0.3, -0.5, 1.1]).as_matrix()
    dst = Sim3(2.5, R, np.array([1.0, -2.0, 3.0])).apply(src)
    sim = umeyama(src, dst)
    assert sim.scale == pytest.approx(2.5)
    np.testing.assert_allclose(sim.rotation, R, atol=1e-10)
    np.testing.assert_allclose(sim.translation, [1.0, -2.0, 3.0], atol=1e-10)


def test_umeyama_rejects_too_few_points():
    with pytest.raises(ValueError, match="at least 3"):
        umeyama(np.zeros((2, 3)), np.zeros((2, 3)))


def test_trajectory_in_another_similar_frame_has_zero_error():
    rng = np.random.default_rng(1)
    ref_R = [Rotation.from_rotvec(rng.normal(size=3)).as_matrix() for _ in range(6)]
    ref_c = np.cumsum(rng.normal(size=(6, 3)), axis=0)
    reference = [pose_from(R, c) for R, c in zip(ref_R, ref_c)]
    # the estimate lives in a world frame x_est = (Ra^T (x_ref - ta)) / s
    s, Ra, ta = 0.3, Rotation.from_rotvec([0.2, 1.0, -0.4]).as_matrix(), np.array([5.0, -1.0, 2.0])
    estimated = [pose_from(Ra.T @ R, Ra.T @ (c - ta) / s) for R, c in zip(ref_R, ref_c)]
    err = trajectory_errors(estimated, reference, length=10.0)
    assert err["ate_rmse"] == pytest.approx(0, abs=1e-9)
    assert err["ate_percent"] == pytest.approx(0, abs=1e-7)
    assert err["rpe_trans_rmse"] == pytest.approx(0, abs=1e-9)
    assert err["rpe_rot_rmse_deg"] == pytest.approx(0, abs=1e-6)
    assert err["scale"] == pytest.approx(s)


def test_known_centre_perturbation():
    d = 0.1
    reference = [pose_from(np.eye(3), c) for c in SQUARE]
    bumps = np.array(
        [[0, 0, d], [0, 0, -d], [0, 0, d], [0, 0, -d]]
    )  # uncorrelated with the square: alignment stays put
    estimated = [pose_from(np.eye(3), c + b) for c, b in zip(SQUARE, bumps)]
    rigid = trajectory_errors(estimated, reference, with_scale=False, length=4.0)
    assert rigid["ate_rmse"] == pytest.approx(d)
    assert rigid["ate_percent"] == pytest.approx(100 * d / 4.0)
    assert rigid["rpe_trans_rmse"] == pytest.approx(2 * d)  # consecutive bumps differ by 2d
    assert rigid["rpe_rot_rmse_deg"] == pytest.approx(0, abs=1e-9)
    # with scale, Umeyama shrinks the estimate by s = 0.5 / (0.5 + d^2): each error is
    # (s - 1)(c - mean) + s * bump, of squared norm (1 - s)^2 / 2 + s^2 d^2
    s = 0.5 / (0.5 + d**2)
    sim = trajectory_errors(estimated, reference)
    assert sim["scale"] == pytest.approx(s)
    assert sim["ate_rmse"] == pytest.approx(np.sqrt((1 - s) ** 2 / 2 + s**2 * d**2))


def test_centre_errors_are_the_bumps_and_give_the_ate():
    d = 0.1
    reference = [pose_from(np.eye(3), c) for c in SQUARE]
    bumps = np.array([[0, 0, d], [0, 0, -d], [0, 0, d], [0, 0, -d]])
    estimated = [pose_from(np.eye(3), c + b) for c, b in zip(SQUARE, bumps)]
    np.testing.assert_allclose(centre_errors(estimated, reference, with_scale=False), bumps, atol=1e-12)
    errors = np.linalg.norm(centre_errors(estimated, reference), axis=1)
    assert np.sqrt(np.mean(errors**2)) == pytest.approx(trajectory_errors(estimated, reference)["ate_rmse"])


def test_known_rotation_perturbation():
    theta = np.radians(10)
    reference = [pose_from(np.eye(3), c) for c in SQUARE]
    turned = Rotation.from_rotvec([0, 0, theta]).as_matrix()
    estimated = [pose_from(turned if i == 1 else np.eye(3), c) for i, c in enumerate(SQUARE)]
    err = trajectory_errors(estimated, reference, with_scale=False)
    assert err["ate_rmse"] == pytest.approx(0, abs=1e-12)  # centres untouched
    # pairs (0,1) and (1,2) are off by theta; (1,2) also moves its 1 m step by 2 sin(theta/2)
    assert err["rpe_rot_rmse_deg"] == pytest.approx(10 * np.sqrt(2 / 3))
    assert err["rpe_trans_rmse"] == pytest.approx(2 * np.sin(theta / 2) / np.sqrt(3))


def test_pairs():
    assert exhaustive_pairs(4) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    assert sequential_pairs(4, 2) == [(0, 1), (0, 2), (1, 2), (1, 3), (2, 3)]
    assert len(make_pairs(30, "sequential", 5)) == 5 * 30 - 15
    with pytest.raises(ValueError):
        make_pairs(3, "nearest")


def test_a_georeferenced_model_is_measured_after_a_yaw_and_a_shift_only():
    rng = np.random.default_rng(7)
    truth = rng.normal(scale=20.0, size=(12, 3))
    yaw = Rotation.from_euler("z", 0.4).as_matrix()
    moved = truth @ yaw.T + np.array([3.0, -8.0, 1.5])
    err = yaw_shift_errors(moved, truth)
    assert err["frame_rmse"] == pytest.approx(0, abs=1e-9)
    assert err["frame_yaw_deg"] == pytest.approx(-np.degrees(0.4))
    # a scale error is not fitted away, nor a tilt: both stay in the error
    scaled = yaw_shift_errors(1.1 * truth, truth)
    spread = truth - truth.mean(0)
    assert scaled["frame_rmse"] == pytest.approx(0.1 * np.sqrt(np.mean(np.sum(spread**2, 1))), rel=1e-9)
    tilt = Rotation.from_euler("x", 0.1).as_matrix()
    assert yaw_shift_errors(truth @ tilt.T, truth)["frame_rmse"] > 0.5


def test_a_known_offset_of_one_camera():
    truth = np.array([[0.0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]])
    moved = truth.copy()
    moved[:, 2] = [0.0, 0.0, 0.0, 4.0]  # one camera 4 m up: the shift takes 1 m, errors 1, 1, 1, 3
    err = yaw_shift_errors(moved, truth)
    assert err["frame_rmse"] == pytest.approx(np.sqrt(12 / 4))
    assert err["frame_max"] == pytest.approx(3.0)
