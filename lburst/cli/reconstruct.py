"""``lburst reconstruct``: a 3D model of a burst scene or recording with COLMAP
(:mod:`lburst.sfm.reconstruct`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.cli.numbers import integer, real
from lburst.cli.options import add_cluster_argument, add_matcher_argument, add_recording_arguments, recording_options
from lburst.errors import RunFailed
from lburst.methods import check
from lburst.sfm.colmap import DEFAULT_THREADS
from lburst.sfm.metrics import markdown_table
from lburst.sfm.options import (
    AUTO_EXHAUSTIVE_MAX,
    LOOP_FRACTION,
    POSITION_NEIGHBOURS,
    POSITION_RADIUS_M,
    RECORDING_ABS_POSE_INLIERS,
    RECORDING_NEAR,
    RECORDING_OVERLAP,
    RECORDING_RETRIEVAL,
    SCENE_OVERLAP,
    ReconstructOptions,
)
from lburst.sfm.positions import DEFAULT_STD_M, MAX_STD_M, MIN_STD_M, describe
from lburst.sfm.reconstruct import reconstruct_scene
from lburst.sfm.result import Status
from lburst.sfm.trust import describe_checks


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scene",
        help="scene folder (one sub-folder of frames per burst, or single images), "
        "or a recording: a video, a folder of DNG frames or with a meta.json, or, with --every or --motion, "
        "any folder of frames",
    )
    parser.add_argument(
        "--method",
        default="lburst",
        help="feature method spec (lburst, sift, merge+sift, r2d2:CKPT, ...); a learned method keeps 8000"
        " keypoints per image of a scene and 4000 of a recording unless the spec sets top_k=N",
    )
    parser.add_argument("--out", required=True, help="output folder (features cache, COLMAP files, result.json)")
    parser.add_argument(
        "--features",
        metavar="DIR",
        help="a folder that `lburst extract --out DIR` or `lburst reconstruct --out DIR` wrote: features it stored "
        "for the same bursts with the same method are used, not computed again, once checked (a file that cannot "
        "be right stops the run naming it; a warning says why a folder's features were not used) (default: --out)",
    )
    parser.add_argument(
        "--pairs",
        choices=("auto", "exhaustive", "sequential", "positions"),
        default="auto",
        help=f"image pairs to match (auto: for a scene exhaustive up to {AUTO_EXHAUSTIVE_MAX} images, beyond by "
        "positions where the images have them, else sequential; for a recording always sequential with retrieval "
        "loop candidates; positions: each image with its --pair-neighbours nearest images by position within "
        "--pair-radius). Where the positions show views turned by over 90 degrees against the views they are "
        "paired with (survey lines flown both ways), a learned method extracts with rotations=2 unless its spec "
        "sets rotations (rotations=1: upright only)",
    )
    parser.add_argument(
        "--pair-neighbours",
        type=integer(1),
        metavar="K",
        help=f"--pairs positions: nearest images of each (default {POSITION_NEIGHBOURS})",
    )
    parser.add_argument(
        "--pair-radius",
        type=real(0, None, low_open=True),
        metavar="M",
        help=f"--pairs positions: only images within this many metres (default {POSITION_RADIUS_M:g})",
    )
    parser.add_argument(
        "--overlap",
        type=integer(1),
        help=f"sequential pairs: neighbours on each side (default {SCENE_OVERLAP} for a scene, "
        f"{RECORDING_OVERLAP} for a recording)",
    )
    parser.add_argument(
        "--near",
        type=integer(0),
        help="pairs farther apart than this (retrieval candidates, the farthest sequential ones) are kept "
        "only when their inlier count passes the loop test "
        f"(default {RECORDING_NEAR} for a recording, no test for a scene)",
    )
    parser.add_argument(
        "--loop-fraction",
        type=real(0, 1),
        default=LOOP_FRACTION,
        help="loop test: fewest inliers as a fraction of the adjacent pairs' median",
    )
    parser.add_argument(
        "--abs-pose-inliers",
        type=integer(1),
        help=f"fewest 2D-3D inliers to register an image (default {RECORDING_ABS_POSE_INLIERS} for a "
        "recording, 30 for a scene)",
    )
    parser.add_argument(
        "--fallback-exhaustive",
        action="store_true",
        help="rerun with all pairs when sequential pairs leave images unregistered",
    )
    parser.add_argument(
        "--mapper",
        choices=("auto", "incremental", "global"),
        default="incremental",
        help="COLMAP's mapper; auto: the one measured best for the image count, so far incremental at every "
        "size (the global mapper was 15 %% of the path off on loops of 100-1000 keyframes, docs/large_surveys.md)",
    )
    parser.add_argument(
        "--camera",
        choices=("auto", "default", "reference", "reference-focal"),
        default="auto",
        help="intrinsics: auto is the scene's calibration, held fixed (a recording's meta.json camera, or a "
        "reference.json that is calibrated or synthetic), else EXIF, else default; default is COLMAP's guess; "
        "reference is the scene's reference.json cameras as a prior (refined unless --fix-intrinsics); "
        "reference-focal only their focal length, in COLMAP's default camera (--camera-model, centred principal "
        "point, no distortion), refined unless --fix-intrinsics",
    )
    parser.add_argument("--camera-model", default="SIMPLE_RADIAL")
    cameras = parser.add_mutually_exclusive_group()
    cameras.add_argument(
        "--single-camera",
        action="store_const",
        const=True,
        help="one camera for all images (when their priors agree; the default for a recording)",
    )
    cameras.add_argument(
        "--camera-per-image",
        dest="single_camera",
        action="store_const",
        const=False,
        help="one camera per image (the default for a scene of bursts or photos)",
    )
    parser.add_argument("--fix-intrinsics", action="store_true", help="do not refine the intrinsics")
    parser.add_argument("--threads", type=integer(1, 1024), default=DEFAULT_THREADS)
    parser.add_argument(
        "--mapper-threads",
        type=integer(1, 1024),
        help="threads of the mapper (default: 1 for a recording, which makes it repeatable; --threads for a scene)",
    )
    parser.add_argument("--seed", type=integer(0), default=0)
    add_matcher_argument(parser)
    parser.add_argument(
        "--retrieval",
        type=integer(1),
        help="sequential pairs: also match each image with its N most similar images farther apart "
        f"(loop closure; default {RECORDING_RETRIEVAL} for a recording, 0 for a scene)",
    )
    parser.add_argument(
        "--positions",
        type=Path,
        metavar="FILE",
        help="position priors (GNSS, a flight log): lines 'NAME X Y Z' (NAME as the scene or images/ names it), "
        "camera centres in metres in a local Cartesian frame; the incremental mapper holds each camera near its "
        "prior and the model comes out in that frame (lburst simulate flight writes SCENE/positions.txt); "
        "overrides the positions the input carries",
    )
    parser.add_argument(
        "--no-positions",
        dest="input_positions",
        action="store_false",
        help="ignore the positions the input carries (EXIF GPS of its frames, a DJI .SRT beside a video, a bag's "
        "NavSatFix), which are otherwise held as priors: vision alone, the model in COLMAP's own frame",
    )
    parser.add_argument(
        "--position-std",
        type=real(MIN_STD_M, MAX_STD_M),
        default=DEFAULT_STD_M,
        metavar="M",
        help=f"standard deviation of each coordinate of a position prior, metres, {MIN_STD_M:g} to {MAX_STD_M:g} "
        f"(default {DEFAULT_STD_M})",
    )
    add_cluster_argument(parser, "the features and matching stages")
    add_recording_arguments(parser)


def main(args: argparse.Namespace) -> int:
    check(args.method)  # a bad spec or option is one line before a cluster starts or a burst is read
    result = reconstruct_scene(
        args.scene,
        args.method,
        args.out,
        ReconstructOptions(
            pairs=args.pairs,
            overlap=args.overlap,
            neighbours=args.pair_neighbours,
            radius=args.pair_radius,
            fallback_exhaustive=args.fallback_exhaustive,
            mapper=args.mapper,
            camera=args.camera,
            camera_model=args.camera_model,
            single_camera=args.single_camera,
            fix_intrinsics=args.fix_intrinsics,
            num_threads=args.threads,
            seed=args.seed,
            matcher=args.matcher,
            retrieval=args.retrieval,
            near=args.near,
            loop_fraction=args.loop_fraction,
            abs_pose_inliers=args.abs_pose_inliers,
            mapper_threads=args.mapper_threads,
            recording=recording_options(args),
            features=args.features,
            cluster=args.cluster,
            positions=args.positions,
            position_std=args.position_std,
            input_positions=args.input_positions,
        ),
    )

    print(markdown_table([{"method": result.method, "scene": Path(result.scene).name, **result.metrics}]))
    if result.status == Status.COLMAP_FAILED:
        raise RunFailed(result.error)
    if not result.converged:
        raise RunFailed(f"no model: COLMAP registered no images of {args.scene}")
    model = Path(args.out) / "colmap" / "model"
    print(
        f"{len(result.registered)}/{len(result.names)} images registered; model in {model} (pycolmap.Reconstruction opens it)"
    )
    if result.metrics.get("camera"):
        print(f"camera: {result.metrics['camera']}")
    for line in describe(result.positions) if result.positions else ():
        print(line)
    partial = f"{result.error} (the {len(result.names)} keyframes before it were used)"
    if not result.trusted:  # exit 1: a model that its checks find folded is no success (lburst.sfm.trust)
        raise RunFailed(describe_checks(result.checks) + (f"; {partial}" if result.status == Status.PARTIAL else ""))
    print(describe_checks(result.checks))
    if result.status == Status.PARTIAL:
        raise RunFailed(partial)
    return 0
