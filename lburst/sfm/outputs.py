"""What every reconstruction leaves for other tools, beside COLMAP's model and PLY.

Every input (a scene of bursts or photos, a video, a folder of frames or DNG) leaves the
same files in the output folder ``OUT``:

- ``images/<name>.png``: the common frame of each burst (the frame its features describe);
- ``keyframes.json``: the images in order with their times (a recording's keyframes: seconds
  into the recording; a scene's bursts, which have no time: their index);
- ``trajectory.tum``: the registered images' camera-to-world poses in the model's
  frame, timestamped with those times (:mod:`lburst.tum`); with a reference
  (``OUT/reference.json``: a scene's ``reference.json``, or the poses a recording's ground
  truth gives its keyframes), ``reference.tum`` holds its poses with the same timestamps, so
  that ``evo_ape tum OUT/reference.tum OUT/trajectory.tum -as`` compares them (for a recording
  ``<recording>.gt.txt`` works as well), and ``result.json`` the ATE/RPE;
- ``features.h5``, ``matches.h5``, ``pairs.txt``: hloc's layout, images named as in
  ``OUT/images`` (``<keyframe>.png``): per image ``keypoints`` (K, 2) (pixel centres at
  integers, as hloc), ``descriptors`` (D, K), ``scores``, ``image_size``; per pair
  ``matches.h5[name0][name1]`` with ``matches0`` (K0,) int32 (index into image 1's
  keypoints, -1: unmatched) and ``matching_scores0`` (K0,) float16, the matcher's score of
  each match (:meth:`lburst.matching.DescriptorMatcher.match`: the similarity of the two
  descriptors in [-1, 1]; 0: unmatched);
- with position priors from GNSS that placed the model (:mod:`lburst.sfm.positions`):
  ``model.las`` and ``cameras.geojson`` in the fixes' UTM zone and WGS 84
  (:mod:`lburst.geo.outputs`), the model and ``trajectory.tum`` in metres east, north and up
  of the first fix;
- ``report.md`` with the model's checks (:mod:`lburst.sfm.trust`: whether it shows the signs of a
  folded model), ``trajectory.png`` (top-down, Sim3-aligned to the ground truth
  when there is one) and ``registration.png`` (3D points per image; grey: not
  registered), the 3D points the first and last images share (a closed loop ties them),
  and a table of every image.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lburst.burst.io import atomic_path, h5_file, to_uint8, write_features_h5, write_image
from lburst.matching import similarity
from lburst.sfm.metrics import markdown_table
from lburst.sfm.poses import umeyama
from lburst.sfm.positions import describe
from lburst.sfm.reference import Reference
from lburst.sfm.result import ReconstructionResult, Status
from lburst.sfm.trust import describe_checks
from lburst.tum import write_tum

IMAGES = "images"  # OUT/images: the common frames, named as in features.h5 and COLMAP


def write_common_frame(path: Path, burst: np.ndarray) -> Path:
    """The common frame of ``burst`` (its middle frame, the one its features describe) as an
    8-bit image at ``path`` (its suffix says the format), atomically; makes the folder."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        write_image(tmp, to_uint8(burst[len(burst) // 2]))
    return path


def write_scene_times(out: Path, scene: str, names: list[str]) -> None:
    """``OUT/keyframes.json`` of a scene of bursts: its images in order, each timed by its index."""
    data = {
        "scene": scene,
        "complete": True,
        "keyframes": [{"name": n, "index": i, "time": float(i)} for i, n in enumerate(names)],
    }
    with atomic_path(out / "keyframes.json") as tmp:
        tmp.write_text(json.dumps(data, indent=1))


def copy_reference(reference: Path | None, path: Path) -> None:
    """A scene's ``reference.json`` copied to ``path`` (``OUT/reference.json``, where a
    recording's is written), or none there when the scene has none."""
    if reference is None:
        path.unlink(missing_ok=True)
        return
    with atomic_path(path) as tmp:
        tmp.write_bytes(Path(reference).read_bytes())


def keyframe_times(out: Path) -> dict[str, float]:
    data = json.loads((out / "keyframes.json").read_text())
    return {k["name"]: float(k["time"]) for k in data["keyframes"]}


def write_reference_tum(result: ReconstructionResult, times: dict[str, float], path: Path) -> Path | None:
    """The reference poses (``OUT/reference.json``) of the scene's images as a TUM file, timed as
    ``trajectory.tum``; ``None`` (and no file) without a reference."""
    reference_path = Path(result.out_dir) / "reference.json"
    if not reference_path.is_file():
        path.unlink(missing_ok=True)
        return None
    poses = Reference.load(reference_path).poses
    names = [n for n in result.names if n in poses and n in times]
    return write_tum(
        path,
        [times[n] for n in names],
        [poses[n] for n in names],
        header=f"reference of {result.scene}: {Reference.load(reference_path).source}",
    )


def write_trajectory(result: ReconstructionResult, times: dict[str, float], path: Path) -> Path:
    names = [n for n in result.registered if n in times]
    return write_tum(
        path,
        [times[n] for n in names],
        [result.poses[n] for n in names],
        header=f"lburst reconstruct {result.scene} ({result.method}): keyframes, model frame",
    )


def write_hloc(
    out: Path,
    names: list[str],
    features: list[dict],
    pairs: list[tuple[int, int]],
    matches: list[np.ndarray],
    scores: list[np.ndarray] | None = None,
) -> None:
    """hloc's ``features.h5``, ``matches.h5`` and ``pairs.txt`` (module docstring), each written
    atomically; each image's size is its features' ``image_size`` (W, H).  ``scores[p]`` (M_p,):
    the scores of pair ``p``'s matches; ``None``: the similarity of the matched descriptors
    (:func:`lburst.matching.similarity`)."""
    files = [f"{n}.png" for n in names]
    with atomic_path(out / "features.h5") as tmp:
        tmp.unlink()  # h5py appends to an existing file; start from none
        for file, feats in zip(files, features):
            write_features_h5(tmp, file, feats)
    with atomic_path(out / "matches.h5") as tmp, h5_file(tmp, "w") as f:
        for p, ((a, b), m) in enumerate(zip(pairs, matches)):
            m0 = np.full(len(features[a]["keypoints"]), -1, np.int32)
            m0[m[:, 0]] = m[:, 1]
            s0 = np.zeros(len(m0), np.float16)
            s0[m[:, 0]] = (
                scores[p]
                if scores is not None
                else similarity(features[a]["descriptors"], features[b]["descriptors"], m)
            )
            group = f.require_group(files[a]).create_group(files[b])
            group.create_dataset("matches0", data=m0)
            group.create_dataset("matching_scores0", data=s0)
    with atomic_path(out / "pairs.txt") as tmp:
        tmp.write_text("".join(f"{files[a]} {files[b]}\n" for a, b in pairs))


def _plot_trajectory(result: ReconstructionResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    est = {n: -np.asarray(R).T @ np.asarray(t) for n, (R, t) in result.poses.items()}
    ref_path = Path(result.out_dir) / "reference.json"
    fig, ax = plt.subplots(figsize=(7, 6))
    names = [n for n in result.names if n in est]
    points = np.array([est[n] for n in names]).reshape(-1, 3)
    if ref_path.is_file():
        centres = Reference.load(ref_path).centers()
        ref = np.array([centres[n] for n in result.names if n in centres])
        ax.plot(ref[:, 0], ref[:, 1], "k-", lw=1, label="ground truth")
        common = [n for n in names if n in centres]
        if len(common) >= 3:
            points = umeyama(np.array([est[n] for n in common]), np.array([centres[n] for n in common])).apply(points)
    ax.plot(
        points[:, 0],
        points[:, 1],
        "o",
        ms=4,
        mfc="none",
        c="tab:blue",
        label=f"{result.method}: {len(names)}/{len(result.names)} keyframes",
    )
    if len(points):
        ax.plot(points[:1, 0], points[:1, 1], "g^", ms=9, label="first keyframe")
    ax.set_aspect("equal")
    ax.set_title("camera positions, top-down" + (" (Sim3-aligned)" if ref_path.is_file() else " (model frame)"))
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def _plot_registration(names: list[str], points: dict[str, int], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3))
    x = np.arange(len(names))
    heights = [points.get(n, 0) for n in names]
    colours = ["tab:blue" if n in points else "lightgrey" for n in names]
    ax.bar(x, [h if n in points else max(heights + [1]) for n, h in zip(names, heights)], color=colours)
    ax.set_xlabel("keyframe")
    ax.set_ylabel("3D points seen")
    ax.set_title(f"registration: {len(points)}/{len(names)} keyframes (grey: not registered)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def write_report(result: ReconstructionResult, times: dict[str, float], path: Path) -> None:
    out = Path(result.out_dir)
    summary_path = out / "colmap" / "output.json"
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    points = {n: int(v.get("num_points3D", 0)) for n, v in summary.get("registered", {}).items()}
    _plot_trajectory(result, out / "trajectory.png")
    _plot_registration(result.names, points, out / "registration.png")
    m = result.metrics
    lines = [
        f"# Reconstruction of {Path(result.scene).name}",
        "",
        f"Method `{result.method}`; {len(result.registered)}/{len(result.names)} keyframes registered.",
    ]
    if m.get("camera"):
        lines.append(f"Camera: {m['camera']}.")
    if result.positions:
        lines += ["", *(f"- {line}" for line in describe(result.positions)), ""]
    if result.checks is not None:
        lines += ["", f"**Checks** ({'passed' if result.trusted else 'failed'}): {describe_checks(result.checks)}.", ""]
    if "ate_rmse" in m:
        lines.append(
            f"ATE {m['ate_rmse']:.4f} m RMSE ({m.get('ate_percent', float('nan')):.3f} % of the path) "
            "after a Sim3 alignment to the ground truth."
        )
    if "frame_rmse" in m:
        lines.append(
            f"In the GNSS frame: camera centres {m['frame_rmse']:.3f} m RMS (max {m['frame_max']:.3f} m) from the "
            f"ground truth after only a rotation about the vertical ({m['frame_yaw_deg']:.2f} deg) and a shift, no scale."
        )
    if m.get("first_last_points3D") is not None:
        lines.append(
            f"The first and last keyframes share {m['first_last_points3D']} 3D points of the model "
            "(tracks seen in both, directly or through the keyframes between)."
        )
    if result.error:
        failed = result.status == Status.COLMAP_FAILED
        lines.append(f"{'COLMAP failed' if failed else 'Reading the recording stopped early'}: {result.error}")
    lines += [
        "",
        markdown_table([{"method": result.method, "scene": Path(result.scene).name, **m}]),
        "",
        "![trajectory](trajectory.png)",
        "",
        "![registration](registration.png)",
        "",
        "| keyframe | time (s) | registered | 3D points |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {n} | {times.get(n, float('nan')):.3f} | {'yes' if n in points else 'no'} | {points.get(n, 0)} |"
        for n in result.names
    ]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def write_outputs(
    result: ReconstructionResult,
    features: list[dict],
    pairs: list[tuple[int, int]],
    matches: list[np.ndarray],
    scores: list[np.ndarray] | None = None,
) -> None:
    """``trajectory.tum`` (and ``reference.tum`` with a reference), hloc's files and the report
    of any reconstruction (module docstring), from ``OUT/keyframes.json``'s times; ``scores``:
    those of the matches, as :func:`write_hloc` takes them."""
    out = Path(result.out_dir)
    times = keyframe_times(out)
    write_trajectory(result, times, out / "trajectory.tum")
    write_reference_tum(result, times, out / "reference.tum")
    write_hloc(out, result.names, features, pairs, matches, scores)
    write_report(result, times, out / "report.md")
