"""``lburst reconstruct``: a 3D model of a burst scene or recording with COLMAP
(:mod:`lburst.sfm.reconstruct`); its options of the reconstruction are those of
:mod:`lburst.cli.reconstruct_options`, which ``lburst bench reconstruction`` shares."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.cli.options import add_cluster_argument, add_recording_arguments, parse_method, recording_options
from lburst.cli.reconstruct_options import add_reconstruct_arguments, reconstruct_options
from lburst.errors import RunFailed
from lburst.sfm.metrics import markdown_table
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.positions import describe
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
        type=parse_method,
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
    add_reconstruct_arguments(parser)
    add_cluster_argument(parser, "the features and matching stages")
    add_recording_arguments(parser)


def main(args: argparse.Namespace) -> int:
    args.method.check()  # a bad spec or option is one line before a cluster starts or a burst is read
    result = reconstruct_scene(
        args.scene,
        args.method,
        args.out,
        ReconstructOptions(
            **reconstruct_options(args),
            recording=recording_options(args),
            features=args.features,
            cluster=args.cluster,
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
