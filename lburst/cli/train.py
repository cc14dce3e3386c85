"""``lburst train``: self-supervised training (:mod:`lburst.train.loop`); under ``torchrun``
(``torchrun --nproc_per_node K -m lburst.cli train ...``) data-parallel on several GPUs."""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import fields, replace
from pathlib import Path

from lburst.cli.numbers import integer, real
from lburst.cli.options import color_jitter_kwargs
from lburst.cli.table import Option, add_options, given, optional_tuple, true_or_none
from lburst.errors import LBurstValueError
from lburst.model.network import AUTOCAST_DTYPES
from lburst.paths import shared_dir
from lburst.train.loop import PRESETS, TEACHER_INPUTS, TrainConfig, check_resume_options, saved_run_length, train
from lburst.train.pairs import SENSOR_MIX, PairConfig

#: the options that set a :class:`TrainConfig` field (:func:`given_options`), in --help's order
TRAIN_OPTIONS = (
    Option("--frames", "frames", dict(type=integer(1, 99), help="burst length N (1 = single-image network)")),
    Option("--steps", "steps", dict(type=integer(1))),
    Option("--batch-size", "batch_size", dict(type=integer(1, 512))),
    Option(
        "--time-budget",
        "time_budget_s",
        dict(type=real(0, low_open=True), help="stop (resumably) after this many seconds"),
    ),
    Option("--workers", "workers", dict(type=integer(0, 64))),
    Option("--threads", "threads", dict(type=integer(1, 1024), help="torch threads")),
    Option(
        "--checkpoint-every",
        "checkpoint_every_s",
        dict(
            type=real(0, low_open=True),
            metavar="SECONDS",
            help="write the resumable last.pt every this many seconds (presets: 300, gpu 60)",
        ),
    ),
    Option(
        "--tensorboard",
        "tensorboard",
        dict(action="store_true", help="also log the losses for TensorBoard (RUN/tensorboard)"),
        read=true_or_none,
    ),
    Option(
        "--snapshot-every",
        "snapshot_every",
        dict(type=integer(1), help="keep the weights every this many steps (snapshots/)"),
    ),
    Option(
        "--precision",
        "precision",
        dict(choices=sorted(AUTOCAST_DTYPES), help="autocast of the forward pass (default fp32)"),
    ),
    Option(
        "--memory-format",
        None,
        dict(
            choices=("auto", "channels_last", "contiguous"),
            default="auto",
            help="tensor layout: auto is channels_last on CUDA and AVX-512 CPUs, contiguous on other CPUs",
        ),
    ),
    Option(
        "--rel-logit-weight",
        "rel_logit_weight",
        dict(
            type=real(0),
            help="weight of the reliability-logit margin loss (keeps a collapsed reliability from saturating)",
        ),
    ),
    Option(
        "--ap-weight",
        "ap_weight",
        dict(
            type=real(0),
            help="weight of the unweighted descriptor AP term (1 - AP) beside R2D2's losses (lburst's presets: "
            "0.25; paper: 0)",
        ),
    ),
    Option("--lr", "lr", dict(type=real(0, 1, low_open=True), help="Adam's learning rate (default: the preset's)")),
    Option(
        "--rel-base",
        "rel_base",
        dict(
            type=real(0, 1),
            help="R2D2's base AP (kappa) of the reliability loss: pixels whose AP passes it learn to be reliable "
            "(default 0.5)",
        ),
    ),
    Option(
        "--ap-border",
        "ap_border",
        dict(
            type=integer(0, 64),
            metavar="PX",
            help="the reliability loss skips query pixels this close to the border (R2D2: 16); "
            "0 also trains reliability at the image border",
        ),
    ),
    Option(
        "--distill-weight",
        "distill_weight",
        dict(type=real(0), help="weight of dense self-distillation from the noise-free burst (the burst preset: 1)"),
    ),
)

#: the options that set a :class:`PairConfig` field (:func:`given_pair_options`)
PAIR_OPTIONS = (
    Option(
        "--max-rotation",
        "max_rotation_deg",
        dict(
            type=real(0, 180),
            metavar="DEG",
            help="largest in-plane rotation between the two bursts of a training pair (presets: 15); "
            "180 trains descriptors to match views turned any way",
        ),
    ),
    Option(
        "--scale-range",
        "scale_range",
        dict(
            type=real(0.1, 10),
            nargs=2,
            metavar=("LOW", "HIGH"),
            help="range of the isotropic scale between the two bursts of a training pair, drawn log-uniformly "
            "(presets: 0.8 1.25; R2D2 rescales its second image to 256-1024 px, a far wider range)",
        ),
        read=optional_tuple,
    ),
    Option(
        "--burst-flow",
        "burst_flow_px",
        dict(
            type=real(0, 16),
            metavar="PX",
            help="largest std of the smooth non-uniform flow between a burst's frames, per frame, beyond the rest "
            "of its motion (burst and aligned presets: 1): what alignment leaves where the scene has depth",
        ),
    ),
    Option(
        "--max-tilt",
        "max_tilt",
        dict(
            type=real(0, 0.9),
            metavar="FRACTION",
            help="largest perspective tilt between the two bursts: one edge of the crop shrinks and the opposite "
            "one grows by up to this fraction of its length (presets: 0.15)",
        ),
    ),
    Option(
        "--color-jitter",
        "color_jitter",
        color_jitter_kwargs(
            help="largest colour change of a pair's second burst against its first: relative brightness, "
            "contrast and saturation, and hue as a fraction of the colour circle (presets: 0 0 0 0; R2D2: "
            "0.2 0.2 0.2 0.1)"
        ),
        read=optional_tuple,
    ),
    Option(
        "--noise-std",
        "noise_std",
        dict(
            type=real(0, 255),
            nargs=2,
            metavar=("LOW", "HIGH"),
            help="range of the Gaussian noise's std on 0..255, drawn per burst (presets: 5 110; burst, aligned: "
            "25 120)",
        ),
        read=optional_tuple,
    ),
    Option(
        "--sensor-prob",
        "sensor_prob",
        dict(
            type=real(0, 1),
            metavar="P",
            help="share of training bursts with a calibrated sensor's noise (sensor:NAME@ISO, docs/noise.md), "
            "taken from the Gaussian share (default 0)",
        ),
    ),
    Option(
        "--sensors",
        "sensors",
        dict(
            nargs="+",
            metavar="NAME@ISO",
            help=f"the sensors of --sensor-prob, drawn uniformly per burst (default: {' '.join(SENSOR_MIX)})",
        ),
        read=optional_tuple,
    ),
)

#: the options of the network, its teacher and its start (:class:`TrainConfig` fields)
NETWORK_OPTIONS = (
    Option(
        "--spread-weight",
        "spread_weight",
        dict(
            type=real(0), help="weight of the spread loss: the squared norm of the batch's mean descriptor (default 0)"
        ),
    ),
    Option(
        "--ema-decay",
        "ema_decay",
        dict(
            type=real(0, 1),
            metavar="D",
            help="also keep a moving average of the weights, over about 1/(1-D) steps (snapshots/*.ema.pt, "
            "final.pt); below 1, default 0: none",
        ),
    ),
    Option(
        "--arch",
        "arch",
        dict(
            help="network: lburst (Fast-Quad-L2-Net), lite (the light network), or a light network of other "
            "widths, e.g. 'LBurstLite(fine=48,coarse=128,dilations=1-2-4-8)'"
        ),
    ),
    Option(
        "--teacher",
        "teacher",
        dict(
            help="distil from this frozen network on the same noisy bursts (a checkpoint or a shipped name, e.g. "
            "lburst-b5)"
        ),
    ),
    Option(
        "--teacher-sees",
        "teacher_sees",
        dict(
            choices=TEACHER_INPUTS,
            help="what --teacher reads: the student's noisy bursts (default) or the noise-free burst, "
            "so a fine-tune is pulled towards its starting network's clean output",
        ),
    ),
    Option("--init", "init", dict(help="start from this checkpoint of our own (e.g. lburst/weights/lburst-b5.pt)")),
    Option("--seed", "seed", dict(type=integer(0))),
)


def configure_parser(p: argparse.ArgumentParser) -> None:
    default_data = os.environ.get("LBURST_TRAIN_DATA")
    p.add_argument(
        "--data",
        nargs="+",
        default=[default_data] if default_data else None,
        help="folders of training photos (default: $LBURST_TRAIN_DATA, else $LBURST_SHARED/data/train)",
    )
    p.add_argument("--out", required=True, help="run folder (checkpoints, log.csv)")
    p.add_argument("--preset", choices=sorted(PRESETS), default="cpu")
    add_options(p, TRAIN_OPTIONS + PAIR_OPTIONS + NETWORK_OPTIONS)
    p.add_argument("--resume", action="store_true", help="continue the run in --out")
    p.add_argument("--device")


def given_options(args: argparse.Namespace) -> dict:
    """The TrainConfig fields set on the command line (``None``: not given)."""
    return given(args, TRAIN_OPTIONS + NETWORK_OPTIONS)


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    cfg = replace(TrainConfig(), **PRESETS[args.preset])
    overrides = given_options(args)
    names = {f.name for f in fields(TrainConfig)}
    cfg = replace(cfg, **{k: v for k, v in overrides.items() if v is not None and k in names})
    pair = {k: v for k, v in given_pair_options(args).items() if v is not None}
    if pair:
        try:
            cfg = replace(cfg, pair=replace(cfg.pair, **pair))
        except LBurstValueError as exc:
            raise LBurstValueError(
                f"--scale-range/--max-tilt/--burst-flow/--color-jitter/--noise-std/--sensor-prob/--sensors: {exc}"
            ) from exc
    if args.frames is not None:
        cfg = replace(cfg, pair=replace(cfg.pair, frames=args.frames))
    elif cfg.pair.frames != cfg.frames:
        cfg = replace(cfg, pair=replace(cfg.pair, frames=cfg.frames))
    if args.steps is not None:
        cfg = replace(cfg, epochs=None)
    elif args.resume:
        cfg = replace(cfg, **saved_run_length(args.out))
    return cfg


def given_pair_options(args: argparse.Namespace) -> dict:
    """The PairConfig fields set on the command line (``None``: not given)."""
    return given(args, PAIR_OPTIONS)


PAIR_FLAGS = {option.name: option.flag for option in PAIR_OPTIONS}


def _shown(value) -> str:
    """A pair option as it is written on the command line."""
    if isinstance(value, (list, tuple)):
        return " ".join(v if isinstance(v, str) else f"{v:g}" for v in value)
    return f"{value:g}"


def _check_resumed_pairs(out: Path, given: dict) -> None:
    """``LBurstValueError`` when a pair option differs from the resumed run's own (which it keeps)."""
    try:
        saved = json.loads((Path(out) / "config.json").read_text())["pair"]
    except (OSError, ValueError, KeyError, TypeError):
        return
    for name, value in given.items():
        if value is None:
            continue
        old = saved.get(name, PairConfig.__dataclass_fields__[name].default)
        if (tuple(old) if isinstance(old, list) else old) != value:
            shown, kept = _shown(value), _shown(old)
            raise LBurstValueError(
                f"{out}: a resumed run keeps its own settings; leave out {PAIR_FLAGS[name]} {shown} (the run has {kept})"
            )


def main(args: argparse.Namespace) -> int:
    data = args.data or [str(shared_dir() / "data" / "train")]
    cfg = config_from_args(args)
    if args.resume:
        check_resume_options(args.out, given_options(args))
        _check_resumed_pairs(args.out, given_pair_options(args))
    last = train(
        data,
        args.out,
        cfg,
        resume=args.resume,
        device=args.device,
        precision=args.precision,
        memory_format=args.memory_format,
    )
    print(f"checkpoint: {last}")
    return 0
