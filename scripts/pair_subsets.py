"""Map subsets of the pairs that a finished ``lburst reconstruct`` run verified, without
verifying again: which pairs and which loop test give which trajectory.

Reads ``OUT/colmap/database.db`` (COLMAP's two-view geometries of every matched pair),
``OUT/colmap/verified.npz`` and ``OUT/reference.json`` of a run whose pairs include the
wanted ones (e.g. ``--pairs exhaustive``).  Each configuration ``OVERLAP:NEAR:FRACTION:ABS[:TWO]``
copies the database, keeps the verified pairs at most ``OVERLAP`` keyframes apart of which
those more than ``NEAR`` apart must pass the loop test
(:func:`lburst.sfm.colmap.loop_test` with ``FRACTION``), deletes the other two-view
geometries, runs the incremental mapper with ``ABS`` as the fewest 2D-3D inliers to
register a keyframe (``TWO`` 1: triangulating tracks of two keyframes too, 0: not, default:
as the run did), and prints the registered keyframes and the ATE::

    lburst reconstruct flight_dng --burst 5 --every 32 --pairs exhaustive --near 14 --out dng_all
    python scripts/pair_subsets.py dng_all /tmp/subsets 2:2:0:30 3:2:0.4:10 14:2:0.4:10
"""

from __future__ import annotations

import argparse
import shutil
from dataclasses import asdict
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="output folder of a finished lburst reconstruct run")
    parser.add_argument("work", type=Path, help="scratch folder for the databases and models")
    parser.add_argument("configs", nargs="+", help="OVERLAP:NEAR:FRACTION:ABS[:TWO]")
    parser.add_argument("--threads", type=int, default=2, help="mapper threads (lburst reconstruct's default: 2)")
    args = parser.parse_args()

    from lburst.sfm.colmap import ColmapJob, ColmapOptions, loop_test, map_database, pycolmap, summarize
    from lburst.sfm.metrics import evaluate_against_reference
    from lburst.sfm.result import ReconstructionResult

    job = ColmapJob.load(args.run / "colmap" / "job.json")
    names = job.names
    verified = np.load(args.run / "colmap" / "verified.npz")
    pairs = verified["pairs"].reshape(-1, 2)
    counts = [len(verified[f"inl_{q}"]) for q in range(len(pairs))]
    for config in args.configs:
        overlap, near, fraction, abs_inliers, *two = config.split(":")
        overlap, near, abs_inliers = int(overlap), int(near), int(abs_inliers)
        two_view = bool(int(two[0])) if two else job.options.two_view_tracks
        within = (pairs[:, 1] - pairs[:, 0]) <= overlap
        keep, threshold = loop_test(pairs[within], np.array(counts)[within], near, float(fraction), 15)
        kept = {tuple(p) for p in pairs[within][keep].tolist()}
        work = args.work / config.replace(":", "_")
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
        shutil.copy(args.run / "colmap" / "database.db", work / "database.db")
        with pycolmap.Database.open(str(work / "database.db")) as db:
            ids = {Path(image.name).stem: image.image_id for image in db.read_all_images()}
            for a in range(len(names)):
                for b in range(a + 1, len(names)):
                    first, second = ids[names[a]], ids[names[b]]
                    if (a, b) not in kept and db.exists_two_view_geometry(first, second):
                        db.delete_two_view_geometry(first, second)
        options = ColmapOptions(
            **{
                **asdict(job.options),
                "num_threads": args.threads,
                "mapper_threads": args.threads,
                "abs_pose_min_num_inliers": abs_inliers,
                "two_view_tracks": two_view,
            }
        )
        summary = summarize(map_database(work / "database.db", job.image_dir, work / "mapper", options))
        result = ReconstructionResult(str(args.run), "", str(work), names)
        for name, image in summary["registered"].items():
            result.registered.append(name)
            result.poses[name] = (np.array(image["R"]), np.array(image["t"]))
        metrics = evaluate_against_reference(result, args.run / "reference.json")
        registered = sorted(names.index(n) for n in result.registered)
        print(
            f"{config}: {len(kept)} pairs (loop threshold {threshold:.0f}), registered {len(registered)}/{len(names)} "
            f"{registered}, ATE {metrics.get('ate_rmse', float('nan')):.3f} m "
            f"({metrics.get('ate_percent', float('nan')):.2f} % of the path)",
            flush=True,
        )


if __name__ == "__main__":
    main()
