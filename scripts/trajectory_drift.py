"""Where along the path a benchmark's trajectories go wrong: the position error of every
keyframe after the benchmark's similarity alignment, split into along the path, across it
(level) and up, averaged over runs (seeds) of one method.

An error that every seed repeats comes from the features (one part of the path stretched,
a bend); COLMAP's run-to-run spread averages out.  Up is the world's z (a rendered flight's).
The runs are OUT/<method>/<scene>[-seedS] folders of ``lburst bench reconstruction`` (their
``trajectory.tum`` and ``reference.tum``):

    python scripts/trajectory_drift.py "outputs/recon_flight_pad/lburst_top_k=8000_*/flight_moonless*" \
        "outputs/recon_flight_pad/_order=published_*/flight_moonless*" --labels lburst-b5 published
"""

from __future__ import annotations

import argparse
import glob
import json
from pathlib import Path

import numpy as np

from lburst.sfm.poses import camera_to_world, centre_errors
from lburst.tum import lookup, read_tum

UP = np.array([0.0, 0.0, 1.0])


def keyframe_errors(run: Path) -> tuple[np.ndarray, np.ndarray]:
    """(times, (K, 3) errors along / across / up) of one run's keyframes, by timestamp."""
    est_t, est = read_tum(run / "trajectory.tum")
    ref_t, ref = read_tum(run / "reference.tum")
    common = np.intersect1d(np.round(est_t, 6), np.round(ref_t, 6))
    estimated = [lookup(est_t, est, t) for t in common]
    reference = [lookup(ref_t, ref, t) for t in common]
    error = centre_errors(estimated, reference)
    r = np.array([camera_to_world(p)[:3, 3] for p in reference])
    along = np.gradient(r, axis=0)
    along /= np.linalg.norm(along, axis=1, keepdims=True)
    across = np.cross(UP, along)
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    return common, np.stack([(error * along).sum(1), (error * across).sum(1), error @ UP], 1)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("patterns", nargs="+", help="a glob of one method's run folders (its seeds), per method")
    p.add_argument("--labels", nargs="+", help="a name per pattern")
    p.add_argument("--out", type=Path, help="write the mean errors as JSON")
    args = p.parse_args()
    labels = args.labels or args.patterns
    if len(labels) != len(args.patterns):
        p.error(f"{len(args.patterns)} patterns but {len(labels)} labels")
    results = {}
    for label, pattern in zip(labels, args.patterns):
        runs = sorted(Path(r) for r in glob.glob(pattern) if (Path(r) / "trajectory.tum").is_file())
        if not runs:
            p.error(f"{pattern}: no run folder with trajectory.tum")
        found = [keyframe_errors(r) for r in runs]
        times = found[0][0]
        kept = [e for t, e in found if len(t) == len(times) and np.allclose(t, times)]
        mean = np.mean(kept, axis=0)
        results[label] = {
            "runs": len(kept),
            "skipped": len(found) - len(kept),  # runs that registered other keyframes
            "along": mean[:, 0].round(4).tolist(),
            "across": mean[:, 1].round(4).tolist(),
            "up": mean[:, 2].round(4).tolist(),
            "systematic_rmse": float(np.sqrt((mean**2).sum(1).mean())),
        }
        print(
            f"\n{label}: {len(kept)} runs, mean error (m) by keyframe; RMSE of the mean {results[label]['systematic_rmse']:.3f}"
        )
        for name, column in (("along", 0), ("across", 1), ("up", 2)):
            print(f"  {name:6s} " + " ".join(f"{v:+.2f}" for v in mean[:, column]))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
