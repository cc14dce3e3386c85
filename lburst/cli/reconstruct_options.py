"""The options of a reconstruction (:class:`lburst.sfm.options.ReconstructOptions`) on the command
line, one table (:data:`RECONSTRUCT_OPTIONS`) that ``lburst reconstruct`` and ``lburst bench
reconstruction`` both add (:func:`add_reconstruct_arguments`) and read (:func:`reconstruct_options`)."""

from __future__ import annotations

import argparse
from dataclasses import fields
from pathlib import Path
from typing import Any

from lburst.cli.numbers import integer, real
from lburst.cli.options import matcher_kwargs
from lburst.cli.table import Option, add_options, given
from lburst.sfm.colmap import DEFAULT_THREADS
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
    Camera,
    Mapper,
    Pairs,
    ReconstructOptions,
)
from lburst.sfm.positions import DEFAULT_STD_M, MAX_STD_M, MIN_STD_M

PAIRS_HELP = (
    f"image pairs to match (auto: for a scene exhaustive up to {AUTO_EXHAUSTIVE_MAX} images, beyond by "
    "positions where the images have them, else sequential; for a recording always sequential with retrieval "
    "loop candidates; positions: each image with its --pair-neighbours nearest images by position within "
    "--pair-radius). Where the positions show views turned by over 90 degrees against the views they are "
    "paired with (survey lines flown both ways), a learned method extracts with rotations=2 unless its spec "
    "sets rotations (rotations=1: upright only)"
)
CAMERA_HELP = (
    "intrinsics: auto is the scene's calibration, held fixed (a recording's meta.json camera, or a "
    "reference.json that is calibrated or synthetic), else EXIF, else default; default is COLMAP's guess; "
    "reference is the scene's reference.json cameras as a prior (refined unless --fix-intrinsics); "
    "reference-focal only their focal length, in COLMAP's default camera (--camera-model, centred principal "
    "point, no distortion), refined unless --fix-intrinsics"
)
POSITIONS_HELP = (
    "position priors (GNSS, a flight log): lines 'NAME X Y Z' (NAME as the scene or images/ names it), "
    "camera centres in metres in a local Cartesian frame; the incremental mapper holds each camera near its "
    "prior and the model comes out in that frame (lburst simulate flight writes SCENE/positions.txt); "
    "overrides the positions the input carries"
)

#: every option of a reconstruction, in ``lburst reconstruct --help``'s order; each row sets the
#: :class:`ReconstructOptions` field it names
RECONSTRUCT_OPTIONS = (
    Option("--pairs", "pairs", dict(choices=tuple(map(str, Pairs)), default="auto", help=PAIRS_HELP)),
    Option(
        "--pair-neighbours",
        "neighbours",
        dict(
            type=integer(1),
            metavar="K",
            help=f"--pairs positions: nearest images of each (default {POSITION_NEIGHBOURS})",
        ),
    ),
    Option(
        "--pair-radius",
        "radius",
        dict(
            type=real(0, None, low_open=True),
            metavar="M",
            help=f"--pairs positions: only images within this many metres (default {POSITION_RADIUS_M:g})",
        ),
    ),
    Option(
        "--overlap",
        "overlap",
        dict(
            type=integer(1),
            help=f"sequential pairs: neighbours on each side (default {SCENE_OVERLAP} for a scene, "
            f"{RECORDING_OVERLAP} for a recording)",
        ),
    ),
    Option(
        "--near",
        "near",
        dict(
            type=integer(0),
            help="pairs farther apart than this (retrieval candidates, the farthest sequential ones) are kept "
            "only when their inlier count passes the loop test "
            f"(default {RECORDING_NEAR} for a recording, no test for a scene)",
        ),
    ),
    Option(
        "--loop-fraction",
        "loop_fraction",
        dict(
            type=real(0, 1),
            default=LOOP_FRACTION,
            help="loop test: fewest inliers as a fraction of the adjacent pairs' median",
        ),
    ),
    Option(
        "--abs-pose-inliers",
        "abs_pose_inliers",
        dict(
            type=integer(1),
            help=f"fewest 2D-3D inliers to register an image (default {RECORDING_ABS_POSE_INLIERS} for a "
            "recording, 30 for a scene)",
        ),
    ),
    Option(
        "--fallback-exhaustive",
        "fallback_exhaustive",
        dict(action="store_true", help="rerun with all pairs when sequential pairs leave images unregistered"),
    ),
    Option(
        "--mapper",
        "mapper",
        dict(
            choices=tuple(map(str, Mapper)),
            default="incremental",
            help="COLMAP's mapper; auto: the one measured best for the image count, so far incremental at every "
            "size (the global mapper was 15 %% of the path off on loops of 100-1000 keyframes, "
            "docs/large_surveys.md)",
        ),
    ),
    Option("--camera", "camera", dict(choices=tuple(map(str, Camera)), default="auto", help=CAMERA_HELP)),
    Option("--camera-model", "camera_model", dict(default="SIMPLE_RADIAL")),
    Option(
        "--single-camera",
        "single_camera",
        dict(
            action="store_const",
            const=True,
            help="one camera for all images (when their priors agree; the default for a recording)",
        ),
        group="cameras",
    ),
    Option(
        "--camera-per-image",
        None,  # the same field, single_camera
        dict(
            dest="single_camera",
            action="store_const",
            const=False,
            help="one camera per image (the default for a scene of bursts or photos)",
        ),
        group="cameras",
    ),
    Option("--fix-intrinsics", "fix_intrinsics", dict(action="store_true", help="do not refine the intrinsics")),
    Option("--threads", "num_threads", dict(type=integer(1, 1024), default=DEFAULT_THREADS)),
    Option(
        "--mapper-threads",
        "mapper_threads",
        dict(
            type=integer(1, 1024),
            help="threads of the mapper (default: 1 for a recording, which makes it repeatable; --threads for a scene)",
        ),
    ),
    Option("--seed", "seed", dict(type=integer(0), default=0)),
    Option("--matcher", "matcher", matcher_kwargs()),
    Option(
        "--retrieval",
        "retrieval",
        dict(
            type=integer(1),
            help="sequential pairs: also match each image with its N most similar images farther apart "
            f"(loop closure; default {RECORDING_RETRIEVAL} for a recording, 0 for a scene)",
        ),
    ),
    Option("--positions", "positions", dict(type=Path, metavar="FILE", help=POSITIONS_HELP)),
    Option(
        "--no-positions",
        "input_positions",
        dict(
            dest="input_positions",
            action="store_false",
            help="ignore the positions the input carries (EXIF GPS of its frames, a DJI .SRT beside a video, a "
            "bag's NavSatFix), which are otherwise held as priors: vision alone, the model in COLMAP's own frame",
        ),
    ),
    Option(
        "--position-std",
        "position_std",
        dict(
            type=real(MIN_STD_M, MAX_STD_M),
            default=DEFAULT_STD_M,
            metavar="M",
            help=f"standard deviation of each coordinate of a position prior, metres, {MIN_STD_M:g} to "
            f"{MAX_STD_M:g} (default {DEFAULT_STD_M})",
        ),
    ),
)

#: the options of ``lburst bench reconstruction``: a run per seed (its own ``--seeds``), scenes
#: without position priors
BENCH_OPTIONS = tuple(
    o for o in RECONSTRUCT_OPTIONS if o.flag not in ("--seed", "--positions", "--no-positions", "--position-std")
)
#: what every benchmark run's key holds, given or not (its other options count only when given)
BENCH_KEYED = ("pairs", "overlap", "fallback_exhaustive", "mapper", "camera", "single_camera", "num_threads", "matcher")


def add_reconstruct_arguments(parser: argparse.ArgumentParser, options=RECONSTRUCT_OPTIONS) -> None:
    """The rows of ``options`` (by default every reconstruction option) on ``parser``."""
    add_options(parser, options)


def reconstruct_options(args: argparse.Namespace, options=RECONSTRUCT_OPTIONS) -> dict[str, Any]:
    """The :class:`ReconstructOptions` fields of ``options`` as parsed in ``args``."""
    return given(args, options)


def bench_options(args: argparse.Namespace) -> dict[str, Any]:
    """:func:`reconstruct_options` of :data:`BENCH_OPTIONS` for a benchmark's runs: those of
    :data:`BENCH_KEYED` always, the others only when they differ from :class:`ReconstructOptions`'
    defaults, so that a finished run keeps the key it was stored under
    (:func:`lburst.bench.reconstruction.run_key`)."""
    defaults = {f.name: f.default for f in fields(ReconstructOptions)}
    return {
        name: value
        for name, value in reconstruct_options(args, BENCH_OPTIONS).items()
        if name in BENCH_KEYED or value != defaults[name]
    }
