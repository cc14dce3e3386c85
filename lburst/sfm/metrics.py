"""The paper's reconstruction table: per method and scene, and averaged over scenes.

Definitions (N = images in the scene, sums over the matched pairs of the final run):

- ``converged``: COLMAP returned a model (at least ``min_model_size`` = 3 images,
  registered by the mapper and refined by its global bundle adjustment); the
  *convergence rate* of a method is the fraction of scenes where it converged.
- ``registered_pct``: 100 * images in the largest model / N.
- ``keypoints_per_image``: mean number of keypoints.
- ``putative_per_image``: (sum of mutual-nearest-neighbour matches over pairs) / N.
- ``inliers_per_image``: (sum of matches kept by COLMAP's geometric verification) / N.
- ``match_ratio``: inliers / putative matches (sums over pairs).
- ``match_score``: inliers per image / keypoints per image.
- ``points3D_per_image``: 3D points of the largest model / registered images.
- ``precision`` (with a reference): fraction of the verified inlier matches whose
  symmetric epipolar distance under the *reference* cameras is at most ``4 px`` (COLMAP's
  RANSAC threshold): for a match (x_a, x_b) between reference images a and b, both are
  undistorted to normalised coordinates with the reference camera, the distance of each
  to the other's epipolar line (essential matrix of the reference relative pose) is
  scaled to pixels by the camera's focal length, and the larger of the two is used.
  Only pairs whose two images both have reference poses count.
- Trajectory errors (with a reference, at least 3 images registered in both): ATE and
  RPE after a Sim3 alignment of estimated to reference camera centres
  (:mod:`lburst.sfm.poses`), ATE also as % of the reference trajectory length, and the ATE's
  rotation part ``ate_rot_rmse_deg`` (RMSE of each camera's orientation error after that
  alignment, degrees).
- ``pose_auc_5``, ``pose_auc_10``, ``pose_auc_20`` (with a reference): the relative pose AUC
  over every pair of reference images (:func:`lburst.sfm.poses.relative_pose_errors`; a pair
  with an unregistered image counts as failed), to 5, 10 and 20 degrees.
- ``fitted_focal``, ``fitted_k`` (:func:`camera_metrics`): the median over the registered
  images of their camera's focal length (px) and first radial distortion coefficient after
  bundle adjustment (``k`` of ``SIMPLE_RADIAL``, ``k1`` of ``RADIAL`` and ``OPENCV``; absent for a
  model without one, such as ``PINHOLE``).
- ``points3D``: 3D points of the largest model.
- ``frame_rmse``, ``frame_max``, ``frame_yaw_deg`` (with a reference, for a model placed in the
  frame of its GNSS positions): camera centres against the reference's after only a rotation
  about the vertical and a shift, no scale (:func:`lburst.sfm.poses.yaw_shift_errors`): how far
  a georeferenced model lies from the truth in metres.

Averages over scenes are plain means of the per-scene values; a scene that did not
converge contributes 0 registered images and 0 points, and no trajectory error
(trajectory errors are averaged over converged scenes only, with their count).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import numpy as np

from lburst.burst.io import file_sha1
from lburst.sfm.colmap import pycolmap
from lburst.sfm.poses import (
    AUC_DEG,
    camera_to_world,
    path_length,
    pose_auc,
    relative_pose_errors,
    trajectory_errors,
    yaw_shift_errors,
)
from lburst.sfm.reference import Reference
from lburst.sfm.scene import reference_cameras


class Reconstruction(Protocol):
    """What the metrics read of a reconstruction (:class:`lburst.sfm.reconstruct.ReconstructionResult` has it)."""

    names: list[str]  # every image of the scene, in scene order
    poses: dict[str, tuple[np.ndarray, np.ndarray]]  # registered image -> world-to-camera (R (3, 3), t (3,))

    def match_data(self) -> tuple[list[np.ndarray], np.ndarray, list[np.ndarray]] | None:
        """Keypoints per image, verified pairs (Q, 2) and their inlier matches, or ``None``."""


PRECISION_THRESHOLD_PX = 4.0

# (key, column title, format) of the markdown table
COLUMNS: list[tuple[str, str, str]] = [
    ("converged", "conv.", "{:.2f}"),
    ("registered_pct", "reg. %", "{:.1f}"),
    ("keypoints_per_image", "kp/img", "{:.0f}"),
    ("putative_per_image", "putative/img", "{:.0f}"),
    ("inliers_per_image", "inliers/img", "{:.0f}"),
    ("match_ratio", "match ratio", "{:.3f}"),
    ("match_score", "match score", "{:.3f}"),
    ("precision", "precision", "{:.3f}"),
    ("points3D_per_image", "3D pts/img", "{:.0f}"),
    ("ate_rmse", "ATE", "{:.3g}"),
    ("ate_percent", "ATE %", "{:.2f}"),
    ("rpe_trans_rmse", "RPE t", "{:.3g}"),
    ("rpe_rot_rmse_deg", "RPE R (deg)", "{:.2f}"),
    ("ate_rot_rmse_deg", "rot. err (deg)", "{:.3f}"),
    *((f"pose_auc_{d}", f"AUC@{d}", "{:.3f}") for d in AUC_DEG),
    ("fitted_k", "fitted k", "{:.4f}"),
]
TRAJECTORY_KEYS = ("ate_rmse", "ate_percent", "rpe_trans_rmse", "rpe_rot_rmse_deg", "ate_rot_rmse_deg")
#: the reference metrics that every pair of reference images decides, a failed run's included
POSE_AUC_KEYS = tuple(f"pose_auc_{d}" for d in AUC_DEG)
#: what COLMAP's bundle adjustment fitted: the first radial coefficient's index in each model's params
RADIAL_PARAM = {"SIMPLE_RADIAL": 3, "RADIAL": 3, "OPENCV": 4, "FULL_OPENCV": 4, "SIMPLE_RADIAL_FISHEYE": 3}


def scene_metrics(
    n_images: int, keypoint_counts: list[int], putative_counts: list[int], inlier_counts: list[int], summary: dict
) -> dict[str, float]:
    """The reference-free columns for one scene (module docstring), from counts and the COLMAP summary."""
    kp = float(np.sum(keypoint_counts))
    putative = float(np.sum(putative_counts))
    inliers = float(np.sum(inlier_counts))
    registered = len(summary.get("registered", {}))
    return {
        "converged": float(bool(summary.get("converged")) and registered > 0),
        "registered_pct": 100.0 * registered / n_images if n_images else 0.0,
        "keypoints_per_image": kp / n_images if n_images else 0.0,
        "putative_per_image": putative / n_images if n_images else 0.0,
        "inliers_per_image": inliers / n_images if n_images else 0.0,
        "match_ratio": inliers / putative if putative else 0.0,
        "match_score": inliers / kp if kp else 0.0,
        "points3D_per_image": summary.get("num_points3D", 0) / registered if registered else 0.0,
        "points3D": float(summary.get("num_points3D", 0)) if registered else 0.0,
        "mean_track_length": float(summary.get("mean_track_length", 0.0)),
        "mean_reprojection_error": float(summary.get("mean_reprojection_error", 0.0)),
    }


def camera_metrics(cameras: dict[str, dict]) -> dict[str, float]:
    """``fitted_focal`` and ``fitted_k`` (module docstring) of the registered images' COLMAP camera dicts."""
    if not cameras:
        return {}
    focal = [
        float(pycolmap.Camera({k: c[k] for k in ("model", "width", "height", "params")}).mean_focal_length())
        for c in cameras.values()
    ]
    out = {"fitted_focal": float(np.median(focal))}
    radial = [float(c["params"][RADIAL_PARAM[c["model"]]]) for c in cameras.values() if c["model"] in RADIAL_PARAM]
    if radial:
        out["fitted_k"] = float(np.median(radial))
    return out


def epipolar_distances(
    points_a: np.ndarray,
    points_b: np.ndarray,
    camera_a: dict,
    camera_b: dict,
    pose_a: tuple[np.ndarray, np.ndarray],
    pose_b: tuple[np.ndarray, np.ndarray],
) -> np.ndarray:
    """Symmetric epipolar distance (M,) in pixels of matches (M, 2) (COLMAP pixel convention) under given cameras.

    ``camera_*`` are COLMAP camera dicts, ``pose_*`` world-to-camera ``(R, t)``.  Each
    point's distance to the epipolar line of its partner is measured in the normalised
    image plane and scaled by that camera's mean focal length; the larger is returned.
    """
    cam_a = pycolmap.Camera({k: camera_a[k] for k in ("model", "width", "height", "params")})
    cam_b = pycolmap.Camera({k: camera_b[k] for k in ("model", "width", "height", "params")})
    if len(points_a) == 0:
        return np.zeros(0)
    xa = np.c_[cam_a.cam_from_img(np.asarray(points_a, np.float64)), np.ones(len(points_a))]
    xb = np.c_[cam_b.cam_from_img(np.asarray(points_b, np.float64)), np.ones(len(points_b))]
    (Ra, ta), (Rb, tb) = pose_a, pose_b
    R = Rb @ Ra.T
    t = tb - R @ ta
    E = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) @ R
    lines_b = xa @ E.T  # epipolar lines in b of the points of a
    lines_a = xb @ E  # epipolar lines in a of the points of b
    residual = np.abs(np.sum(xb * lines_b, axis=1))
    d_b = residual / np.maximum(np.linalg.norm(lines_b[:, :2], axis=1), 1e-12) * cam_b.mean_focal_length()
    d_a = residual / np.maximum(np.linalg.norm(lines_a[:, :2], axis=1), 1e-12) * cam_a.mean_focal_length()
    return np.maximum(d_a, d_b)


def match_precision(
    names: list[str],
    keypoints: list[np.ndarray],
    pairs: np.ndarray,
    inliers: list[np.ndarray],
    reference: Reference,
    cameras: dict[str, dict],
    threshold: float = PRECISION_THRESHOLD_PX,
) -> tuple[float | None, int]:
    """Fraction of inlier matches within ``threshold`` px of the reference epipolar geometry, and how many were checked.

    ``keypoints[i]`` (K_i, 2) in lburst's convention (+0.5 is added here); ``pairs`` (Q, 2)
    image indices with inlier keypoint index pairs ``inliers[q]`` (M_q, 2).  Returns
    ``(None, 0)`` when no pair has both images in the reference.
    """
    good = total = 0
    for (a, b), m in zip(pairs, inliers):
        na, nb = names[a], names[b]
        if na not in reference.poses or nb not in reference.poses or len(m) == 0:
            continue
        d = epipolar_distances(
            keypoints[a][m[:, 0]] + 0.5,
            keypoints[b][m[:, 1]] + 0.5,
            cameras[na],
            cameras[nb],
            reference.poses[na],
            reference.poses[nb],
        )
        good += int(np.sum(d <= threshold))
        total += len(d)
    return (good / total if total else None), total


def reference_length(reference: Reference, order: list[str]) -> float:
    """The reference's ``length``, else the path length through its camera centres in scene order."""
    if reference.length:
        return float(reference.length)
    centres = reference.centers()
    return path_length(np.array([centres[n] for n in order if n in centres]))


def evaluate_against_reference(
    result: Reconstruction,
    reference: Reference | str | Path,
    cameras: dict[str, dict] | None = None,
    threshold: float = PRECISION_THRESHOLD_PX,
) -> dict[str, Any]:
    """Trajectory errors and match precision of ``result`` against ``reference`` (module docstring).

    ``reference`` is a :class:`Reference` or the path of a ``reference.json`` (whose
    per-image ``cameras`` are then used).  ``cameras`` maps image names to reference
    camera dicts (default: those of the file, else ``reference.camera`` for every image).
    Returns ``precision``, ``precision_matches``, ``ate_*``, ``rpe_*``, ``num_poses``
    (keys absent when they cannot be computed, e.g. fewer than 3 common registered images),
    ``pose_auc_*`` (every pair of reference images), and for a file its ``reference_sha1``
    (so a result can tell when it was remade).
    """
    out: dict[str, Any] = {}
    if not isinstance(reference, Reference):
        out["reference_sha1"] = file_sha1(reference)
        cameras = cameras or reference_cameras(reference)
        reference = Reference.load(reference)
    cameras = cameras or {name: reference.camera for name in reference.poses}
    out["reference_source"] = reference.source
    data = result.match_data()
    if data is not None:
        keypoints, pairs, inliers = data
        precision, checked = match_precision(result.names, keypoints, pairs, inliers, reference, cameras, threshold)
        if precision is not None:
            out.update(precision=precision, precision_matches=checked)
    ordered = {n: reference.poses[n] for n in result.names if n in reference.poses}
    auc = pose_auc(relative_pose_errors(result.poses, ordered))
    out.update({f"pose_auc_{d}": auc[str(d)] for d in AUC_DEG})
    common = [n for n in result.names if n in result.poses and n in reference.poses]
    if len(common) >= 3:
        try:
            errors = trajectory_errors(
                [result.poses[n] for n in common],
                [reference.poses[n] for n in common],
                length=reference_length(reference, result.names),
            )
        except ValueError:
            errors = {}
        out.update(errors)
        positions = getattr(result, "positions", None) or {}
        if positions.get("in_frame"):  # the model is in the GNSS frame: how far, with no scale fitted
            out.update(
                yaw_shift_errors(
                    np.array([camera_to_world(result.poses[n])[:3, 3] for n in common]),
                    np.array([camera_to_world(reference.poses[n])[:3, 3] for n in common]),
                )
            )
    return out


def aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean over scenes of each column (see the module docstring for trajectory errors)."""
    out: dict[str, Any] = {"scenes": len(rows)}
    for key, _, _ in COLUMNS:
        values = [row[key] for row in rows if row.get(key) is not None]
        if key in TRAJECTORY_KEYS:
            values = [row[key] for row in rows if row.get(key) is not None and row.get("converged")]
            if key == "ate_rmse":
                out["trajectory_scenes"] = len(values)
        out[key] = float(np.mean(values)) if values else None
    return out


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """A markdown table, one row per dict (which carries ``method`` and ``scene`` labels)."""
    head = ["method", "scene"] + [title for _, title, _ in COLUMNS]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        cells = [str(row.get("method", "")), str(row.get("scene", ""))]
        for key, _, fmt in COLUMNS:
            value = row.get(key)
            cells.append("-" if value is None else fmt.format(value))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


#: the columns of :func:`seed_summary`: (key, column title, format)
SEED_COLUMNS: list[tuple[str, str, str]] = [
    ("registered_pct", "reg. %", "{:.1f}"),
    ("points3D_per_image", "3D pts/img", "{:.0f}"),
    ("points3D", "3D pts", "{:.0f}"),
    ("ate_rmse", "ATE", "{:.3g}"),
    ("ate_rot_rmse_deg", "rot. err (deg)", "{:.3f}"),
    *((f"pose_auc_{d}", f"AUC@{d}", "{:.3f}") for d in AUC_DEG),
    ("fitted_k", "fitted k", "{:.4f}"),
]


def seed_summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (method, scene), over its runs with different seeds: ``runs``, ``converged`` (how many
    made a model) and, for each :data:`SEED_COLUMNS` key, the median, min and max over the runs
    that have it (``KEY``, ``KEY_min``, ``KEY_max``); a run without a model counts 0 registered
    images, 0 points and a pose AUC of 0 (when the others have one), and no trajectory error or
    fitted distortion (as in :func:`aggregate`)."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault((row["method"], row["scene"]), []).append(row)
    out = []
    for (method, scene), runs in groups.items():
        summary: dict[str, Any] = {"method": method, "scene": scene, "runs": len(runs)}
        summary["converged"] = sum(1 for r in runs if r.get("converged"))
        for key, _, _ in SEED_COLUMNS:
            if key in TRAJECTORY_KEYS or key == "fitted_k":
                values = [r[key] for r in runs if r.get(key) is not None and r.get("converged")]
            elif key in POSE_AUC_KEYS and not any(r.get(key) is not None for r in runs):
                values = []  # no reference
            else:
                values = [r.get(key) or 0.0 for r in runs]
            if values:
                summary.update({key: float(np.median(values)), f"{key}_min": min(values), f"{key}_max": max(values)})
        out.append(summary)
    return out


def seed_table(summaries: list[dict[str, Any]]) -> str:
    """A markdown table of :func:`seed_summary`: the median and, in brackets, the range."""
    head = ["method", "scene", "runs", "models"] + [f"{title} median (range)" for _, title, _ in SEED_COLUMNS]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s in summaries:
        cells = [str(s["method"]), str(s["scene"]), str(s["runs"]), str(s["converged"])]
        for key, _, fmt in SEED_COLUMNS:
            if s.get(key) is None:
                cells.append("-")
            else:
                low, high = (fmt.format(s[f"{key}_{end}"]) for end in ("min", "max"))
                cells.append(f"{fmt.format(s[key])} ({low}-{high})")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
