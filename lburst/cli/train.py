"""``lburst train``: self-supervised training (:mod:`lburst.train.loop`); under ``torchrun``
(``torchrun --nproc_per_node K -m lburst.cli train ...``) data-parallel on several GPUs."""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import fields, replace
from pathlib import Path

from lburst.cli.numbers import integer, real
from lburst.cli.options import add_color_jitter_argument
from lburst.errors import LBurstValueError
from lburst.model.network import AUTOCAST_DTYPES
from lburst.paths import shared_dir
from lburst.train.loop import PRESETS, TEACHER_INPUTS, TrainConfig, check_resume_options, saved_run_length, train
from lburst.train.pairs import SENSOR_MIX, PairConfig


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
    p.add_argument("--frames", type=integer(1, 99), help="burst length N (1 = single-image network)")
    p.add_argument("--steps", type=integer(1))
    p.add_argument("--batch-size", type=integer(1, 512))
    p.add_argument("--time-budget", type=real(0, low_open=True), help="stop (resumably) after this many seconds")
    p.add_argument("--workers", type=integer(0, 64))
    p.add_argument("--threads", type=integer(1, 1024), help="torch threads")
    p.add_argument(
        "--checkpoint-every",
        type=real(0, low_open=True),
        metavar="SECONDS",
        help="write the resumable last.pt every this many seconds (presets: 300, gpu 60)",
    )
    p.add_argument("--tensorboard", action="store_true", help="also log the losses for TensorBoard (RUN/tensorboard)")
    p.add_argument("--snapshot-every", type=integer(1), help="keep the weights every this many steps (snapshots/)")
    p.add_argument("--precision", choices=sorted(AUTOCAST_DTYPES), help="autocast of the forward pass (default fp32)")
    p.add_argument(
        "--memory-format",
        choices=("auto", "channels_last", "contiguous"),
        default="auto",
        help="tensor layout: auto is channels_last on CUDA and AVX-512 CPUs, contiguous on other CPUs",
    )
    p.add_argument(
        "--rel-logit-weight",
        type=real(0),
        help="weight of the reliability-logit margin loss (keeps a collapsed reliability from saturating)",
    )
    p.add_argument(
        "--ap-weight",
        type=real(0),
        help="weight of the unweighted descriptor AP term (1 - AP) beside R2D2's losses (lburst's presets: 0.25; paper: 0)",
    )
    p.add_argument("--lr", type=real(0, 1, low_open=True), help="Adam's learning rate (default: the preset's)")
    p.add_argument(
        "--rel-base",
        type=real(0, 1),
        help="R2D2's base AP (kappa) of the reliability loss: pixels whose AP passes it learn to be reliable (default 0.5)",
    )
    p.add_argument(
        "--ap-border",
        type=integer(0, 64),
        metavar="PX",
        help="the reliability loss skips query pixels this close to the border (R2D2: 16); "
        "0 also trains reliability at the image border",
    )
    p.add_argument(
        "--distill-weight",
        type=real(0),
        help="weight of dense self-distillation from the noise-free burst (the burst preset: 1)",
    )
    p.add_argument(
        "--max-rotation",
        type=real(0, 180),
        metavar="DEG",
        help="largest in-plane rotation between the two bursts of a training pair (presets: 15); "
        "180 trains descriptors to match views turned any way",
    )
    p.add_argument(
        "--scale-range",
        type=real(0.1, 10),
        nargs=2,
        metavar=("LOW", "HIGH"),
        help="range of the isotropic scale between the two bursts of a training pair, drawn log-uniformly "
        "(presets: 0.8 1.25; R2D2 rescales its second image to 256-1024 px, a far wider range)",
    )
    p.add_argument(
        "--burst-flow",
        type=real(0, 16),
        metavar="PX",
        help="largest std of the smooth non-uniform flow between a burst's frames, per frame, beyond the rest of "
        "its motion (burst and aligned presets: 1): what alignment leaves where the scene has depth",
    )
    p.add_argument(
        "--max-tilt",
        type=real(0, 0.9),
        metavar="FRACTION",
        help="largest perspective tilt between the two bursts: one edge of the crop shrinks and the opposite "
        "one grows by up to this fraction of its length (presets: 0.15)",
    )
    add_color_jitter_argument(
        p,
        help="largest colour change of a pair's second burst against its first: relative brightness, contrast "
        "and saturation, and hue as a fraction of the colour circle (presets: 0 0 0 0; R2D2: 0.2 0.2 0.2 0.1)",
    )
    p.add_argument(
        "--noise-std",
        type=real(0, 255),
        nargs=2,
        metavar=("LOW", "HIGH"),
        help="range of the Gaussian noise's std on 0..255, drawn per burst (presets: 5 110; burst, aligned: 25 120)",
    )
    p.add_argument(
        "--sensor-prob",
        type=real(0, 1),
        metavar="P",
        help="share of training bursts with a calibrated sensor's noise (sensor:NAME@ISO, docs/noise.md), "
        "taken from the Gaussian share (default 0)",
    )
    p.add_argument(
        "--sensors",
        nargs="+",
        metavar="NAME@ISO",
        help=f"the sensors of --sensor-prob, drawn uniformly per burst (default: {' '.join(SENSOR_MIX)})",
    )
    p.add_argument(
        "--spread-weight",
        type=real(0),
        help="weight of the spread loss: the squared norm of the batch's mean descriptor (default 0)",
    )
    p.add_argument(
        "--ema-decay",
        type=real(0, 1),
        metavar="D",
        help="also keep a moving average of the weights, over about 1/(1-D) steps (snapshots/*.ema.pt, "
        "final.pt); below 1, default 0: none",
    )
    p.add_argument(
        "--arch",
        help="network: lburst (Fast-Quad-L2-Net), lite (the light network), or a light network of other widths, "
        "e.g. 'LBurstLite(fine=48,coarse=128,dilations=1-2-4-8)'",
    )
    p.add_argument(
        "--teacher",
        help="distil from this frozen network on the same noisy bursts (a checkpoint or a shipped name, e.g. lburst-b5)",
    )
    p.add_argument(
        "--teacher-sees",
        choices=TEACHER_INPUTS,
        help="what --teacher reads: the student's noisy bursts (default) or the noise-free burst, "
        "so a fine-tune is pulled towards its starting network's clean output",
    )
    p.add_argument("--init", help="start from this checkpoint of our own (e.g. lburst/weights/lburst-b5.pt)")
    p.add_argument("--seed", type=integer(0))
    p.add_argument("--resume", action="store_true", help="continue the run in --out")
    p.add_argument("--device")


def given_options(args: argparse.Namespace) -> dict:
    """The TrainConfig fields set on the command line (``None``: not given)."""
    return {
        "frames": args.frames,
        "steps": args.steps,
        "batch_size": args.batch_size,
        "time_budget_s": args.time_budget,
        "workers": args.workers,
        "threads": args.threads,
        "seed": args.seed,
        "precision": args.precision,
        "snapshot_every": args.snapshot_every,
        "tensorboard": args.tensorboard or None,
        "rel_logit_weight": args.rel_logit_weight,
        "ap_weight": args.ap_weight,
        "lr": args.lr,
        "rel_base": args.rel_base,
        "ap_border": args.ap_border,
        "distill_weight": args.distill_weight,
        "spread_weight": args.spread_weight,
        "ema_decay": args.ema_decay,
        "arch": args.arch,
        "teacher": args.teacher,
        "teacher_sees": args.teacher_sees,
        "init": args.init,
        "checkpoint_every_s": args.checkpoint_every,
    }


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
    return {
        "max_rotation_deg": getattr(args, "max_rotation", None),
        "scale_range": tuple(args.scale_range) if getattr(args, "scale_range", None) else None,
        "max_tilt": getattr(args, "max_tilt", None),
        "burst_flow_px": getattr(args, "burst_flow", None),
        "color_jitter": tuple(args.color_jitter) if getattr(args, "color_jitter", None) else None,
        "noise_std": tuple(args.noise_std) if getattr(args, "noise_std", None) else None,
        "sensor_prob": getattr(args, "sensor_prob", None),
        "sensors": tuple(args.sensors) if getattr(args, "sensors", None) else None,
    }


PAIR_FLAGS = {
    "max_rotation_deg": "--max-rotation",
    "scale_range": "--scale-range",
    "max_tilt": "--max-tilt",
    "burst_flow_px": "--burst-flow",
    "color_jitter": "--color-jitter",
    "noise_std": "--noise-std",
    "sensor_prob": "--sensor-prob",
    "sensors": "--sensors",
}


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
