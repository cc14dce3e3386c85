"""A faster, inference-only form of :class:`lburst.model.LBurstNet` with the same outputs.

What it changes, none of which changes the result beyond float rounding:

- BatchNorm (no affine, running statistics) is folded into the preceding conv;
- tensors are channels-last, which oneDNN convolves without reordering;
- the repeatability and reliability heads are computed from the *half-resolution*
  raw map: the x2 bilinear upsampling is linear, so ``W . (U x)^2`` expands into
  weighted sums of ``W . (x_i * x_j)`` over the 2x2 cell of half-resolution pixels
  that each output pixel interpolates; those five 3-channel maps (self, right, down,
  diagonal, anti-diagonal products) are cheap, and the 128-channel full-resolution
  map is never built;
- descriptors are only interpolated and normalised at the keypoints.

Outputs are those of :class:`LBurstNet` at even input sizes (``(B, 1, H, W)`` maps);
odd sizes are padded exactly as there.
"""

from __future__ import annotations

import copy

import torch
import torch.nn.functional as F
from torch import nn

from lburst.model import LBurstNet


def fold_batchnorm(ops: nn.ModuleList) -> nn.Sequential:
    """The op list with every Conv2d + BatchNorm2d pair replaced by one equivalent Conv2d."""
    folded: list[nn.Module] = []
    i = 0
    while i < len(ops):
        op = ops[i]
        if isinstance(op, nn.Conv2d) and i + 1 < len(ops) and isinstance(ops[i + 1], nn.BatchNorm2d):
            bn = ops[i + 1]
            conv = copy.deepcopy(op)
            scale = torch.rsqrt(bn.running_var + bn.eps)
            if bn.affine:
                scale = scale * bn.weight
            bias = (op.bias - bn.running_mean) * scale
            if bn.affine:
                bias = bias + bn.bias
            conv.weight.data = op.weight.data * scale[:, None, None, None]
            conv.bias.data = bias.data
            folded.append(conv)
            i += 2
        else:
            folded.append(copy.deepcopy(op))
            i += 1
    return nn.Sequential(*folded)


# weights of the two half-resolution rows (or columns) that x2 bilinear upsampling
# (align_corners=False) blends, in a map padded by one replicated pixel: output 2m uses
# padded rows (m, m+1) with (1/4, 3/4), output 2m+1 uses (m+1, m+2) with (3/4, 1/4)
_PARITY_WEIGHTS = ((0.25, 0.75), (0.75, 0.25))


class FastLBurstNet(nn.Module):
    """Inference-only LBurst network; see the module docstring."""

    def __init__(self, net: LBurstNet, precision: str = "fp32") -> None:
        super().__init__()
        if precision not in ("fp32", "bf16", "fp16"):
            raise ValueError(f"precision must be fp32, bf16 or fp16, got {precision!r}")
        self.precision = precision
        self.config = net.config
        self.body = fold_batchnorm(net.ops).eval().to(memory_format=torch.channels_last)
        heads = torch.cat([net.sal.weight, net.clf.weight])[:, :, 0, 0]  # (3, D): sal, clf0, clf1
        self.register_buffer("head_weight", heads.detach().clone())
        self.register_buffer("head_bias", torch.cat([net.sal.bias, net.clf.bias]).detach().clone())

    def raw(self, x: torch.Tensor) -> torch.Tensor:
        """The half-resolution raw descriptor map (B, D, H//2, W//2)."""
        return self.body(x.contiguous(memory_format=torch.channels_last))

    def _heads(self, half: torch.Tensor) -> torch.Tensor:
        """Head pre-activations (B, 3, 2h, 2w) of the upsampled map, from the half map (B, D, h, w)."""
        # channels-last (B, h, w, D) views: the products and projections stream through memory
        p = F.pad(half, (1, 1, 1, 1), mode="replicate").permute(0, 2, 3, 1).contiguous()
        bsz, h, w = half.shape[0], half.shape[-2], half.shape[-1]
        weight_t = self.head_weight.t().contiguous()

        def proj(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:  # (B, *, *, 3)
            return torch.matmul(a * b, weight_t)

        s = proj(p, p)  # (h+2, w+2)
        right = proj(p[:, :, :-1], p[:, :, 1:])  # (h+2, w+1)
        down = proj(p[:, :-1, :], p[:, 1:, :])  # (h+1, w+2)
        cross = proj(p[:, :-1, :-1], p[:, 1:, 1:]) + proj(p[:, :-1, 1:], p[:, 1:, :-1])  # diagonals (h+1, w+1)
        rows = []
        for py, (a0, a1) in enumerate(_PARITY_WEIGHTS):
            r, r1 = slice(py, py + h), slice(py + 1, py + 1 + h)
            cols = []
            for px, (b0, b1) in enumerate(_PARITY_WEIGHTS):
                c, c1 = slice(px, px + w), slice(px + 1, px + 1 + w)
                cols.append(
                    (a0 * b0) ** 2 * s[:, r, c]
                    + (a0 * b1) ** 2 * s[:, r, c1]
                    + (a1 * b0) ** 2 * s[:, r1, c]
                    + (a1 * b1) ** 2 * s[:, r1, c1]
                    + 2 * a0 * a0 * b0 * b1 * right[:, r, c]
                    + 2 * a1 * a1 * b0 * b1 * right[:, r1, c]
                    + 2 * a0 * a1 * b0 * b0 * down[:, r, c]
                    + 2 * a0 * a1 * b1 * b1 * down[:, r, c1]
                    + 2 * a0 * a1 * b0 * b1 * cross[:, r, c]
                )
            rows.append(torch.stack(cols, dim=3))  # (B, h, w, 2, 3): column parity
        out = torch.stack(rows, dim=2)  # (B, h, 2, w, 2, 3): output pixel (2m + py, 2n + px)
        out = out.reshape(bsz, 2 * h, 2 * w, 3) + self.head_bias
        return out.permute(0, 3, 1, 2)

    def core(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(repeatability, reliability, half)`` at the network's output size ``2 * (H // 2)``.

        With ``precision`` ``'bf16'`` or ``'fp16'`` the backbone runs under autocast and
        the heads in fp32 (so the 3x3 maxima do not tie on rounded values)."""
        if self.precision == "fp32":
            half = self.raw(x)
        else:
            dtype = {"bf16": torch.bfloat16, "fp16": torch.float16}[self.precision]
            with torch.autocast(device_type=x.device.type, dtype=dtype):
                half = self.raw(x)
            half = half.float()
        pre = self._heads(half)
        sal = F.softplus(pre[:, :1])
        return sal / (1 + sal), torch.softmax(pre[:, 1:], dim=1)[:, 1:2], half

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(repeatability, reliability, half)``: maps (B, 1, H, W) and the raw half map."""
        repeatability, reliability, half = self.core(x)
        return pad_maps(repeatability, reliability, x.shape[-2:]) + (half,)


class CoreModule(nn.Module):
    """:meth:`FastLBurstNet.core` as a module (what ``lburst export onnx`` exports)."""

    def __init__(self, fast: FastLBurstNet) -> None:
        super().__init__()
        self.fast = fast

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return self.fast.core(x)


def pad_maps(repeatability: torch.Tensor, reliability: torch.Tensor, size) -> tuple[torch.Tensor, torch.Tensor]:
    """Zero-pad maps one pixel short along odd input dimensions (see :mod:`lburst.model`)."""
    pad_h, pad_w = size[0] - repeatability.shape[-2], size[1] - repeatability.shape[-1]
    if pad_w or pad_h:
        repeatability = F.pad(repeatability, (0, pad_w, 0, pad_h))
        reliability = F.pad(reliability, (0, pad_w, 0, pad_h))
    return repeatability, reliability


def descriptors_at(half: torch.Tensor, y: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """L2-normalised descriptors (K, D) at full-resolution integer pixels (y, x) of image 0,
    interpolated from the half map (1, D, h, w) exactly as x2 bilinear upsampling does."""
    h, w = half.shape[-2:]

    half = half.float()

    def taps(i: torch.Tensor, n: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        src = ((i.to(torch.float32) + 0.5) / 2 - 0.5).clamp(min=0)
        i0 = src.floor().long()
        lam = src - i0
        return i0, (i0 + 1).clamp(max=n - 1), lam

    y0, y1, ly = taps(y, h)
    x0, x1, lx = taps(x, w)
    m = half[0]
    top = m[:, y0, x0] * (1 - lx) + m[:, y0, x1] * lx
    bottom = m[:, y1, x0] * (1 - lx) + m[:, y1, x1] * lx
    d = top * (1 - ly) + bottom * ly
    return F.normalize(d.t(), p=2, dim=1)
