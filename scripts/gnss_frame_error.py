"""How far a reconstruction made with GNSS priors lies from the truth in metres, with no scale
fitted: the registered keyframes' camera centres against the ground truth's
(``OUT/reference.json``, which ``lburst reconstruct`` writes from a recording's ``gt.txt``)
after only a rotation about the vertical and a shift, the difference between the flight's
frame and the frame of the first fix.  Also the registered fraction and whether
``OUT/model.las`` holds a CRS laspy reads.

    python scripts/gnss_frame_error.py outputs/geo/rec_jpg [outputs/geo/rec_bag ...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def yaw_shift(source: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray]:
    """The rotation about z (radians) and shift taking ``source`` (N, 3) onto ``target`` in the
    least-squares sense (2-D Procrustes on x, y; the mean difference on z)."""
    a, b = source - source.mean(0), target - target.mean(0)
    angle = float(np.arctan2((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum(), (a[:, :2] * b[:, :2]).sum()))
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return angle, target.mean(0) - rot @ source.mean(0)


def evaluate(out: Path) -> dict:
    result = json.loads((out / "result.json").read_text())
    truth = json.loads((out / "reference.json").read_text())["images"]
    names = [n for n in result["registered"] if n in truth]
    model = np.array([-np.array(result["poses"][n]["R"]).T @ np.array(result["poses"][n]["t"]) for n in names])
    true = np.array([-np.array(truth[n]["R"]).T @ np.array(truth[n]["t"]) for n in names])
    angle, shift = yaw_shift(model, true)
    c, s = np.cos(angle), np.sin(angle)
    aligned = model @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T + shift
    errors = np.linalg.norm(aligned - true, axis=1)
    las = out / "model.las"
    crs = None
    if las.is_file():
        import laspy

        crs = laspy.read(las).header.parse_crs()
    return {
        "out": str(out),
        "registered": f"{len(result['registered'])}/{len(result['names'])}",
        "registered_pct": 100.0 * len(result["registered"]) / len(result["names"]),
        "yaw_deg": float(np.degrees(angle)),
        "rms_m": float(np.sqrt(np.mean(errors**2))),
        "max_m": float(errors.max()),
        "las_crs": None if crs is None else f"EPSG:{crs.to_epsg()} ({crs.name})",
        "positions": (result.get("positions") or {}).get("source"),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("outs", nargs="+", type=Path, help="lburst reconstruct --out folders")
    for out in parser.parse_args().outs:
        print(json.dumps(evaluate(out)))


if __name__ == "__main__":
    main()
