"""The LBurst network and its checkpoints.

The network is R2D2's Fast-Quad-L2-Net with the "ConfCFS" heads, taking a burst of
``N`` RGB frames concatenated on channels (``3N`` input channels; ``N = 1`` is the
single-image R2D2 network).  For an input of ``H x W`` pixels it predicts, at the
same resolution:

- ``descriptors`` ``(B, 128, H, W)``: L2-normalised dense descriptors;
- ``repeatability`` ``(B, 1, H, W)``: ``softplus(s) / (1 + softplus(s))`` with
  ``s`` a 1x1 conv of the squared raw output;
- ``reliability`` ``(B, 1, H, W)``: channel 1 of a 2-class softmax of a 1x1 conv of
  the squared raw output.

The module list reproduces the published state-dict layout (``ops.{i}.*`` by
position), so the published LBurst (``RoBLo_N16_B*.pt``) and R2D2 checkpoints load
strictly, and our own checkpoints are written in the same layout.

Odd input sizes: the 2x2 max-pool and the x2 upsampling return a map one pixel
smaller than the input along an odd dimension.  The published code keeps that
smaller map; here the missing last row/column is filled explicitly (replicated
descriptors, zero repeatability and reliability) so every output has the input's
size and the last row/column can never hold a keypoint, as in the published code.
"""

from __future__ import annotations

import pickle
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from lburst.burst.io import atomic_path
from lburst.errors import LBurstValueError
from lburst.memory import check_memory, gib
from lburst.model.lite import LITE_NAME, LiteConfig, LiteNet
from lburst.model.precision import (  # noqa: F401  (re-exported)
    AUTOCAST_DTYPES,
    NATIVE_BF16_FLAGS,
    autocast_dtype,
    check_precision,
    cpu_flags,
)
from lburst.normalization import IMAGENET_MEAN, IMAGENET_STD

#: Class name written into checkpoints, as in the published files.
NET_NAME = "Fast_Quad_L2Net_ConfCFS"


def training_memory_format(device: torch.device | str, name: str = "auto") -> torch.memory_format:
    """The memory format for training the network: ``channels_last``, ``contiguous``, or
    ``auto``: channels-last on CUDA and on CPUs with AVX-512, contiguous on CPUs without
    it, where it trains faster (docs/training.md, "Continuing on another CPU")."""
    formats = {"channels_last": torch.channels_last, "contiguous": torch.contiguous_format}
    if name == "auto":
        flags = cpu_flags()
        cpu_without_avx512 = torch.device(device).type == "cpu" and flags is not None and "avx512f" not in flags
        name = "contiguous" if cpu_without_avx512 else "channels_last"
    if name not in formats:
        raise LBurstValueError(f"memory format must be auto, channels_last or contiguous, got {name!r}")
    return formats[name]


def check_device(device: torch.device | str) -> torch.device:
    """``device`` as a torch device; ``ValueError`` in one line for a bad name or CUDA that is not there."""
    try:
        device = torch.device(device)
    except RuntimeError as exc:
        raise LBurstValueError(f"device {device!r}: not a torch device (use cpu or cuda)") from exc
    if device.type == "cuda" and not torch.cuda.is_available():
        why = "this torch is built without CUDA" if torch.version.cuda is None else "no CUDA GPU is visible"
        raise LBurstValueError(f"device {device}: CUDA is not available ({why}); use --device cpu")
    return device


class CheckpointError(LBurstValueError):
    """A checkpoint file that cannot be read or does not describe an LBurst network."""


@dataclass(frozen=True)
class NetConfig:
    """Architecture of a Fast-Quad-L2-Net.

    Attributes:
        frames: number of burst frames N (input channels = 3N).
        dim: descriptor dimension.
        mchan: channel multiplier (4 gives 32, 32, 64, 64, 128, 128 channels).
    """

    frames: int = 5
    dim: int = 128
    mchan: int = 4

    @property
    def in_channels(self) -> int:
        return 3 * self.frames

    def net_string(self) -> str:
        """The checkpoint's ``net`` string, in the published files' spelling."""
        if self.frames == 1:
            return f"{NET_NAME}()"
        return f"{NET_NAME}(inchan={self.in_channels})"


class LBurstNet(nn.Module):
    """Fast-Quad-L2-Net with reliability (``clf``) and repeatability (``sal``) heads."""

    def __init__(self, config: NetConfig = NetConfig()) -> None:
        super().__init__()
        if config.frames < 1 or config.frames % 2 == 0:
            raise LBurstValueError(f"frames must be odd and positive, got {config.frames}")
        self.config = config
        m = config.mchan
        ops: list[nn.Module] = []
        channels = config.in_channels

        def conv(out: int, k: int = 3, dilation: int = 1, bn: bool = True, relu: bool = True) -> None:
            nonlocal channels
            ops.append(nn.Conv2d(channels, out, k, padding=((k - 1) * dilation) // 2, dilation=dilation))
            if bn:
                ops.append(nn.BatchNorm2d(out, affine=False))
            if relu:
                ops.append(nn.ReLU(inplace=True))
            channels = out

        conv(8 * m)
        conv(8 * m)
        conv(16 * m)
        ops.append(nn.MaxPool2d(2))
        conv(16 * m)
        conv(32 * m)  # stride 2 of the original net, turned into dilation of what follows
        conv(32 * m, dilation=2)
        # the 8x8 conv of L2-Net replaced by three dilated 2x2 convs
        conv(32 * m, k=2, dilation=2, relu=False)
        conv(32 * m, k=2, dilation=4, relu=False)
        conv(config.dim, k=2, dilation=8, bn=False, relu=False)
        self.ops = nn.ModuleList(ops)
        self.clf = nn.Conv2d(config.dim, 2, kernel_size=1)
        self.sal = nn.Conv2d(config.dim, 1, kernel_size=1)

    def forward(self, x: torch.Tensor, reliability_logits: bool = False) -> dict[str, torch.Tensor]:
        """Run the net on normalised bursts ``x`` of shape ``(B, 3N, H, W)``.

        ``reliability_logits`` also returns the reliability's logit (class 1 minus class 0,
        ``(B, 1, H, W)``), for training (see ``TrainConfig.rel_logit_weight``)."""
        if x.ndim != 4 or x.shape[1] != self.config.in_channels:
            raise LBurstValueError(
                f"expected input (B, {self.config.in_channels}, H, W) for a {self.config.frames}-frame "
                f"network, got {tuple(x.shape)}"
            )
        height, width = x.shape[-2:]
        for op in self.ops:
            x = op(x)
        x = F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)
        squared = x * x
        logits = self.clf(squared)
        reliability = torch.softmax(logits, dim=1)[:, 1:2]
        s = F.softplus(self.sal(squared))
        repeatability = s / (1 + s)
        descriptors = F.normalize(x, p=2, dim=1)
        out = {"descriptors": descriptors, "repeatability": repeatability, "reliability": reliability}
        if reliability_logits:
            out["reliability_logits"] = logits[:, 1:2] - logits[:, 0:1]
        pad_w, pad_h = width - x.shape[-1], height - x.shape[-2]
        if pad_w or pad_h:  # odd input size: see the module docstring
            out = {
                k: F.pad(v, (0, pad_w, 0, pad_h), mode="replicate" if k == "descriptors" else "constant")
                for k, v in out.items()
            }
        return out


FLOAT_TOLERANCE = 1e-3  # float bursts may stray this far outside [0, 1] (rounding)


def check_float_burst(burst: np.ndarray) -> None:
    """``ValueError`` for a float burst with NaN or inf, or with values outside ``[0, 1]``
    (a 0..255 float burst would give no keypoints)."""
    finite = np.isfinite(burst)
    if not finite.all():
        raise LBurstValueError(f"the burst holds {burst.size - int(finite.sum())} NaN or infinite values")
    low, high = float(burst.min(initial=0.0)), float(burst.max(initial=0.0))
    if low < -FLOAT_TOLERANCE or high > 1 + FLOAT_TOLERANCE:
        hint = " (it looks like 0..255: divide by 255, or pass uint8)" if high > 2 else ""
        raise LBurstValueError(f"a float burst must be in [0, 1], this one spans [{low:g}, {high:g}]{hint}")


def normalize_burst(
    burst: np.ndarray,
    device: torch.device | str = "cpu",
    memory_format: torch.memory_format = torch.contiguous_format,
) -> torch.Tensor:
    """Turn a burst ``(N, H, W, 3)`` uint8/uint16/float array into the net's input.

    Each frame is scaled to ``[0, 1]`` (by 255 for uint8, 65535 for uint16, unchanged
    for float), normalised with the ImageNet mean and std, and the frames are
    concatenated on channels in the given order: output ``(1, 3N, H, W)`` float32 in
    ``memory_format`` (one pass: the frames are reordered as integers, then converted and
    scaled in place).
    """
    if burst.ndim != 4 or burst.shape[-1] != 3:
        raise LBurstValueError(f"expected a burst of shape (N, H, W, 3), got {burst.shape}")
    if burst.dtype == np.uint8:
        scale = 1 / 255.0
    elif burst.dtype == np.uint16:
        scale = 1 / 65535.0
    elif np.issubdtype(burst.dtype, np.floating):
        scale = 1.0
        check_float_burst(burst)
    else:
        raise LBurstValueError(f"unsupported burst dtype {burst.dtype}: use uint8, uint16 or float in [0, 1]")
    n, h, w, _ = burst.shape
    x = torch.from_numpy(np.ascontiguousarray(burst)).to(device)
    if memory_format == torch.channels_last:
        x = x.permute(1, 2, 0, 3).reshape(1, h, w, 3 * n).permute(0, 3, 1, 2)
    else:
        x = x.permute(0, 3, 1, 2).reshape(1, 3 * n, h, w)
    out = torch.empty((1, 3 * n, h, w), device=x.device, memory_format=memory_format)
    out.copy_(x)
    std = torch.tensor(IMAGENET_STD, device=x.device).repeat(n).view(1, 3 * n, 1, 1)
    mean = torch.tensor(IMAGENET_MEAN, device=x.device).repeat(n).view(1, 3 * n, 1, 1)
    return out.mul_(scale / std).sub_(mean / std)


_INCHAN = re.compile(r"inchan\s*=\s*(\d+)")


def config_from_net_string(net: str) -> NetConfig:
    """Parse a checkpoint's ``net`` string (never evaluated) into a :class:`NetConfig`."""
    if not isinstance(net, str) or not net.startswith(NET_NAME):
        raise CheckpointError(f"unsupported network {net!r}: expected {NET_NAME}(...)")
    match = _INCHAN.search(net)
    inchan = int(match.group(1)) if match else 3
    if inchan % 3:
        raise CheckpointError(f"input channels {inchan} in {net!r} are not a multiple of 3")
    return NetConfig(frames=inchan // 3)


#: ``meta`` entries of a checkpoint (and ONNX metadata) that hold its descriptor whitening
#: (:mod:`lburst.train.whitening`).
WHITENING_KEYS = ("descriptor_mean", "descriptor_whitening")

MAX_PAD = 256  # pixels of reflected border around a pyramid level (MultiScaleConfig.pad)


def check_pad(pad, what: str = "pad") -> int:
    """``pad`` as an int, or ``ValueError`` naming ``what`` unless it is an integer 0-:data:`MAX_PAD`."""
    if isinstance(pad, bool) or not isinstance(pad, (int, np.integer)) or not 0 <= pad <= MAX_PAD:
        raise LBurstValueError(f"{what} must be an integer 0-{MAX_PAD} (pixels), got {pad!r}")
    return int(pad)


def default_pad(meta: dict | None) -> int:
    """The reflected border (px) weights ask to be run with, ``meta['pad']``; 0 when they do
    not say (published weights, and lburst's shipped ones: docs/results/border.md, "A reflected
    border at extraction")."""
    return check_pad((meta or {}).get("pad", 0), "the weights' pad")


#: pixels of the largest pyramid level at extraction (``MultiScaleConfig.max_size`` 1024, 4:3): a
#: network holds the maps of one level beside its weights
LEVEL_PIXELS = 1024 * 768


def weight_bytes(build: Callable[[], nn.Module]) -> int:
    """Bytes of the weights (and buffers) of the network ``build()`` makes, from shapes alone: it
    is built on PyTorch's ``meta`` device, which allocates nothing (a light network of
    ``dim=2000000000`` asked for 768 GB)."""
    with torch.device("meta"):
        net = build()
    return sum(t.numel() * t.element_size() for t in (*net.parameters(), *net.buffers()))


def map_bytes_per_pixel(net: nn.Module, channels: int, side: int = 32) -> float:
    """Bytes per input pixel of ``net``'s largest layer output and that layer's input (float32),
    from one forward pass of a ``side x side`` zero input in eval mode (its state unchanged)."""
    largest = 0

    def count(_module, _inputs, output) -> None:
        nonlocal largest
        values = output.values() if isinstance(output, dict) else output
        values = [values] if torch.is_tensor(values) else values
        largest = max(largest, sum(v.numel() for v in values if torch.is_tensor(v)))

    leaves = [m for m in net.modules() if not any(True for _ in m.children())]
    hooks = [m.register_forward_hook(count) for m in leaves]
    training = net.training
    try:
        with torch.no_grad():
            net.eval()(torch.zeros(1, channels, side, side))
    finally:
        net.train(training)
        for hook in hooks:
            hook.remove()
    return 2 * 4 * largest / side**2


def checked_network(build: Callable[[], nn.Module], channels: int, what: str, lower: str) -> nn.Module:
    """``build()``, refused with ``ValueError`` naming ``what``, the figure and ``lower`` (what makes
    it smaller) when its weights (:func:`weight_bytes`, before it is built) or its weights with the
    maps of a :data:`LEVEL_PIXELS` pyramid level (:func:`map_bytes_per_pixel`) would need more than
    half of the machine's memory."""
    weights = weight_bytes(build)
    check_memory(weights, f"{what} (its weights alone)", lower)
    net = build()
    need = weights + map_bytes_per_pixel(net, channels) * LEVEL_PIXELS
    check_memory(need, f"{what} on a 1024x768 input (its weights {gib(weights)})", lower)
    return net


#: what makes a light network smaller (its net string's fields)
LITE_SMALLER = "a smaller network (lower dim, fine or coarse)"


def network_from_net_string(net: str) -> LBurstNet | LiteNet:
    """An untrained network of the architecture a checkpoint's ``net`` string names:
    the Fast-Quad-L2-Net (published layout) or the light network (:mod:`lburst.model.lite`),
    refused before it is built when it would not fit in memory (:func:`checked_network`)."""
    if isinstance(net, str) and net.startswith(LITE_NAME):
        try:
            lite = LiteConfig.from_net_string(net)
            return checked_network(lambda: LiteNet(lite), lite.in_channels, net, LITE_SMALLER)
        except ValueError as exc:
            raise CheckpointError(str(exc)) from exc
    config = config_from_net_string(net)
    try:
        return checked_network(lambda: LBurstNet(config), config.in_channels, net, "fewer burst frames (inchan)")
    except ValueError as exc:
        raise CheckpointError(str(exc)) from exc


def load_checkpoint(path: str | Path, device: torch.device | str = "cpu") -> tuple[LBurstNet | LiteNet, dict]:
    """Load a published or lburst checkpoint safely (``weights_only=True``): a Fast-Quad-L2-Net
    or a light network (:mod:`lburst.model.lite`), as its ``net`` string says.

    Returns the network in eval mode on ``device`` and the checkpoint's other
    entries (``net`` and, for our own files, ``meta``).
    Raises :class:`CheckpointError` naming the file on any problem.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: checkpoint file not found")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        if "weights only load failed" not in str(exc).lower():
            raise CheckpointError(f"{path}: not a readable checkpoint (UnpicklingError: {exc})") from exc
        # torch's message advises weights_only=False: lburst never does that
        raise CheckpointError(
            f"{path}: not a checkpoint lburst loads: it holds Python objects beyond tensors, and lburst loads "
            "checkpoints with weights_only=True only (it never runs code from a file)"
        ) from exc
    except Exception as exc:  # truncated zip, not a torch file...
        raise CheckpointError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") from exc
    if not isinstance(ckpt, dict) or "state_dict" not in ckpt or "net" not in ckpt:
        raise CheckpointError(f"{path}: expected a dict with 'net' and 'state_dict'")
    try:
        net = network_from_net_string(ckpt["net"])
    except CheckpointError as exc:
        raise CheckpointError(f"{path}: {exc}") from exc
    state = {k.removeprefix("module."): v for k, v in ckpt["state_dict"].items()}
    try:
        net.load_state_dict(state, strict=True)
    except RuntimeError as exc:
        raise CheckpointError(f"{path}: weights do not fit {ckpt['net']}: {exc}") from exc
    check_finite_weights(
        path, [k for k, v in net.state_dict().items() if v.is_floating_point() and not torch.isfinite(v).all()]
    )
    net.eval().to(device)
    extra = {k: v for k, v in ckpt.items() if k != "state_dict"}
    return net, extra


def check_finite_weights(path: str | Path, broken: list[str]) -> None:
    """:class:`CheckpointError` naming ``path`` when weight tensors (the names ``broken``) hold NaN
    or inf: such a network gives no keypoint at all, silently.  Every model lburst loads is checked
    (a checkpoint, an ONNX export, an OpenVINO model)."""
    if broken:
        raise CheckpointError(
            f"{path}: {len(broken)} weight tensors hold NaN or inf (a diverged run?), first {broken[0]!r}"
        )


def replicate_frames(net: LBurstNet, frames: int) -> LBurstNet:
    """A ``frames``-frame network made from a single-image ``net``: the first convolution's
    weights are copied to every frame and divided by ``frames``.  Since every frame is
    normalised alike, the result on a burst equals ``net`` on the burst's mean, exactly
    (up to float rounding): on an aligned burst it starts as "average, then the
    single-image network", and training can only teach it more than averaging."""
    if net.config.frames != 1:
        raise LBurstValueError(f"replicate_frames takes a single-image network, got {net.config.frames} frames")
    wide = LBurstNet(replace(net.config, frames=frames))
    state = {k: v.clone() for k, v in net.state_dict().items()}
    first = "ops.0.weight"
    state[first] = state[first].repeat(1, frames, 1, 1) / frames
    wide.load_state_dict(state)
    return wide


def checkpoint_dict(net: LBurstNet | LiteNet) -> dict:
    """``{'net', 'state_dict'}``: ``net`` in the published checkpoint layout, on the CPU."""
    return {"net": net.config.net_string(), "state_dict": {k: v.detach().cpu() for k, v in net.state_dict().items()}}


def write_checkpoint(checkpoint: dict, path: str | Path) -> None:
    """``torch.save`` of ``checkpoint`` (weights, or a training state) to ``path``, atomically."""
    with atomic_path(path) as tmp:
        torch.save(checkpoint, tmp)


def save_checkpoint(net: LBurstNet | LiteNet, path: str | Path, meta: dict | None = None) -> None:
    """Write ``net`` in the published layout (``{'net', 'state_dict'}``) plus ``meta``, atomically."""
    ckpt = checkpoint_dict(net)
    if meta:
        ckpt["meta"] = meta
    write_checkpoint(ckpt, path)
