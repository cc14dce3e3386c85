"""``lburst simulate flight``: the synthetic night flight scene (:mod:`lburst.scenes.night_flight`),
as bursts, a video, DNG frames or PNG frames (:mod:`lburst.scenes.flight_recording`); an arc (``--turn``,
``--loop``) or a lawnmower survey (``--survey LINES``, whose path sets the number of bursts,
so ``--bursts`` is refused with it)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lburst.cli.numbers import integer, real
from lburst.errors import LBurstValueError
from lburst.scenes import flight_gnss
from lburst.scenes import flight_recording as recording
from lburst.scenes.night_flight import NightFlightConfig, check_flight_memory, gnss_positions, make_night_flight
from lburst.sfm.positions import DEFAULT_STD_M, POSITIONS_FILE, write_positions


def configure_parser(p: argparse.ArgumentParser) -> None:
    """Options of a ``lburst simulate flight``-style command (see :func:`main`)."""
    add_output_arguments(p)
    add_flight_arguments(p)


def add_output_arguments(p: argparse.ArgumentParser) -> None:
    """Where the flight goes: the scene folder of bursts, and a video, frames or a bag of it."""
    p.add_argument(
        "out_dir", type=Path, nargs="?", metavar="OUT", help="scene folder of bursts to write (re-running resumes)"
    )
    p.add_argument("--out", type=Path, help="the scene folder OUT, given as an option")
    p.add_argument(
        "--video",
        type=Path,
        help="also (or only) write the flight as a continuous MP4 video, with "
        "per-frame ground truth X.gt.txt (TUM) and X.meta.json (camera, fps); with --noise "
        "lowlight:... or sensor:... its frames are the camera's processing of the --dng version's raw frames",
    )
    p.add_argument(
        "--dng",
        type=Path,
        help="also (or only) write the flight as a folder of Bayer DNG frames, with gt.txt and meta.json inside; "
        "needs a sensor: --noise lowlight:... (12-bit) or sensor:NAME@ISO (that sensor's bit depth and black level)",
    )
    p.add_argument(
        "--png",
        type=Path,
        help="also (or only) write the flight as a folder of 8-bit PNG frames, the --video frames before "
        "encoding, with gt.txt and meta.json inside",
    )
    p.add_argument(
        "--jpg",
        type=Path,
        help="also (or only) write the flight as a folder of JPEG frames with each camera's exact position in "
        "EXIF GPS (the --png frames, on the Earth at lburst.scenes.flight_gnss.FLIGHT_ORIGIN), gt.txt and "
        "meta.json inside",
    )
    p.add_argument(
        "--srt",
        action="store_true",
        help="with --video: also write X.SRT beside it, a DJI drone's subtitles with each frame's exact position",
    )
    p.add_argument(
        "--bag",
        type=Path,
        help="also (or only) write the flight as a ROS bag (X.bag: ROS 1; else a ROS 2 folder, --bag-storage): "
        "JPEG CompressedImage, CameraInfo and NavSatFix (5 Hz, exact) topics, gt.txt beside",
    )
    p.add_argument("--bag-storage", choices=("sqlite3", "mcap"), default="sqlite3", help="storage of a ROS 2 --bag")
    p.add_argument(
        "--crf", type=integer(0, 51), default=16, help="H.264 quality of --video (lower: better; default 16)"
    )


def add_flight_arguments(p: argparse.ArgumentParser) -> None:
    """The flight: its path (an arc, a loop or a survey), camera, bursts, noise and GNSS log."""
    default = NightFlightConfig()
    p.add_argument(
        "--turn",
        type=real(-3600, 3600),
        default=default.turn_deg,
        help="heading change over the flight, degrees (the arc path; not for --survey)",
    )
    p.add_argument("--loop", action="store_true", help="fly a loop that passes over its start again (--turn 380)")
    p.add_argument(
        "--survey",
        type=integer(2),
        metavar="LINES",
        help="fly a lawnmower survey instead of the arc: LINES parallel lines, each the reverse of the last "
        "and --line-spacing to the left of it, joined by semicircular turns; a burst every 8 m of the whole "
        "path (so not with --bursts or --loop), and OUT/survey.json gives each burst's line",
    )
    p.add_argument(
        "--line-length",
        type=real(0, 10_000, low_open=True),
        default=default.line_length,
        metavar="M",
        help="--survey: length of a line, metres",
    )
    p.add_argument(
        "--line-spacing",
        type=real(0, 1_000, low_open=True),
        default=default.line_spacing,
        metavar="M",
        help="--survey: distance between neighbouring lines, metres",
    )
    p.add_argument(
        "--pitch",
        type=real(0, 60),
        default=default.pitch_deg,
        metavar="DEG",
        help="camera tilt from nadir towards the direction of flight, degrees (0: straight down)",
    )
    p.add_argument(
        "--bursts",
        type=integer(2),
        help=f"number of bursts (default {default.n_bursts}; a --survey derives it from its path and refuses it)",
    )
    p.add_argument(
        "--spacing",
        type=real(0, 1_000, low_open=True),
        default=default.burst_spacing,
        metavar="M",
        help="distance flown between consecutive bursts, metres (the world grows with the path: a loop of 1000 "
        "bursts 8 m apart needs over 20 GB, the same bursts 2.4 m apart fly the 300-burst loop)",
    )
    p.add_argument("--frames", type=integer(1, 99), default=default.frames_per_burst, help="frames per burst (odd)")
    p.add_argument("--size", default=f"{default.width}x{default.height}", help="WIDTHxHEIGHT")
    p.add_argument(
        "--noise",
        default=default.noise,
        help="noise spec, e.g. gaussian:50, lowlight:night or sensor:imx686@6400,photons=20 (default: none)",
    )
    p.add_argument("--exposure", type=real(0, low_open=True), default=default.exposure, help="gain before noise")
    p.add_argument("--daylight", action="store_true", help="no night lighting")
    p.add_argument("--supersample", type=integer(1, 16), default=default.supersample, help="anti-aliasing factor")
    p.add_argument("--seed", type=integer(0), default=default.seed)
    p.add_argument(
        "--gnss-noise",
        type=real(0),
        default=DEFAULT_STD_M,
        metavar="M",
        help="OUT/positions.txt: the true camera centres plus Gaussian noise of this many metres on each "
        f"coordinate, a GNSS receiver's log for lburst reconstruct --positions (default {DEFAULT_STD_M})",
    )


def survey_conflict(args: argparse.Namespace) -> str | None:
    """Why ``--survey`` cannot go with the other options given, or None."""
    if args.survey is None:
        return None
    if args.loop:
        return "--survey and --loop are two different paths; give one"
    if args.bursts is not None:
        return "--survey sets the number of bursts from its path (one every 8 m); leave out --bursts"
    return None


def flight_config(args: argparse.Namespace, width: int, height: int) -> NightFlightConfig:
    """The flight the options describe (``ValueError`` if it is not a valid one)."""
    kwargs: dict = dict(
        frames_per_burst=args.frames,
        width=width,
        height=height,
        noise=args.noise,
        exposure=args.exposure,
        supersample=args.supersample,
        seed=args.seed,
        turn_deg=380.0 if args.loop else args.turn,
        pitch_deg=args.pitch,
        burst_spacing=args.spacing,
    )
    if args.bursts is not None:
        kwargs.update(n_bursts=args.bursts)
    if args.survey is not None:
        kwargs.update(survey_lines=args.survey, line_length=args.line_length, line_spacing=args.line_spacing)
    return NightFlightConfig.daylight(**kwargs) if args.daylight else NightFlightConfig(**kwargs)


def main(args: argparse.Namespace) -> int:
    """Render the night flight into ``args.out`` and print where it is."""
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise LBurstValueError(f"--size must be WIDTHxHEIGHT, got {args.size!r}") from None
    if args.out is not None and args.out_dir is not None and args.out != args.out_dir:
        raise LBurstValueError(f"two scene folders given: {args.out_dir} and --out {args.out}")
    args.out = args.out or args.out_dir
    recordings = (args.video, args.dng, args.png, args.jpg, args.bag)
    if args.out is None and all(r is None for r in recordings):
        raise LBurstValueError("give a scene folder OUT, --video FILE.mp4, --dng, --png or --jpg FOLDER, or --bag PATH")
    if args.srt and args.video is None:
        raise LBurstValueError("--srt writes the subtitles of --video: give --video FILE.mp4 too")
    conflict = survey_conflict(args)
    if conflict:
        raise LBurstValueError(conflict)
    cfg = flight_config(args, width, height)
    check_flight_memory(cfg)  # before any output is written
    if args.out is not None:
        ref = make_night_flight(args.out, cfg)
        write_positions(args.out / POSITIONS_FILE, gnss_positions(cfg, args.gnss_noise))
        path = f"a survey of {cfg.survey_lines} lines, " if cfg.survey_lines else ""
        print(
            f"{args.out}: {path}{cfg.n_bursts} bursts of {cfg.frames_per_burst} frames, trajectory {ref.length:.1f} m"
        )
    if any(r is not None for r in recordings):
        frames = f"{recording.frame_count(cfg)} frames at {recording.fps(cfg):g} fps, {width}x{height}"
        if args.video is not None:
            recording.write_flight_video(args.video, cfg, crf=args.crf)
            print(f"{args.video}: {frames}; ground truth {recording.ground_truth_path(args.video)}")
        if args.dng is not None:
            recording.write_flight_dng(args.dng, cfg)
            print(f"{args.dng}: {frames} (DNG); ground truth {recording.ground_truth_path(args.dng)}")
        if args.png is not None:
            recording.write_flight_png(args.png, cfg)
            print(f"{args.png}: {frames} (PNG); ground truth {recording.ground_truth_path(args.png)}")
        if args.srt:
            print(f"{flight_gnss.write_flight_srt(args.video, cfg)}: the position of every frame (DJI subtitles)")
        if args.jpg is not None:
            flight_gnss.write_flight_jpg(args.jpg, cfg)
            print(f"{args.jpg}: {frames} (JPEG, EXIF GPS); ground truth {recording.ground_truth_path(args.jpg)}")
        if args.bag is not None:
            flight_gnss.write_flight_bag(args.bag, cfg, args.bag_storage)
            print(f"{args.bag}: {frames} (ROS bag); ground truth {recording.ground_truth_path(args.bag)}")
    return 0
