"""``lburst demo``: a synthetic night flight reconstructed with LBurst and with SIFT.

Makes the built-in night flight (:mod:`lburst.scenes.night_flight`: a drone over a toy
city, bursts with real parallax, physical low-light noise, exact ground-truth cameras),
reconstructs it with COLMAP from LBurst features of each burst and from SIFT features
of each noisy common frame, and writes a report folder::

    OUT/report.md         the reconstruction table and the pictures below
    OUT/results.json      every number of the table
    OUT/keypoints_*.png   keypoints of one burst per method (and LBurst's confidence maps)
    OUT/matches_*.png     verified matches between two consecutive bursts per method
    OUT/trajectory.png    top-down view: true vs estimated camera positions (Sim3-aligned)
    OUT/scene/, OUT/<method>/   the scene and each reconstruction (resumable)
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from lburst.burst.io import atomic_path, load_burst, read_features_npz
from lburst.methods import Method
from lburst.scenes.night_flight import NightFlightConfig, make_night_flight
from lburst.sfm.metrics import markdown_table
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.poses import umeyama
from lburst.sfm.reconstruct import reconstruct_scene
from lburst.viz import new_figure, plot_keypoints_and_maps
from lburst.weights import weights_path


def lburst_method(weights: str | None) -> Method:
    """``lburst:W`` for given weights, else the shipped model (error if there is none)."""
    weights = weights or os.environ.get("LBURST_WEIGHTS")
    if weights:
        return Method("lburst", weights)

    weights_path("lburst-b5")  # raises a clear error when no weights are shipped
    return Method("lburst")


def method_labels(methods: Sequence[Method]) -> dict[Method, str]:
    """:meth:`Method.label` of every method (a table row, an output folder), with 6 hex digits of
    its spec's SHA-1 added where two collide."""
    import hashlib

    labels = {method: method.label() for method in methods}
    clashes = {lab for lab in labels.values() if list(labels.values()).count(lab) > 1}
    return {
        method: f"{lab}-{hashlib.sha1(str(method).encode()).hexdigest()[:6]}" if lab in clashes else lab
        for method, lab in labels.items()
    }


def plot_matches(
    image_a: np.ndarray,
    image_b: np.ndarray,
    kp_a: np.ndarray,
    kp_b: np.ndarray,
    path: Path,
    title: str,
    max_lines: int = 300,
) -> None:
    """Two images side by side with lines between matched keypoints (K, 2) each."""
    h = max(image_a.shape[0], image_b.shape[0])
    canvas = np.zeros((h, image_a.shape[1] + image_b.shape[1], 3), image_a.dtype)
    canvas[: image_a.shape[0], : image_a.shape[1]] = image_a
    canvas[: image_b.shape[0], image_a.shape[1] :] = image_b
    fig = new_figure((12, 12 * h / canvas.shape[1] + 0.5))
    ax = fig.subplots()
    ax.imshow(canvas)
    pick = np.random.default_rng(0).permutation(len(kp_a))[:max_lines]
    for i in pick:
        ax.plot([kp_a[i, 0], kp_b[i, 0] + image_a.shape[1]], [kp_a[i, 1], kp_b[i, 1]], lw=0.6, c="lime")
    ax.set_title(f"{title}: {len(kp_a)} verified matches" + (f" ({len(pick)} drawn)" if len(pick) < len(kp_a) else ""))
    ax.set_axis_off()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")


def plot_trajectories(reference, results: dict, path: Path) -> None:
    """Top-down (x, y) camera centres: reference and each method's, Sim3-aligned to it."""
    centres = reference.centers()
    names = list(centres)
    ref = np.array([centres[n] for n in names])
    fig = new_figure((7, 6))
    ax = fig.subplots()
    ax.plot(ref[:, 0], ref[:, 1], "k-o", ms=4, label="ground truth")
    for (label, result), marker in zip(results.items(), "sx^v"):
        common = [n for n in names if n in result.poses]
        if len(common) < 3:
            ax.plot([], [], marker, label=f"{label}: {len(common)}/{len(names)} registered (not aligned)")
            continue
        est = np.array([-np.asarray(result.poses[n][0]).T @ np.asarray(result.poses[n][1]) for n in common])
        aligned = umeyama(est, np.array([centres[n] for n in common])).apply(est)
        ax.plot(
            aligned[:, 0],
            aligned[:, 1],
            marker,
            ms=7,
            mfc="none",
            label=f"{label}: {len(common)}/{len(names)} registered",
        )
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("camera positions, top-down")
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")


def run_demo(
    out: Path,
    methods: Sequence[str | Method],
    noise: str = "lowlight:moonless",
    bursts: int = 15,
    seed: int = 0,
    overlap: int = 4,
    matcher: str = "mnn",
) -> None:
    """The night flight with ``bursts`` bursts of ``noise``, reconstructed with each of ``methods``
    (sequential pairs, ``overlap`` next bursts, the true intrinsics fixed), and the report in
    ``out`` (module docstring); prints progress and the table."""
    from lburst.model.extractor import LBurst

    out.mkdir(parents=True, exist_ok=True)
    cfg = replace(NightFlightConfig(), n_bursts=bursts, noise=noise, seed=seed)
    print(f"[1/3] night flight: {cfg.n_bursts} bursts of {cfg.frames_per_burst} frames, noise {cfg.noise}")
    reference = make_night_flight(out / "scene", cfg)
    results, rows = {}, []
    methods = [Method.of(method) for method in methods]
    labels = method_labels(methods)
    for i, method in enumerate(methods):
        label = labels[method]
        print(f"[2/3] reconstruct with {method} ({i + 1}/{len(methods)})")
        # the drone's camera is calibrated: both methods get the true intrinsics, fixed, and
        # sequential pairs along the trajectory
        result = reconstruct_scene(
            out / "scene",
            method,
            out / label,
            ReconstructOptions(
                camera="reference", fix_intrinsics=True, pairs="sequential", overlap=overlap, matcher=matcher
            ),
        )
        results[label] = result
        rows.append({"method": label, "scene": "night flight", **result.metrics})
    print("[3/3] report")
    names = sorted(p.name for p in (out / "scene").iterdir() if p.is_dir())
    show = names[len(names) // 2]
    burst = load_burst(out / "scene" / show)
    pictures = []
    for label, result in results.items():
        data = result.match_data()
        kp_path = out / f"keypoints_{label}.png"
        feats = read_features_npz(Path(result.out_dir) / "features" / f"{show}.npz")
        maps = (None, None)
        method = next(m for m in methods if labels[m] == label)
        model = getattr(method.create(), "model", None)  # a learned burst method: show its maps too
        if isinstance(model, LBurst) and model.frames == len(burst):
            dense = model.dense(burst)
            maps = (dense["repeatability"], dense["reliability"])
        plot_keypoints_and_maps(
            burst[len(burst) // 2], feats["keypoints"], *maps, kp_path, title=f"{label}, burst {show}"
        )
        pictures.append(kp_path.name)
        if data is not None and len(data[1]):
            keypoints, pairs, inliers = data
            q = int(np.argmax([len(m) for m in inliers]))
            a, b = pairs[q]
            frames = [load_burst(out / "scene" / result.names[j]) for j in (a, b)]
            m_path = out / f"matches_{label}.png"
            plot_matches(
                frames[0][len(frames[0]) // 2],
                frames[1][len(frames[1]) // 2],
                keypoints[a][inliers[q][:, 0]],
                keypoints[b][inliers[q][:, 1]],
                m_path,
                f"{label}: {result.names[a]} - {result.names[b]}",
            )
            pictures.append(m_path.name)
    plot_trajectories(reference, results, out / "trajectory.png")
    pictures.append("trajectory.png")
    table = markdown_table(rows)
    report = [
        "# lburst demo: synthetic night flight",
        "",
        f"{cfg.n_bursts} bursts of {cfg.frames_per_burst} frames, {cfg.width}x{cfg.height}, noise `{cfg.noise}`, "
        f"seed {cfg.seed}; ground truth from the renderer. ATE in metres (and % of the "
        f"{reference.length:.0f} m trajectory) after a Sim3 alignment.",
        "",
        table,
        "",
    ] + [f"![{p}]({p})" for p in pictures]
    with atomic_path(out / "report.md") as tmp:
        tmp.write_text("\n".join(report) + "\n")
    with atomic_path(out / "results.json") as tmp:
        tmp.write_text(json.dumps({"config": cfg.to_dict(), "rows": rows}, indent=1, default=str))
    print(table)
    print(f"\nreport: {(out / 'report.md').resolve()}")
