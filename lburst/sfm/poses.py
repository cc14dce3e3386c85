"""Trajectory errors after a similarity alignment: ATE and RPE with evo's definitions.

Implemented here with NumPy/SciPy (evo is not a dependency).  A pose is ``(R, t)``
world-to-camera in COLMAP's convention (``x_cam = R @ x_world + t``); its camera centre
is ``C = -R^T t`` and its camera-to-world pose ``T = [R^T | C]``.

- **Alignment**: the similarity ``x_ref = s * Ra @ x_est + ta`` minimising the squared
  distances between estimated and reference camera centres (Umeyama 1991), applied to
  the estimated camera-to-world poses as ``(Ra @ R_c2w, s * Ra @ C + ta)``.
- **ATE** (evo ``ape``, translation part): for each image ``E_i = Q_i^-1 P_i`` with
  ``Q`` reference and ``P`` aligned estimated camera-to-world poses; the error is
  ``|trans(E_i)| = |C_est,i - C_ref,i|``; reported as RMSE (also mean, median, max).
  Its rotation part (evo ``ape --pose_relation angle_deg``) is ``angle(rot(E_i))`` in degrees,
  the angle between the aligned estimated and the reference orientation of each camera
  (``ate_rot_*_deg``).
- **RPE** (evo ``rpe``, delta = 1 frame): for consecutive images ``i, j`` of the
  trajectory ``E_ij = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``; translation error ``|trans(E_ij)|``
  and rotation error ``angle(rot(E_ij))`` in degrees; reported as RMSE and mean.
- **Relative pose AUC** (:func:`relative_pose_errors`, :func:`pose_auc`; SuperGlue's and
  LightGlue's evaluations, and the pose AUC of reconstruction benchmarks): for every pair of
  reference images, the larger of the angular errors of the estimated relative rotation and
  of the direction of the relative translation (no alignment needed), infinite when either
  image is not registered; the area under the cumulative curve of these errors up to 5, 10
  and 20 degrees, normalised to 1 (1: every pair exact).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from lburst.errors import LBurstValueError

Pose = tuple[np.ndarray, np.ndarray]  # (R (3, 3), t (3,)) world-to-camera


@dataclass(frozen=True)
class Sim3:
    """``x -> scale * rotation @ x + translation``."""

    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform points (N, 3)."""
        return self.scale * np.asarray(points) @ self.rotation.T + self.translation


def umeyama(source: np.ndarray, target: np.ndarray, with_scale: bool = True) -> Sim3:
    """Least-squares similarity (or rigid, ``with_scale=False``) transform taking ``source`` (N, 3) onto ``target`` (N, 3).

    Raises ``ValueError`` for fewer than 3 points or points that are all the same.
    """
    src = np.asarray(source, dtype=np.float64)
    dst = np.asarray(target, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3:
        raise LBurstValueError(f"need two (N, 3) point sets of the same size, got {src.shape} and {dst.shape}")
    if len(src) < 3:
        raise LBurstValueError(f"a similarity alignment needs at least 3 points, got {len(src)}")
    mu_src, mu_dst = src.mean(0), dst.mean(0)
    xs, xd = src - mu_src, dst - mu_dst
    var_src = (xs**2).sum() / len(src)
    if var_src <= 1e-24:
        raise LBurstValueError("cannot align: the source points coincide")
    cov = xd.T @ xs / len(src)
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1
    R = U @ S @ Vt
    scale = float(np.trace(np.diag(D) @ S) / var_src) if with_scale else 1.0
    return Sim3(scale, R, mu_dst - scale * R @ mu_src)


def camera_to_world(pose: Pose) -> np.ndarray:
    """4x4 camera-to-world matrix of a world-to-camera pose ``(R, t)``."""
    R, t = (np.asarray(a, dtype=np.float64) for a in pose)
    T = np.eye(4)
    T[:3, :3] = R.T
    T[:3, 3] = -R.T @ t
    return T


def align_poses(poses: list[Pose], sim: Sim3) -> list[np.ndarray]:
    """Camera-to-world 4x4 matrices of ``poses`` moved into the reference frame by ``sim``."""
    out = []
    for pose in poses:
        T = camera_to_world(pose)
        A = np.eye(4)
        A[:3, :3] = sim.rotation @ T[:3, :3]
        A[:3, 3] = sim.apply(T[:3, 3][None])[0]
        out.append(A)
    return out


def centre_errors(estimated: list[Pose], reference: list[Pose], with_scale: bool = True) -> np.ndarray:
    """(N, 3): each estimated camera centre, moved onto the reference by the similarity (or,
    without ``with_scale``, the rigid motion) that :func:`trajectory_errors` aligns with, minus
    the reference centre.  Its norms are the ATE's per-camera errors."""
    est = np.array([camera_to_world(p)[:3, 3] for p in estimated])
    ref = np.array([camera_to_world(p)[:3, 3] for p in reference])
    return umeyama(est, ref, with_scale).apply(est) - ref


def _stats(errors: np.ndarray) -> dict[str, float]:
    return {
        "rmse": float(np.sqrt(np.mean(errors**2))),
        "mean": float(np.mean(errors)),
        "median": float(np.median(errors)),
        "max": float(np.max(errors)),
    }


def trajectory_errors(
    estimated: list[Pose], reference: list[Pose], with_scale: bool = True, length: float | None = None
) -> dict[str, float]:
    """ATE and RPE (module docstring) of ``estimated`` against ``reference`` poses, matched by position.

    Both lists are in trajectory order; RPE uses consecutive entries.  ``length`` (the
    reference trajectory length) adds ``ate_percent`` = 100 * ATE RMSE / length.
    Returns ``ate_rmse, ate_mean, ate_median, ate_max``, the same of the rotation part
    (``ate_rot_rmse_deg, ...``), ``rpe_trans_rmse, rpe_trans_mean,
    rpe_rot_rmse_deg, rpe_rot_mean_deg, scale, num_poses`` (and ``ate_percent``).
    """
    if len(estimated) != len(reference):
        raise LBurstValueError(f"{len(estimated)} estimated poses but {len(reference)} reference poses")
    est_c = np.array([camera_to_world(p)[:3, 3] for p in estimated])
    ref_T = [camera_to_world(p) for p in reference]
    ref_c = np.array([T[:3, 3] for T in ref_T])
    sim = umeyama(est_c, ref_c, with_scale)
    est_T = align_poses(estimated, sim)
    ate = np.linalg.norm(np.array([T[:3, 3] for T in est_T]) - ref_c, axis=1)
    out = {f"ate_{k}": v for k, v in _stats(ate).items()}
    angles = np.array([rotation_angle_deg(Q[:3, :3].T @ P[:3, :3]) for Q, P in zip(ref_T, est_T)])
    out.update({f"ate_rot_{k}_deg": v for k, v in _stats(angles).items()})
    trans, rot = [], []
    for i in range(len(est_T) - 1):
        rel_ref = np.linalg.inv(ref_T[i]) @ ref_T[i + 1]
        rel_est = np.linalg.inv(est_T[i]) @ est_T[i + 1]
        E = np.linalg.inv(rel_ref) @ rel_est
        trans.append(np.linalg.norm(E[:3, 3]))
        rot.append(np.degrees(Rotation.from_matrix(E[:3, :3]).magnitude()))
    trans_a, rot_a = np.array(trans), np.array(rot)
    out.update(
        rpe_trans_rmse=float(np.sqrt(np.mean(trans_a**2))),
        rpe_trans_mean=float(trans_a.mean()),
        rpe_rot_rmse_deg=float(np.sqrt(np.mean(rot_a**2))),
        rpe_rot_mean_deg=float(rot_a.mean()),
        scale=sim.scale,
        num_poses=len(estimated),
    )
    if length:
        out["ate_percent"] = 100.0 * out["ate_rmse"] / length
    return out


def yaw_shift_errors(estimated: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """Errors of camera centres ``estimated`` (N, 3) that should already be in ``reference``'s
    metric, z-up frame (a model georeferenced by GNSS): after only the rotation about z and the
    shift that best take one onto the other (least squares: a 2-D Procrustes on x, y and the
    mean difference on z), with no scale fitted.  Returns ``frame_rmse``, ``frame_max`` (metres)
    and ``frame_yaw_deg`` (the rotation that was needed)."""
    a, b = estimated - estimated.mean(0), reference - reference.mean(0)
    angle = float(np.arctan2((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum(), (a[:, :2] * b[:, :2]).sum()))
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    errors = np.linalg.norm(a @ rot.T - b, axis=1)
    return {
        "frame_rmse": float(np.sqrt(np.mean(errors**2))),
        "frame_max": float(errors.max()),
        "frame_yaw_deg": float(np.degrees(angle)),
    }


def path_length(centres: np.ndarray) -> float:
    """Length of the polyline through camera centres (N, 3) in order."""
    c = np.asarray(centres, dtype=np.float64)
    return float(np.linalg.norm(np.diff(c, axis=0), axis=1).sum()) if len(c) > 1 else 0.0


def rotation_angle_deg(R: np.ndarray) -> float:
    """The angle in degrees of a rotation matrix."""
    return float(np.degrees(Rotation.from_matrix(R).magnitude()))


def direction_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle in degrees between two vectors (180 when either is zero)."""
    norms = np.linalg.norm(a) * np.linalg.norm(b)
    if norms <= 1e-15:
        return 180.0
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / norms, -1.0, 1.0))))


def relative_pose(a: Pose, b: Pose) -> Pose:
    """The pose of camera ``b`` from camera ``a``: ``(R, t)`` with ``x_b = R x_a + t``."""
    (Ra, ta), (Rb, tb) = a, b
    R = Rb @ Ra.T
    return R, tb - R @ ta


def relative_pose_errors(estimated: dict[str, Pose], reference: dict[str, Pose]) -> np.ndarray:
    """For every pair of ``reference``'s images (in its order), the larger of the angular errors
    (degrees) of the estimated relative rotation and of the relative translation's direction;
    ``inf`` for a pair with an image that ``estimated`` lacks (module docstring)."""
    names = list(reference)
    errors = []
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            if a not in estimated or b not in estimated:
                errors.append(np.inf)
                continue
            R_est, t_est = relative_pose(estimated[a], estimated[b])
            R_ref, t_ref = relative_pose(reference[a], reference[b])
            errors.append(max(rotation_angle_deg(R_ref.T @ R_est), direction_angle_deg(t_est, t_ref)))
    return np.array(errors, dtype=np.float64)


AUC_DEG = (5, 10, 20)


def pose_auc(errors, limits=AUC_DEG) -> dict[str, float]:
    """Area under the cumulative curve of ``errors`` (degrees; ``inf`` never counts) up to each
    limit, normalised to 1, keyed by the limit as text."""
    errs = np.sort(np.asarray(errors, float))
    if len(errs) == 0:
        return {str(limit): 0.0 for limit in limits}
    recall = np.arange(1, len(errs) + 1) / len(errs)
    errs, recall = np.r_[0.0, errs], np.r_[0.0, recall]
    out = {}
    for limit in limits:
        i = np.searchsorted(errs, limit)
        x = np.r_[errs[:i], limit]
        y = np.r_[recall[:i], recall[i - 1]]
        out[str(limit)] = float(np.trapezoid(y, x) / limit)
    return out
