"""The training loop behind ``lburst train`` (:mod:`lburst.cli.train`).

A run lives in one folder: ``last.pt`` (resumable: weights, optimizer, step, config,
RNG state; written atomically every few minutes and at the end), ``log.csv`` (one row
per step), ``config.json`` and, at the end, ``final.pt`` in the published checkpoint
layout.  ``--resume`` continues from ``last.pt`` with the same data stream, so a run
stopped and resumed reaches the same steps as one that never stopped.  Under
``torchrun`` it trains data-parallel on several GPUs (:mod:`lburst.train.distributed`);
``--tensorboard`` adds a TensorBoard log.
"""

from __future__ import annotations

import csv
import json
import signal
import threading
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import torch
import torch.nn.functional as F
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
from torch.utils.data import DataLoader
from tqdm import tqdm

from lburst.burst.io import atomic_path
from lburst.errors import LBurstFileExistsError, LBurstValueError
from lburst.extras import MissingExtra
from lburst.model.lite import LITE_NAME, LiteConfig, LiteNet
from lburst.model.network import (
    LITE_SMALLER,
    CheckpointError,
    LBurstNet,
    NetConfig,
    autocast_dtype,
    check_device,
    check_precision,
    checked_network,
    checkpoint_dict,
    load_checkpoint,
    replicate_frames,
    save_checkpoint,
    training_memory_format,
    write_checkpoint,
)
from lburst.noise import IMAGENET_MEAN, IMAGENET_STD
from lburst.process import keeps_state
from lburst.train import distributed
from lburst.train.data import PairDataset, StreamSampler, init_worker, list_photos
from lburst.train.distill import lite_distillation_step, teacher_form
from lburst.train.losses import (
    APSampling,
    cosim_loss,
    distillation_loss,
    logit_margin_loss,
    peaky_loss,
    reliability_ap_loss,
    spread_loss,
)
from lburst.train.memory import check_step_memory
from lburst.train.pairs import PairConfig
from lburst.weights import resolve_weights

LOG_FIELDS = (
    "step",
    "seconds",
    "loss",
    "cosim",
    "peaky",
    "reliability",
    "ap",
    "distill",
    "spread",
    "distill_desc",
    "distill_rep",
    "distill_rel",
)


@dataclass(frozen=True)
class TrainConfig:
    """A training run.  ``steps`` bounds the run; ``time_budget_s`` stops it earlier
    (resumable).  ``epochs`` (if set) overrides ``steps`` as epochs x photos / batch.

    ``ap_weight`` adds ``ap_weight * (1 - AP)`` to the loss.  R2D2's reliability loss
    trains descriptors only through ``AP * rel``: when AP starts below the base (0.5),
    as it does under heavy noise, reliability collapses to 0 and descriptors stop
    learning (docs/training.md).  The unweighted term keeps them learning; 0 is the paper.

    ``rel_logit_weight`` adds ``rel_logit_weight * logit_margin_loss(z, rel_logit_margin)``
    on the reliability logits ``z`` of both bursts (:func:`lburst.train.losses.logit_margin_loss`):
    it keeps a collapsed reliability from saturating, so it can recover once AP passes the
    base.  0 (the paper) leaves the logits free.

    ``rel_base`` is R2D2's base AP (kappa): the reliability loss pushes a pixel's
    reliability up where its AP passes it and down where it does not.  Under heavy noise
    fewer pixels reach 0.5, so fewer pass the 0.7 keypoint threshold at test time; a lower
    base keeps pixels whose descriptors still match under that noise.

    ``ap_border`` (pixels): the reliability loss takes no query pixel this close to the
    border of burst A (R2D2's 16).  Reliability there is then never trained, so keypoints
    avoid the image borders, where they would pin down the camera's distortion
    (docs/results/border.md).  0 trains every pixel whose target lies inside burst B.

    ``snapshot_every`` (steps) also keeps the weights at every multiple of it as
    ``snapshots/step_XXXXXX.pt`` in the published layout (a few MB each), so the
    benchmark can follow a run's progress.

    ``ema_decay`` above 0 also keeps an exponential moving average of the weights
    (:class:`torch.optim.swa_utils.AveragedModel`, buffers included), updated after every
    step: ``w_ema <- ema_decay * w_ema + (1 - ema_decay) * w``, over about
    ``1 / (1 - ema_decay)`` steps, to keep what neighbouring steps agree on.  Each snapshot
    then also writes ``step_XXXXXX.ema.pt``, ``final.pt``
    holds the average, and ``last.pt`` keeps it for a resume.  0 (the default) keeps none.

    ``distill_weight`` adds ``distill_weight * distillation_loss``: the network on burst A
    without noise, in eval mode and without gradient, is the teacher of the network on
    the noisy burst A at every pixel (descriptors and both maps), so every step teaches
    noise invariance directly (:func:`lburst.train.losses.distillation_loss`).

    ``spread_weight`` adds ``spread_weight * spread_loss``: the squared norm of the batch's
    mean descriptor over the pixels the detector would keep (3x3 maxima of the
    repeatability with both maps above 0.7), so that keypoint descriptors keep no common component
    (:func:`lburst.train.losses.spread_loss`).

    ``arch`` is the network trained: ``'lburst'`` (the Fast-Quad-L2-Net of lburst-b5),
    ``'lite'`` (:class:`lburst.model.lite.LiteNet`, the light network) or a light network of
    other widths, named by its net string without ``inchan`` (for example
    ``'LBurstLite(fine=48,coarse=128,dilations=1-2-4-8-1-2)'``, :class:`LiteConfig`).

    ``teacher`` (a checkpoint of this project's own, or a shipped name such as
    ``'lburst-b5'``) makes the distillation target another network: the teacher, frozen,
    in eval mode, on the same noisy bursts A and B as the student, at every pixel
    (descriptors and both maps), instead of the network itself on the noise-free burst.
    This is how the light network learns from lburst-b5.  With ``teacher_sees='clean'``
    the frozen teacher reads the noise-free burst A instead: a fine-tune then pulls its
    noisy-burst output towards the starting network's clean-burst output, a target that,
    unlike self-distillation's, cannot drift (flatten) together with the student.

    ``init`` starts the weights from a checkpoint of this project's own (for example the
    shipped ``lburst-b5``) instead of at random; the optimizer starts fresh.  A
    single-image checkpoint starts a burst run through :func:`lburst.model.replicate_frames`
    (the burst network that equals the single-image one on the burst's mean).

    ``tensorboard`` also writes the losses for TensorBoard to ``tensorboard/`` in the run.

    ``precision`` ``'bf16'`` (or ``'fp16'`` on a GPU) runs the network's forward pass under
    autocast; the losses are computed in fp32 from its outputs (its speed and its loss curve
    against fp32's: docs/training.md)."""

    frames: int = 5
    batch_size: int = 4
    steps: int = 20000
    epochs: float | None = None
    time_budget_s: float | None = None
    lr: float = 1e-4
    weight_decay: float = 5e-4
    patch: int = 16
    ap_weight: float = 0.0
    rel_logit_weight: float = 0.0
    rel_logit_margin: float = 4.0
    rel_base: float = 0.5
    ap_border: int = 16
    distill_weight: float = 0.0
    spread_weight: float = 0.0
    ema_decay: float = 0.0
    arch: str = "lburst"
    teacher: str | None = None
    teacher_sees: str = "noisy"
    init: str | None = None
    seed: int = 0
    workers: int = 1
    threads: int | None = None
    checkpoint_every_s: float = 300.0
    snapshot_every: int | None = None
    tensorboard: bool = False
    precision: str = "fp32"
    pair: PairConfig = field(default_factory=PairConfig)


#: ``paper``: the paper's recipe (for a GPU).  ``cpu``: this project's CPU recipe: wider
#: noise range (std 5-110 on 0..255, the benchmark goes to 100) and darker exposures.
PRESETS: dict[str, dict] = {
    "paper": dict(batch_size=8, epochs=25.0, workers=8),
    # lburst's recipes (ap_weight, rel_logit_weight: see TrainConfig)
    "cpu": dict(
        batch_size=4,
        steps=20000,
        workers=1,
        ap_weight=0.25,
        rel_logit_weight=0.01,
        pair=PairConfig(noise_variance=None, noise_std=(5.0, 110.0), dark_prob=0.3, gamma_range=(0.8, 1.25)),
    ),
}
#: ``gpu``: the ``cpu`` recipe with a larger batch and more loader workers.
PRESETS["gpu"] = dict(PRESETS["cpu"], batch_size=8, steps=100000, workers=7, checkpoint_every_s=60.0)
#: ``burst``: the burst-against-noise recipe, for fine-tuning (``--init``): heavy noise
#: (Gaussian std 25-120 on 0..255, or physical low light at 3-60 photons for a third of
#: the bursts), small in-burst motion (up to 3 px of translation, 1 degree of rotation,
#: 1% zoom and 1 px of smooth non-uniform flow per frame), and dense self-distillation
#: from the noise-free burst.
PRESETS["burst"] = dict(
    PRESETS["cpu"],
    distill_weight=1.0,
    pair=PairConfig(
        noise_variance=None,
        noise_std=(25.0, 120.0),
        dark_prob=0.3,
        gamma_range=(0.8, 1.25),
        max_burst_motion=12.0,
        burst_rotation_deg=1.0,
        burst_zoom=0.01,
        burst_flow_px=1.0,
        lowlight_prob=0.33,
        lowlight_photons=(3.0, 60.0),
    ),
)
#: ``aligned``: the ``burst`` recipe for a network that reads bursts aligned by
#: ``align+lburst``: every training frame is warped back by its shift plus a 0.25 px
#: error, so what is left is the rotation, zoom and flow; start it from the shipped
#: single-image weights (``--init lburst/weights/lburst-b1.pt``), which it then equals on
#: the burst's mean.
PRESETS["aligned"] = dict(PRESETS["burst"], pair=replace(PRESETS["burst"]["pair"], align_error_px=0.25))
#: ``lite``: the light network (:mod:`lburst.model.lite`) from scratch, on the bursts of
#: lburst-b5's recipe (``aligned``), with lburst-b5 as its dense teacher on the same noisy
#: bursts beside R2D2's repeatability losses (:mod:`lburst.train.distill`; no AP or spread
#: term: the descriptors and the reliability come from the teacher), and a higher learning
#: rate for a network from scratch.
PRESETS["lite"] = dict(
    PRESETS["aligned"],
    arch="lite",
    teacher="lburst-b5",
    distill_weight=1.0,
    ap_weight=0.0,
    rel_logit_weight=0.0,
    spread_weight=0.0,
    lr=5e-4,
)
ARCHS = ("lburst", "lite")
#: what ``TrainConfig.teacher`` reads: the student's noisy bursts, or the noise-free burst A
TEACHER_INPUTS = ("noisy", "clean")


def is_lite(arch: str) -> bool:
    """Whether ``arch`` names the light network (``'lite'`` or an ``LBurstLite(...)`` string)."""
    return arch == "lite" or arch.startswith(LITE_NAME)


def build_network(arch: str, frames: int) -> torch.nn.Module:
    """An untrained network of the architecture ``arch`` (see :class:`TrainConfig`)."""
    if arch == "lburst":
        return LBurstNet(NetConfig(frames=frames))
    if arch == "lite":
        return LiteNet(LiteConfig(frames=frames))
    if arch.startswith(LITE_NAME):
        lite = replace(LiteConfig.from_net_string(arch), frames=frames)
        return checked_network(lambda: LiteNet(lite), lite.in_channels, f"--arch {arch!r}", LITE_SMALLER)
    raise LBurstValueError(f"unknown architecture {arch!r}: use {', '.join(ARCHS)} or an {LITE_NAME}(...) string")


def device_memory_limit(device: torch.device) -> int | None:
    """The memory a step may use on ``device``: 90 % of a GPU's, half of the machine's on a CPU."""
    if device.type == "cuda":
        return int(torch.cuda.get_device_properties(device).total_memory * 0.9)
    return None


def load_teacher(spec: str, frames: int, device: torch.device) -> torch.nn.Module:
    """The frozen teacher network named by ``spec`` (a checkpoint file or a shipped name)."""
    teacher, _ = load_checkpoint(resolve_weights(spec), device)
    if teacher.config.frames != frames:
        raise LBurstValueError(
            f"teacher {spec}: a {teacher.config.frames}-frame network, but the run has {frames} frames"
        )
    for p in teacher.parameters():
        p.requires_grad_(False)
    return teacher.eval()


def _normalise(burst: torch.Tensor) -> torch.Tensor:
    """(B, N, 3, H, W) on 0..255 -> (B, 3N, H, W) ImageNet-normalised, frames in order."""
    mean = torch.tensor(IMAGENET_MEAN, device=burst.device).view(1, 1, 3, 1, 1) * 255
    std = torch.tensor(IMAGENET_STD, device=burst.device).view(1, 1, 3, 1, 1) * 255
    x = (burst - mean) / std
    return x.flatten(1, 2)


def training_step(
    net: torch.nn.Module,
    batch: dict[str, torch.Tensor],
    patch: int,
    generator: torch.Generator | None = None,
    ap_weight: float = 0.0,
    precision: str = "fp32",
    rel_logit_weight: float = 0.0,
    rel_logit_margin: float = 4.0,
    rel_base: float = 0.5,
    distill_weight: float = 0.0,
    teacher: torch.nn.Module | None = None,
    memory_format: torch.memory_format = torch.channels_last,
    spread_weight: float = 0.0,
    teacher_on_noisy: bool = False,
    ap_border: int = 16,
) -> dict[str, torch.Tensor]:
    """Losses of one batch (both bursts through the net in one pass; see ``TrainConfig.precision``).

    With ``distill_weight`` > 0 the batch holds ``clean_a`` and ``teacher`` (the network
    itself, unwrapped) runs on it in eval mode without gradient; with ``teacher_on_noisy``
    ``teacher`` is another, frozen network run on the same noisy bursts A and B as the
    student (``TrainConfig.teacher``)."""
    dtype = autocast_dtype(precision)
    n = batch["burst_a"].shape[0]
    x = torch.cat([_normalise(batch["burst_a"]), _normalise(batch["burst_b"])])
    x = x.contiguous(memory_format=memory_format)
    with torch.autocast(device_type=x.device.type, dtype=dtype, enabled=dtype is not None):
        out = net(x, reliability_logits=rel_logit_weight > 0)
    desc, rep, rel = (out[k].float() for k in ("descriptors", "repeatability", "reliability"))
    flow, mask = batch["flow"], batch["mask"]
    cosim = cosim_loss(rep[:n], rep[n:], flow, mask, patch)
    peaky = (peaky_loss(rep[:n], patch) + peaky_loss(rep[n:], patch)) / 2
    reliability, ap = reliability_ap_loss(
        desc[:n], desc[n:], rel[:n], flow, mask, generator, APSampling(base=rel_base, border=ap_border)
    )
    loss = cosim + peaky + reliability + ap_weight * (1 - ap)
    if rel_logit_weight > 0:
        loss = loss + rel_logit_weight * logit_margin_loss(out["reliability_logits"].float(), rel_logit_margin)
    losses = {"cosim": cosim, "peaky": peaky, "reliability": reliability, "ap": ap}
    if spread_weight > 0:
        with torch.no_grad():  # the keypoints of the test-time detector (3x3 maxima, both thresholds 0.7)
            peaks = (rep == F.max_pool2d(rep, 3, 1, 1)) & (rep > 0.7) & (rel > 0.7)
        losses["spread"] = spread_loss(desc, peaks.float())
        loss = loss + spread_weight * losses["spread"]
    if distill_weight > 0 and teacher_on_noisy:
        if teacher is None:
            raise LBurstValueError("teacher_on_noisy needs a teacher")
        with torch.no_grad(), torch.autocast(device_type=x.device.type, dtype=dtype, enabled=dtype is not None):
            target = teacher(x)
        student = {k: out[k].float() for k in ("descriptors", "repeatability", "reliability")}
        losses["distill"] = distillation_loss(student, {k: target[k].float() for k in student})
        loss = loss + distill_weight * losses["distill"]
    elif distill_weight > 0:
        if teacher is None or "clean_a" not in batch:
            raise LBurstValueError("distill_weight > 0 needs a teacher and the batch's clean_a")
        clean = _normalise(batch["clean_a"]).contiguous(memory_format=memory_format)
        was_training = teacher.training
        teacher.eval()
        with torch.no_grad(), torch.autocast(device_type=x.device.type, dtype=dtype, enabled=dtype is not None):
            target = teacher(clean)
        teacher.train(was_training)
        student = {k: out[k][:n].float() for k in ("descriptors", "repeatability", "reliability")}
        losses["distill"] = distillation_loss(student, {k: v.float() for k, v in target.items()})
        loss = loss + distill_weight * losses["distill"]
    return {"loss": loss, **losses}


def finite_gradients(net: torch.nn.Module) -> bool:
    """Whether every gradient of ``net`` is finite (a NaN or inf loss leaves non-finite ones)."""
    grads = [p.grad for p in net.parameters() if p.grad is not None]
    return bool(grads) and bool(torch.stack([torch.isfinite(g).all() for g in grads]).all())


def _read_log(path: Path, upto: int) -> list[dict]:
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return [row for row in csv.DictReader(f) if int(row["step"]) <= upto]


def _write_log(path: Path, rows: list[dict]) -> None:
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, LOG_FIELDS)
        writer.writeheader()
        writer.writerows(rows)


def _config_dict(cfg: TrainConfig) -> dict:
    return json.loads(json.dumps(asdict(cfg)))


def _config_from_dict(d: dict) -> TrainConfig:
    pair = PairConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.pop("pair").items()})
    return TrainConfig(**d, pair=pair)


def _to_cpu(obj):
    """Tensors of a nested state dict moved to the CPU (so a GPU run resumes anywhere)."""
    if isinstance(obj, torch.Tensor):
        return obj.cpu()
    if isinstance(obj, dict):
        return {k: _to_cpu(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_to_cpu(v) for v in obj)
    return obj


def weight_average(net: torch.nn.Module, decay: float) -> AveragedModel | None:
    """The exponential moving average of ``net``'s weights and buffers (``decay`` in [0, 1);
    0: none).  Its first update copies ``net``."""
    if not 0.0 <= decay < 1.0:
        raise LBurstValueError(f"ema_decay {decay}: use a value in [0, 1) (0: no average)")
    if decay == 0.0:
        return None
    return AveragedModel(net, multi_avg_fn=get_ema_multi_avg_fn(decay), use_buffers=True)


def save_state(path: Path, net, optimizer, step: int, cfg: TrainConfig, seconds: float, generator, ema=None) -> None:
    state = {
        **checkpoint_dict(net),
        "optimizer": _to_cpu(optimizer.state_dict()),
        "step": step,
        "seconds": seconds,
        "config": _config_dict(cfg),
        "torch_rng": torch.get_rng_state(),
        "generator": generator.get_state(),
    }
    if ema is not None:
        state["ema"] = _to_cpu(ema.state_dict())
    write_checkpoint(state, path)


@dataclass
class _Run:
    """What a run trains with: the network, its teacher (itself without ``cfg.teacher``), the
    optimizer, the weight average, the memory layout, and how the teacher is used."""

    net: torch.nn.Module
    teacher: torch.nn.Module
    optimizer: torch.optim.Optimizer
    ema: AveragedModel | None
    layout: torch.memory_format
    teacher_on_noisy: bool
    lite_distillation: bool


@keeps_state
def train(
    photo_folders: list[str | Path],
    out: str | Path,
    cfg: TrainConfig,
    resume: bool = False,
    device: str | None = None,
    progress: bool = True,
    precision: str | None = None,
    memory_format: str = "auto",
) -> Path:
    """Train (or resume) a run in folder ``out``; returns the path of ``last.pt``.
    ``precision`` (if given) replaces the run's own, also on resume: native bf16 is a
    property of the machine the run continues on, not of the recipe; so is
    ``memory_format`` (:func:`lburst.model.training_memory_format`).

    Started by ``torchrun`` with several processes, it trains data-parallel
    (:mod:`lburst.train.distributed`): each rank draws its own share of the stream and
    rank 0 writes the files.  It sets torch's thread count (``cfg.threads``) and seeds its
    global random state for the run only: its caller finds both as they were."""
    out = Path(out)
    ctx = distributed.setup(None if device is None else str(check_device(device)))
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    last = out / "last.pt"
    generator = torch.Generator().manual_seed(cfg.seed + ctx.rank)
    cfg, state = _run_config(cfg, last, resume, precision, ctx.device)
    photos = list_photos([Path(p) for p in photo_folders])
    total = cfg.steps if cfg.epochs is None else int(cfg.epochs * len(photos) / (cfg.batch_size * ctx.world))
    if total < 1:
        raise LBurstValueError(f"a run needs at least 1 step, got {total} (--steps, or --epochs x photos / batch)")
    run = _build_run(cfg, state is None, ctx.device, memory_format)
    step, seconds = _restore(run, state, last, cfg, generator, ctx.main) if state is not None else (0, 0.0)
    writer = _tensorboard_writer(out) if cfg.tensorboard and ctx.main else None
    if ctx.main:
        out.mkdir(parents=True, exist_ok=True)
        with atomic_path(out / "config.json") as tmp:
            tmp.write_text(json.dumps(_config_dict(cfg), indent=2))
    model = ctx.wrap(run.net.train())
    step = _train_steps(run, model, cfg, out, ctx, photos, (step, total, seconds), generator, progress, writer)
    if ctx.main and step >= total:
        final = run.net if run.ema is None else run.ema.module
        save_checkpoint(final, out / "final.pt", meta={"step": step, "config": _config_dict(cfg), **_input_meta(cfg)})
    ctx.close()
    return last


def _run_config(
    cfg: TrainConfig, last: Path, resume: bool, precision: str | None, device: torch.device
) -> tuple[TrainConfig, dict | None]:
    """The run's configuration (on ``resume``: the saved one with :data:`RESUME_OVERRIDES` from
    ``cfg``), checked, and its saved state (``None`` for a new run)."""
    state = None
    if resume and not last.is_file():
        raise CheckpointError(f"{last}: no run to resume (no such file); leave out --resume to start one")
    if resume:
        state = load_state(last)
        saved = _config_from_dict(dict(state["config"]))
        cfg = replace(
            saved,
            time_budget_s=cfg.time_budget_s,
            steps=cfg.steps,
            epochs=cfg.epochs,
            workers=cfg.workers,
            threads=cfg.threads,
            checkpoint_every_s=cfg.checkpoint_every_s,
            snapshot_every=cfg.snapshot_every or saved.snapshot_every,
            tensorboard=cfg.tensorboard,
        )
    elif last.is_file():
        raise LBurstFileExistsError(f"{last} exists: pass --resume to continue it, or choose another --out")
    if precision is not None:  # a property of the machine, not of the recipe: a resumed run may change it
        cfg = replace(cfg, precision=precision)
    check_precision(cfg.precision, device)
    if cfg.teacher_sees not in TEACHER_INPUTS:
        raise LBurstValueError(f"teacher_sees {cfg.teacher_sees!r}: use one of {', '.join(TEACHER_INPUTS)}")
    if cfg.teacher_sees == "clean" and not (cfg.teacher and cfg.distill_weight > 0):
        raise LBurstValueError("--teacher-sees clean needs a --teacher and a --distill-weight above 0")
    return cfg, state


def _initial_network(cfg: TrainConfig, from_init: bool) -> torch.nn.Module:
    """The network of ``cfg.arch``, seeded by ``cfg.seed``, with the weights of ``cfg.init`` when
    ``from_init`` (a new run)."""
    torch.manual_seed(cfg.seed)
    net = build_network(cfg.arch, cfg.frames)
    if cfg.init and from_init:
        init_net, _ = load_checkpoint(cfg.init)
        if type(init_net) is not type(net):
            raise LBurstValueError(f"{cfg.init}: not a network of the run's architecture {cfg.arch!r}")
        if init_net.config.frames == 1 and cfg.frames > 1:
            init_net = replicate_frames(init_net, cfg.frames)
        if init_net.config.frames != cfg.frames:
            raise LBurstValueError(
                f"{cfg.init}: a {init_net.config.frames}-frame network, but the run has {cfg.frames} frames"
            )
        net.load_state_dict(init_net.state_dict())
    return net


def _build_run(cfg: TrainConfig, new: bool, device: torch.device, memory_format: str) -> _Run:
    """The network (its step's memory checked first), teacher, optimizer and weight average of a run."""
    net = _initial_network(cfg, new)
    check_step_memory(net, 3 * cfg.frames, cfg.batch_size, cfg.pair.crop, device_memory_limit(device))
    layout = training_memory_format(device, memory_format)
    net = net.to(device).to(memory_format=layout)
    teacher = load_teacher(cfg.teacher, cfg.frames, device).to(memory_format=layout) if cfg.teacher else net
    teacher_on_noisy = cfg.teacher is not None and cfg.teacher_sees == "noisy"
    lite_distillation = is_lite(cfg.arch) and teacher_on_noisy
    if lite_distillation:
        teacher = teacher_form(teacher, cfg.precision).to(device)
    optimizer = torch.optim.Adam(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    ema = weight_average(net, cfg.ema_decay)
    return _Run(net, teacher, optimizer, ema, layout, teacher_on_noisy, lite_distillation)


def _restore(run: _Run, state: dict, last: Path, cfg: TrainConfig, generator, main: bool) -> tuple[int, float]:
    """The saved weights, optimizer, weight average and random states into ``run``; returns the
    saved step and seconds."""
    run.net.load_state_dict(state["state_dict"])
    run.optimizer.load_state_dict(state["optimizer"])
    if run.ema is not None:
        if "ema" not in state:
            raise CheckpointError(f"{last}: the run keeps no weight average (ema_decay {cfg.ema_decay})")
        run.ema.load_state_dict(state["ema"])
    torch.set_rng_state(state["torch_rng"])
    if main:  # the saved sampling state is rank 0's; the others start anew from their seed
        generator.set_state(state["generator"])
    return int(state["step"]), float(state["seconds"])


def _loader(photos: list[Path], cfg: TrainConfig, run: _Run, step: int, ctx, device: torch.device) -> DataLoader:
    """The stream of training pairs from ``step`` on (each rank its share)."""
    return DataLoader(
        PairDataset(photos, cfg.pair, cfg.seed, clean=cfg.distill_weight > 0 and not run.teacher_on_noisy),
        batch_size=cfg.batch_size,
        sampler=StreamSampler(step * cfg.batch_size * ctx.world + ctx.rank, ctx.world),
        num_workers=cfg.workers,
        persistent_workers=cfg.workers > 0,
        prefetch_factor=4 if cfg.workers > 0 else None,
        pin_memory=device.type == "cuda",
        worker_init_fn=init_worker,
    )


def _losses(run: _Run, model, batch: dict[str, torch.Tensor], cfg: TrainConfig, generator) -> dict[str, torch.Tensor]:
    """The losses of one batch: the light network's distillation step, or :func:`training_step`."""
    if run.lite_distillation:
        x = torch.cat([_normalise(batch["burst_a"]), _normalise(batch["burst_b"])])
        return lite_distillation_step(
            model,
            run.teacher,
            batch,
            x.contiguous(memory_format=run.layout),
            cfg.patch,
            cfg.distill_weight,
            cfg.precision,
            ap_weight=cfg.ap_weight,
            generator=generator,
        )
    return training_step(
        model,
        batch,
        cfg.patch,
        generator,
        ap_weight=cfg.ap_weight,
        precision=cfg.precision,
        rel_logit_weight=cfg.rel_logit_weight,
        rel_logit_margin=cfg.rel_logit_margin,
        rel_base=cfg.rel_base,
        distill_weight=cfg.distill_weight,
        teacher=run.teacher,
        memory_format=run.layout,
        spread_weight=cfg.spread_weight,
        teacher_on_noisy=run.teacher_on_noisy,
        ap_border=cfg.ap_border,
    )


def _update(run: _Run, losses: dict[str, torch.Tensor]) -> bool:
    """One optimizer step (and weight-average update) from ``losses``; ``False``, with no update,
    when a gradient is not finite (one bad batch must not leave NaN weights behind)."""
    run.optimizer.zero_grad(set_to_none=True)
    losses["loss"].backward()
    if not finite_gradients(run.net):
        return False
    run.optimizer.step()
    if run.ema is not None:
        run.ema.update_parameters(run.net)
    return True


def _snapshot(run: _Run, out: Path, step: int, cfg: TrainConfig) -> None:
    """``snapshots/step_XXXXXX.pt`` (and ``.ema.pt`` of the weight average) in the published layout."""
    meta = {"step": step, **_input_meta(cfg)}
    save_checkpoint(run.net, out / "snapshots" / f"step_{step:06d}.pt", meta=meta)
    if run.ema is not None:
        average = {**meta, "ema_decay": cfg.ema_decay}
        save_checkpoint(run.ema.module, out / "snapshots" / f"step_{step:06d}.ema.pt", meta=average)


def _train_steps(
    run: _Run,
    model,
    cfg: TrainConfig,
    out: Path,
    ctx,
    photos,
    span: tuple[int, int, float],
    generator,
    progress: bool,
    writer,
) -> int:
    """The steps from ``span``'s first to its total (``seconds`` already spent), each logged
    (and to TensorBoard's ``writer``), checkpointed every ``cfg.checkpoint_every_s`` and at the
    end (also on Ctrl-C or SIGTERM, then raised); returns the last step done."""
    step, total, seconds = span
    last = out / "last.pt"
    log = _read_log(out / "log.csv", step)
    data = iter(_loader(photos, cfg, run, step, ctx, ctx.device))
    started = time.monotonic()
    last_save = started

    def checkpoint() -> None:  # rank 0: the log, then the resumable state, atomically
        _write_log(out / "log.csv", log)  # first: a resume reads the log only up to the state's step
        elapsed = seconds + time.monotonic() - started
        save_state(last, run.net, run.optimizer, step, cfg, elapsed, generator, run.ema)

    bar = tqdm(
        total=total, initial=step, desc=f"train b{cfg.frames}", disable=not (progress and ctx.main), dynamic_ncols=True
    )
    skipped = 0
    previous = _stop_on_sigterm()
    try:
        while step < total:
            if ctx.any(cfg.time_budget_s is not None and time.monotonic() - started > cfg.time_budget_s):
                break
            batch = {k: v.to(ctx.device, non_blocking=True) for k, v in next(data).items()}
            losses = _losses(run, model, batch, cfg, generator)
            if not _update(run, losses):  # skipped: say so in the log
                skipped += 1
                bar.write(f"step {step + 1}: non-finite loss or gradient, update skipped ({skipped} so far)")
            values = ctx.mean(losses)
            step += 1
            if not ctx.main:
                continue
            log.append(
                {
                    "step": step,
                    "seconds": round(seconds + time.monotonic() - started, 2),
                    **{k: round(values[k], 5) for k in losses},
                }
            )
            bar.update(1)
            bar.set_postfix({k: f"{values[k]:.3f}" for k in losses})
            if writer is not None:
                for k in losses:
                    writer.add_scalar(f"train/{k}", values[k], step)
            if cfg.snapshot_every and step % cfg.snapshot_every == 0:
                _snapshot(run, out, step, cfg)
            if time.monotonic() - last_save > cfg.checkpoint_every_s:
                checkpoint()
                last_save = time.monotonic()
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: keep every finished step; a --resume continues from here
        if ctx.main:
            checkpoint()
        raise
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    bar.close()
    if ctx.main:
        checkpoint()
    if writer is not None:
        writer.close()
    return step


def _input_meta(cfg: TrainConfig) -> dict:
    """``{'input': 'aligned'}`` for weights trained on aligned bursts (:class:`lburst.LBurst`
    then aligns a burst before the network), else nothing."""
    return {"input": "aligned"} if cfg.pair.align_error_px is not None else {}


def _stop_on_sigterm():
    """Make SIGTERM stop training like Ctrl-C (a run in the background ignores SIGINT);
    returns the previous handler, or None off the main thread."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def stop(signum, frame):
        raise KeyboardInterrupt

    return signal.signal(signal.SIGTERM, stop)


def _tensorboard_writer(out: Path):
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError as exc:
        raise MissingExtra("--tensorboard needs tensorboard: pip install 'lburst[tensorboard]'") from exc
    return SummaryWriter(str(out / "tensorboard"))


def load_state(path: Path) -> dict:
    """The resumable state in ``last.pt``; ``CheckpointError`` naming the file if it is unreadable."""
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated, empty, not a torch file
        raise CheckpointError(
            f"{path}: not a readable training state ({type(exc).__name__}: {exc}); "
            f"restore it or start a new run in another --out"
        ) from exc
    missing = [
        k for k in ("state_dict", "optimizer", "step", "config") if not isinstance(state, dict) or k not in state
    ]
    if missing:
        raise CheckpointError(f"{path}: not a training state (lacks {', '.join(missing)})")
    return state


#: Settings that a resumed run takes from the command line; the others stay the run's own.
RESUME_OVERRIDES = (
    "steps",
    "epochs",
    "time_budget_s",
    "workers",
    "threads",
    "checkpoint_every_s",
    "snapshot_every",
    "tensorboard",
    "precision",
)


def saved_run_length(out: str | Path) -> dict:
    """``steps`` and ``epochs`` of the run in ``out`` (its ``config.json``), so that ``--resume``
    without ``--steps`` runs to the run's own end, not to a preset's; ``{}`` without a record."""
    try:
        saved = json.loads((Path(out) / "config.json").read_text())
        return {"steps": int(saved["steps"]), "epochs": saved.get("epochs")}
    except (OSError, ValueError, KeyError, TypeError):
        return {}


def check_resume_options(out: str | Path, given: dict) -> None:
    """``ValueError`` for an option given with ``--resume`` that the resumed run would ignore
    (its value differs from the one in the run's ``config.json``)."""
    try:
        saved = json.loads((Path(out) / "config.json").read_text())
    except (OSError, ValueError):
        return  # no record to compare with; the run's last.pt is checked when it is loaded
    ignored = [
        f"--{name.removesuffix('_s').replace('_', '-')} {value} (the run has {saved[name]})"
        for name, value in given.items()
        if value is not None and name not in RESUME_OVERRIDES and name in saved and saved[name] != value
    ]
    if ignored:
        raise LBurstValueError(f"{out}: a resumed run keeps its own settings; leave out {', '.join(ignored)}")
