"""``lburst show``: a PNG of a burst's keypoints and its repeatability and reliability maps."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.burst.io import BurstError
from lburst.burst.sources import RecordingOptions
from lburst.cli.numbers import integer
from lburst.model.extractor import LBurst
from lburst.sfm.inputs import burst_name, open_bursts
from lburst.viz import plot_keypoints_and_maps
from lburst.weights import resolve_weights


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "burst",
        type=Path,
        help="burst folder, image or video, or a recording (video, or a folder of "
        "frames or DNGs with meta.json, or any folder of frames with --frame): then the burst centred on --frame",
    )
    p.add_argument(
        "--frame", type=integer(0), help="recording: the keyframe's frame index (a video without it is one burst)"
    )
    p.add_argument("--frames", type=integer(1, 99), default=5, help="recording: frames in the burst (odd, default 5)")
    p.add_argument("--weights", help="checkpoint (default: $LBURST_WEIGHTS, else the shipped lburst-b5)")
    p.add_argument("--frame-order", choices=["temporal", "published"], default="temporal")
    p.add_argument("--top-k", type=integer(0), default=4000)
    p.add_argument("--out", type=Path, help="PNG path (default: <burst>_keypoints.png here)")
    p.add_argument("--device")


def load_model(weights: str | None, frame_order: str = "temporal", device: str | None = None) -> LBurst:
    """``weights``, else ``$LBURST_WEIGHTS``, else the shipped ``lburst-b5``."""
    import os

    weights = weights or os.environ.get("LBURST_WEIGHTS")
    if weights:
        return LBurst.from_checkpoint(resolve_weights(weights), device=device, frame_order=frame_order)
    return LBurst.pretrained("lburst-b5", device=device)


def load_shown_burst(args: argparse.Namespace):
    """The burst to show: ``args.burst`` itself, or, of a recording (:func:`lburst.sfm.inputs.open_bursts`),
    the burst of ``args.frames`` frames centred on frame ``args.frame`` (default 0)."""
    frame = args.frame or 0
    options = RecordingOptions(
        burst=args.frames,
        every=1,
        start=frame,
        max_frames=frame + args.frames // 2 + 1,
        frame_folders=args.frame is not None,  # --frame: a video or a folder of frames is a recording
    )
    for burst in open_bursts(args.burst, options).keyframe_bursts():
        if burst.index in (None, frame):  # a burst, or the keyframe asked for
            return burst.load()
    raise BurstError(f"{args.burst}: no frame {frame}")


def main(args: argparse.Namespace) -> int:
    model = load_model(args.weights, args.frame_order, args.device)
    burst = load_shown_burst(args)
    features = model.extract(burst, top_k=args.top_k)
    dense = model.dense(burst)
    out = args.out or Path(f"{burst_name(args.burst)}_keypoints.png")
    plot_keypoints_and_maps(
        burst[len(burst) // 2],
        features["keypoints"],
        dense["repeatability"],
        dense["reliability"],
        out,
        title=f"{args.burst}",
    )
    print(f"wrote {out}")
    return 0
