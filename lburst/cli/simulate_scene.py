"""``lburst simulate scene``: a burst scene from a multi-view photo set (:mod:`lburst.scenes.photo_scene`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.cli.numbers import integer, real
from lburst.errors import LBurstValueError, RunFailed
from lburst.scenes.photo_scene import REFERENCE_DIR, REFERENCE_SOURCE, photo_set, simulate_scene
from lburst.scenes.reference_spread import load_spread, summary
from lburst.sfm.colmap import DEFAULT_THREADS
from lburst.sfm.scene import list_scene


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "photos",
        help="folder of photos of one scene (natural order = trajectory order); a gt_cameras/ folder beside it "
        "(Strecha's format) is the reference, with exact cameras, instead of a clean SIFT reconstruction",
    )
    parser.add_argument("--out", required=True, help="scene folder to write")
    parser.add_argument("--frames", type=integer(1, 99), default=5, help="frames per burst (odd)")
    parser.add_argument(
        "--motion-px", type=real(0, 1000), default=2.0, help="largest in-burst motion, pixels per frame"
    )
    parser.add_argument("--noise", default="gaussian:50", help="noise spec (lburst.noise), or 'none'")
    parser.add_argument("--seed", type=integer(0), default=0)
    parser.add_argument("--no-reference", action="store_true", help="skip the clean SIFT reconstruction")
    parser.add_argument(
        "--reference-single-camera",
        action="store_true",
        help="one shared COLMAP camera for all clean photos in the reference reconstruction "
        "(when their priors agree), for a set shot with one camera; default: one camera "
        "per photo (lund needs this and --reference-fix-intrinsics)",
    )
    parser.add_argument(
        "--reference-fix-intrinsics",
        action="store_true",
        help="keep the reference cameras at their prior (EXIF focal length, no distortion) "
        "instead of refining them; with --reference-single-camera for forward motion (lund)",
    )
    parser.add_argument(
        "--reference-threads",
        type=integer(1, 1024),
        default=DEFAULT_THREADS,
        help="COLMAP threads for the reference reconstruction (its result depends on them)",
    )
    parser.add_argument(
        "--reference-seeds",
        nargs="+",
        type=integer(0),
        default=[],
        metavar="SEED",
        help="also reconstruct the clean photos under these COLMAP seeds and record how far each "
        "lies from the reference (OUT/.reference/spread.json): ATE differences below that spread "
        "cannot rank methods on this scene",
    )


def reference_options(args: argparse.Namespace) -> dict:
    """The :class:`lburst.sfm.ReconstructOptions` fields of the clean reference, from the options."""
    return {
        "single_camera": args.reference_single_camera or None,  # None: the default, one camera per photo
        "fix_intrinsics": args.reference_fix_intrinsics,
        "num_threads": args.reference_threads,
    }


def main(args: argparse.Namespace) -> int:
    photos, cameras = photo_set(args.photos)
    if cameras is not None and args.reference_seeds:
        raise LBurstValueError(f"--reference-seeds: {photos} has exact cameras ({cameras}), no reference to rerun")
    ref = simulate_scene(
        args.photos,
        args.out,
        args.frames,
        args.motion_px,
        args.noise,
        args.seed,
        reference=not args.no_reference,
        reference_options=reference_options(args),
        reference_seeds=args.reference_seeds,
    )
    if not args.no_reference:
        if ref is None:
            raise RunFailed(f"the clean photos did not reconstruct; {args.out} has no reference")
        total = len([i for i in list_scene(photos).items if i.kind == "image"])
        if cameras is not None:
            print(
                f"reference: exact cameras of {len(ref.poses)}/{total} photos ({ref.source}, {cameras}) in "
                f"{Path(args.out) / 'reference.json'}"
            )
        else:
            print(
                f"reference: {len(ref.poses)}/{total} photos registered ({REFERENCE_SOURCE}) "
                f"in {Path(args.out) / 'reference.json'}"
            )
        spread = load_spread(args.out, REFERENCE_DIR) if args.reference_seeds else None
        if spread is not None:
            print(f"reference spread: {summary(spread)}")
    print(f"scene written to {args.out}")
    return 0
