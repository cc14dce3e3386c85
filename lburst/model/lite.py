"""LBurst-Lite: a light burst network with the outputs of :class:`lburst.model.LBurstNet`.

Where the Fast-Quad-L2-Net runs three 3x3 convolutions at full resolution and five
128-channel layers at half resolution (about 230 GFLOP for a 1024x768 burst), the light
network works at half and quarter resolution, spends its depth on depthwise-separable
blocks, and never builds a wide map at half or full resolution (about 12 GFLOP for the
same burst)::

    burst (3N, H, W)
      stem   3x3 conv, stride 2, 3N -> fine           half resolution
      fine   3x3 conv, fine -> fine                   half resolution     F
      down   3x3 conv, stride 2, fine -> coarse       quarter resolution
      blocks residual [3x3 depthwise (dilation d) -> 1x1] for d in dilations   (receptive field) Q
      desc   1x1 conv Q -> dim: raw descriptors at quarter resolution
      heads  3x3 conv(F) + up2(1x1 conv(Q)) -> 6 logits at half resolution: four repeatability
             logits per half-resolution pixel (one per full-resolution pixel it covers, pixel
             shuffle) and the two reliability classes (bilinear x2)

Every convolution but the descriptor and head projections is followed by BatchNorm and
ReLU; :meth:`LiteNet.inference` folds the BatchNorm into the convolutions.

The repeatability is predicted per full-resolution pixel (pixel shuffle), not upsampled
from half resolution: the 3x3 maxima of a bilinearly upsampled map fall between two
pixels, which would cost keypoint localisation.

Descriptors are kept at quarter resolution and interpolated only at the keypoints: wide
maps at half resolution are what costs on a CPU (docs/speed.md, "The light network's design").

Inference form (:meth:`LiteNet.core`, what :class:`lburst.LBurst` and the ONNX export run):
``(repeatability, reliability, descriptor map)`` as :meth:`lburst.model.fast.FastLBurstNet.core`,
with the raw descriptor map at quarter instead of half resolution
(:func:`lburst.model.fast.descriptor_stride` tells them apart), so multi-scale detection
and descriptor sampling are shared with lburst-b5.
"""

from __future__ import annotations

import copy
import re
from dataclasses import dataclass, fields

import torch
import torch.nn.functional as F
from torch import nn

from lburst.errors import LBurstValueError
from lburst.model.precision import autocast_dtype

#: Class name written into checkpoints of the light network.
LITE_NAME = "LBurstLite"


@dataclass(frozen=True)
class LiteConfig:
    """Architecture of the light network.

    Attributes:
        frames: burst frames N (input channels 3N).
        dim: descriptor dimension.
        fine: channels at half resolution.
        coarse: channels at quarter resolution.
        dilations: one residual depthwise-separable block per entry, with that dilation.
        desc_stride: image pixels per pixel of the raw descriptor map: 4 (quarter resolution,
            the shipped light network) or 2 (half resolution: the quarter map upsampled x2
            plus a 1x1 projection of the fine map, as lburst-b5's half map).
    """

    frames: int = 5
    dim: int = 128
    fine: int = 32
    coarse: int = 96
    dilations: tuple[int, ...] = (1, 2, 4, 8)
    desc_stride: int = 4

    def __post_init__(self) -> None:
        if self.frames < 1 or self.frames % 2 == 0:
            raise LBurstValueError(f"frames must be odd and positive, got {self.frames}")
        for name in ("dim", "fine", "coarse"):
            if getattr(self, name) < 1:
                raise LBurstValueError(f"{name} must be positive, got {getattr(self, name)}")
        if not self.dilations or any(d < 1 for d in self.dilations):
            raise LBurstValueError(f"dilations must be positive, got {self.dilations}")
        if self.desc_stride not in (2, 4):
            raise LBurstValueError(f"desc_stride must be 2 or 4, got {self.desc_stride}")

    @property
    def in_channels(self) -> int:
        return 3 * self.frames

    def net_string(self) -> str:
        """The checkpoint's ``net`` string: ``LBurstLite(inchan=15,dim=128,...)``."""
        dil = "-".join(str(d) for d in self.dilations)
        stride = "" if self.desc_stride == 4 else f",desc_stride={self.desc_stride}"
        return f"{LITE_NAME}(inchan={self.in_channels},dim={self.dim},fine={self.fine},coarse={self.coarse},dilations={dil}{stride})"

    @classmethod
    def from_net_string(cls, net: str) -> "LiteConfig":
        """Parse :meth:`net_string` (never evaluated); ``ValueError`` on anything else."""
        match = re.fullmatch(rf"{LITE_NAME}\(([^()]*)\)", net.strip())
        if not match:
            raise LBurstValueError(f"not a {LITE_NAME} network string: {net!r}")
        values: dict[str, str] = {}
        for item in filter(None, (s.strip() for s in match.group(1).split(","))):
            key, _, value = item.partition("=")
            values[key.strip()] = value.strip()
        known = {f.name for f in fields(cls)} | {"inchan"}
        unknown = set(values) - known
        if unknown:
            raise LBurstValueError(f"{net!r}: unknown fields {', '.join(sorted(unknown))}")
        try:
            inchan = int(values.pop("inchan", "15"))
            kwargs: dict = {k: int(v) for k, v in values.items() if k != "dilations"}
            if "dilations" in values:
                kwargs["dilations"] = tuple(int(d) for d in values["dilations"].split("-"))
        except ValueError as exc:
            raise LBurstValueError(f"{net!r}: {exc}") from exc
        if inchan % 3:
            raise LBurstValueError(f"{net!r}: input channels {inchan} are not a multiple of 3")
        return cls(frames=inchan // 3, **kwargs)


def _conv_bn_relu(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride=stride, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True)
    )


class SeparableBlock(nn.Module):
    """``x + relu(bn(pointwise(depthwise_dilated(x))))``."""

    def __init__(self, channels: int, dilation: int) -> None:
        super().__init__()
        self.depthwise = nn.Conv2d(channels, channels, 3, padding=dilation, dilation=dilation, groups=channels)
        self.pointwise = nn.Conv2d(channels, channels, 1, bias=False)
        self.bn = nn.BatchNorm2d(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + F.relu(self.bn(self.pointwise(self.depthwise(x))))


def _up2(x: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Bilinear x2 (as the Fast-Quad-L2-Net's upsampling), cropped to ``size``."""
    up = F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)
    return up[..., : size[0], : size[1]]


def _descriptors(
    desc: nn.Module, desc_fine: nn.Module | None, coarse: torch.Tensor, fine: torch.Tensor
) -> torch.Tensor:
    """The raw descriptor map: ``desc(coarse)`` at quarter resolution, or with ``desc_fine``
    that map upsampled x2 plus ``desc_fine(fine)`` at half resolution."""
    if desc_fine is None:
        return desc(coarse)
    return _up2(desc(coarse), fine.shape[-2:]) + desc_fine(fine)


class LiteNet(nn.Module):
    """The light burst network; see the module docstring."""

    def __init__(self, config: LiteConfig = LiteConfig()) -> None:
        super().__init__()
        self.config = config
        c = config
        self.stem = _conv_bn_relu(c.in_channels, c.fine, stride=2)
        self.fine = _conv_bn_relu(c.fine, c.fine)
        self.down = _conv_bn_relu(c.fine, c.coarse, stride=2)
        self.blocks = nn.Sequential(*(SeparableBlock(c.coarse, d) for d in c.dilations))
        self.desc = nn.Conv2d(c.coarse, c.dim, 1)
        self.desc_fine = nn.Conv2d(c.fine, c.dim, 1, bias=False) if c.desc_stride == 2 else None
        self.head_coarse = nn.Conv2d(c.coarse, 6, 1)
        self.head_fine = nn.Conv2d(c.fine, 6, 3, padding=1, bias=False)

    def _check(self, x: torch.Tensor) -> None:
        if x.ndim != 4 or x.shape[1] != self.config.in_channels:
            raise LBurstValueError(
                f"expected input (B, {self.config.in_channels}, H, W) for a {self.config.frames}-frame "
                f"network, got {tuple(x.shape)}"
            )

    def desc_and_heads(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Raw descriptors, ``(B, dim, ceil(H/4), ceil(W/4))`` (rounding up at each stride;
        ``(B, dim, ceil(H/2), ceil(W/2))`` with ``desc_stride`` 2) and the six head logits at
        half resolution (four repeatability sub-pixels, two reliability classes)."""
        self._check(x)
        fine = self.fine(self.stem(x))
        coarse = self.blocks(self.down(fine))
        heads = self.head_fine(fine) + _up2(self.head_coarse(coarse), fine.shape[-2:])
        return _descriptors(self.desc, self.desc_fine, coarse, fine), heads

    @staticmethod
    def maps(heads: torch.Tensor, size: tuple[int, int]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(repeatability, reliability, reliability logit)`` ``(B, 1, H, W)`` from the head logits."""
        sal = F.softplus(F.pixel_shuffle(heads[:, :4], 2)[..., : size[0], : size[1]])
        clf = _up2(heads[:, 4:], size)
        logit = clf[:, 1:2] - clf[:, 0:1]
        return sal / (1 + sal), torch.sigmoid(logit), logit

    def forward(self, x: torch.Tensor, reliability_logits: bool = False, raw: bool = False):
        """The training outputs of :meth:`lburst.model.LBurstNet.forward`: full-resolution
        ``descriptors``, ``repeatability`` and ``reliability`` (and ``reliability_logits``);
        with ``raw``, :meth:`desc_and_heads` instead (what distillation trains)."""
        if raw:
            return self.desc_and_heads(x)
        size = x.shape[-2:]
        desc, heads = self.desc_and_heads(x)
        repeatability, reliability, logit = self.maps(heads, size)
        up = F.interpolate(desc, scale_factor=float(self.config.desc_stride), mode="bilinear", align_corners=False)
        up = up[..., : size[0], : size[1]]
        out = {
            "descriptors": F.normalize(up, p=2, dim=1),
            "repeatability": repeatability,
            "reliability": reliability,
        }
        if reliability_logits:
            out["reliability_logits"] = logit
        return out

    def core(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(repeatability, reliability, descriptor map)`` (the interface of ``FastLBurstNet``)."""
        desc, heads = self.desc_and_heads(x)
        repeatability, reliability, _ = self.maps(heads, x.shape[-2:])
        return repeatability, reliability, desc

    def inference(self, precision: str = "fp32") -> "LiteInference":
        """An eval-mode copy with BatchNorm folded into the convolutions, channels-last."""
        return LiteInference(self, precision)


def _fold(conv: nn.Conv2d, bn: nn.BatchNorm2d) -> nn.Conv2d:
    return torch.nn.utils.fusion.fuse_conv_bn_eval(copy.deepcopy(conv).eval(), copy.deepcopy(bn).eval())


class LiteInference(nn.Module):
    """:class:`LiteNet` for inference: BatchNorm folded, channels-last, with ``core`` and
    ``forward`` returning ``(repeatability, reliability, half)`` as ``FastLBurstNet`` does.
    ``precision`` ``'bf16'`` runs the convolutions under autocast and the maps in fp32."""

    def __init__(self, net: LiteNet, precision: str = "fp32") -> None:
        super().__init__()
        net = copy.deepcopy(net).eval()
        self._autocast = autocast_dtype(precision)
        self.precision = precision
        self.config = net.config
        self.stem = nn.Sequential(_fold(net.stem[0], net.stem[1]), nn.ReLU(inplace=True))
        self.fine = nn.Sequential(_fold(net.fine[0], net.fine[1]), nn.ReLU(inplace=True))
        self.down = nn.Sequential(_fold(net.down[0], net.down[1]), nn.ReLU(inplace=True))
        self.blocks = nn.ModuleList()
        for block in net.blocks:
            self.blocks.append(nn.ModuleList([block.depthwise, _fold(block.pointwise, block.bn)]))
        self.desc, self.desc_fine = net.desc, net.desc_fine
        self.head_coarse, self.head_fine = net.head_coarse, net.head_fine
        self.eval().to(memory_format=torch.channels_last)

    def _desc_and_heads(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x = x.contiguous(memory_format=torch.channels_last)
        fine = self.fine(self.stem(x))
        y = self.down(fine)
        for depthwise, pointwise in self.blocks:
            y = y + F.relu(pointwise(depthwise(y)))
        heads = self.head_fine(fine) + _up2(self.head_coarse(y), fine.shape[-2:])
        return _descriptors(self.desc, self.desc_fine, y, fine), heads

    def core(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        if self._autocast is None:
            desc, heads = self._desc_and_heads(x)
        else:
            with torch.autocast(device_type=x.device.type, dtype=self._autocast):
                desc, heads = self._desc_and_heads(x)
            desc, heads = desc.float(), heads.float()
        repeatability, reliability, _ = LiteNet.maps(heads, x.shape[-2:])
        return repeatability, reliability, desc

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return self.core(x)
