"""Options that several commands share: ``--matcher``, ``--cluster`` and the recording options."""

from __future__ import annotations

import argparse

from lburst.burst.keyframes import MotionGate
from lburst.burst.meta import MAX_FPS, MIN_FPS
from lburst.burst.sources import DEFAULT_FPS, Normalisation, RecordingOptions
from lburst.cli.numbers import integer, real
from lburst.errors import LBurstValueError
from lburst.matching import DEFAULT, available, create
from lburst.methods import Method


def add_recording_arguments(p) -> None:
    """The command-line options of :class:`RecordingOptions` (for commands that read recordings);
    ``--every`` stays ``None`` when not given (:func:`recording_options` reads it as 10)."""
    g = p.add_argument_group(
        "recordings (a video, a ROS bag, or a folder of consecutive frames or DNGs; a folder of PNG/JPEG/TIFF "
        "frames without meta.json is one only with --every or --motion)"
    )
    g.add_argument(
        "--burst",
        dest="burst_frames",
        type=integer(1, 99),
        default=5,
        help="frames per burst, odd, centred on each keyframe (default 5)",
    )
    g.add_argument("--every", type=integer(1), help="a keyframe every this many frames (default 10)")
    g.add_argument(
        "--motion",
        type=real(0, 1, low_open=True),
        metavar="F",
        help="instead of --every: a keyframe once the view has moved F of the image width since the last one "
        "(median pixel shift of burst-averaged thumbnails registered by ECC; 0.05-0.2)",
    )
    g.add_argument("--start", type=integer(0), default=0, help="frame index of the first keyframe (default 0)")
    g.add_argument(
        "--fps",
        type=real(MIN_FPS, MAX_FPS),
        help=f"frame rate of a frame folder, {MIN_FPS:g}-{MAX_FPS:g} (default: its meta.json, else {DEFAULT_FPS:g})",
    )
    g.add_argument(
        "--raw-gain",
        default="auto",
        help="linear 16-bit frames: 'auto' (the first burst's mean, binned 4x4: its 99.5th luminance "
        "percentile to 0.94, then 8 bit), 'none' (keep linear), or a fixed gain",
    )
    g.add_argument(
        "--raw-curve",
        choices=("linear", "srgb"),
        default="linear",
        help="tone curve after the gain (default linear, as the networks' training noise)",
    )
    g.add_argument(
        "--topic",
        help="a ROS bag's image topic (sensor_msgs/Image or CompressedImage; default: its only one)",
    )


def recording_options(args) -> RecordingOptions:
    """:class:`RecordingOptions` from :func:`add_recording_arguments`' options (``ValueError`` if bad);
    ``--every`` or ``--motion`` make a folder of plain frames a recording (``frame_folders``)."""
    if args.every is not None and args.motion is not None:
        raise LBurstValueError("give --every or --motion, not both")
    return RecordingOptions(
        burst=args.burst_frames,
        every=args.every or 10,
        start=args.start,
        fps=args.fps,
        normalisation=Normalisation(gain=args.raw_gain, curve=args.raw_curve),
        motion=None if args.motion is None else MotionGate(args.motion),
        frame_folders=args.every is not None or args.motion is not None,
        topic=args.topic,
    )


def matcher_spec(spec: str) -> str:
    """``spec`` if it names a valid matcher with valid options (an argparse ``type``)."""
    try:
        create(spec)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return spec


def parse_method(spec: str) -> Method:
    """The :class:`lburst.methods.Method` of ``spec`` (an argparse ``type``): a spec that breaks
    the grammar is refused as the command line is read; its names and values by ``Method.check``."""
    try:
        return Method.parse(spec)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def matcher_kwargs() -> dict:
    """``add_argument``'s keywords of ``--matcher SPEC``, checked before the command starts."""
    names = ", ".join(m.name for m in available())
    return dict(
        type=matcher_spec,
        default=DEFAULT,
        help=f"how to match descriptors: {names}, with options as NAME,KEY=VALUE "
        f"(default {DEFAULT}; `lburst methods` lists them)",
    )


def add_matcher_argument(parser) -> None:
    """``--matcher SPEC`` (:func:`matcher_kwargs`) on a command's parser."""
    parser.add_argument("--matcher", **matcher_kwargs())


def color_jitter_kwargs(help: str, default: tuple[float, ...] | None = None) -> dict:
    """``add_argument``'s keywords of ``--color-jitter BRIGHTNESS CONTRAST SATURATION HUE``, four
    numbers in [0, 1] (:func:`lburst.photometric.color_jitter`), for training and the homography benchmark."""
    return dict(
        type=real(0, 1), nargs=4, default=default, metavar=("BRIGHTNESS", "CONTRAST", "SATURATION", "HUE"), help=help
    )


def add_color_jitter_argument(parser, help: str, default: tuple[float, ...] | None = None) -> None:
    """``--color-jitter`` (:func:`color_jitter_kwargs`) on ``parser``."""
    parser.add_argument("--color-jitter", **color_jitter_kwargs(help, default))


def add_cluster_argument(p, what: str) -> None:
    """``--cluster local:N | tcp://HOST:PORT``: run ``what`` on a cluster (:mod:`lburst.cluster`); the
    command reads it with :func:`lburst.cluster.spec.parse_cluster` before any work, so that a bad
    one is one line (exit 2)."""
    p.add_argument(
        "--cluster",
        metavar="SPEC",
        help=f"run {what} on a Dask cluster: local:N starts N worker processes on this machine for the run, "
        "tcp://HOST:PORT joins a running scheduler (workers must reach the input and --out); "
        "needs lburst[cluster] (docs/large_surveys.md)",
    )
