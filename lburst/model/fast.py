"""A faster, inference-only form of :class:`lburst.model.LBurstNet` with the same outputs.

What it changes, none of which changes the result beyond float rounding:

- BatchNorm (no affine, running statistics) is folded into the preceding conv;
- tensors are channels-last, which oneDNN convolves without reordering;
- on the CPU, the full-resolution layers (three 3x3 convs and the max-pool) run in
  stripes of rows, with one row of context per conv, so their maps stay in the cache
  (see :meth:`FastLBurstNet._striped_front`);
- the repeatability and reliability heads (upsampling, squaring, 1x1 projection) run
  in bands of a few rows, so the 128-channel full-resolution map is never built whole
  and each band stays in the cache (see :meth:`FastLBurstNet._heads`);
- descriptors are only interpolated and normalised at the keypoints.

Outputs are those of :class:`LBurstNet` at even input sizes (``(B, 1, H, W)`` maps);
odd sizes are padded exactly as there.
"""

from __future__ import annotations

import copy

import torch
import torch.nn.functional as F
from torch import nn

from lburst.errors import LBurstValueError
from lburst.model.network import LBurstNet, autocast_dtype


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


#: bytes of the largest map of a stripe of the full-resolution layers (32 rows of a
#: 1024-wide 64-channel map): a stripe's maps then stay in an L3 cache of that size
STRIPE_BYTES = 8 << 20
#: input bytes per band of the head computation (8 rows of a 512-wide 128-D half map):
#: the band's upsampled map (4x that) then fits in the L2 and L3 caches
HEAD_BAND_BYTES = 2 << 20


class FastLBurstNet(nn.Module):
    """Inference-only LBurst network; see the module docstring."""

    def __init__(
        self,
        net: LBurstNet,
        precision: str = "fp32",
        tiled: bool = True,
        stripe_rows: int | None = None,
        head_band_rows: int | None = None,
    ) -> None:
        """``precision``: see :meth:`core`.  ``tiled``: on the CPU, run the full-resolution
        layers in stripes (:meth:`raw`) and the heads in bands (:meth:`_heads`) so their maps
        stay in the cache; ``stripe_rows`` and ``head_band_rows`` set the sizes (default:
        :data:`STRIPE_BYTES` and :data:`HEAD_BAND_BYTES`).  ``tiled=False`` runs every
        layer on the whole map (one graph for any size, as the ONNX export needs; the GPU
        path always does)."""
        super().__init__()
        self._autocast = autocast_dtype(precision)
        for name, rows in (("stripe_rows", stripe_rows), ("head_band_rows", head_band_rows)):
            if rows is not None and (rows < 1 or (name == "stripe_rows" and rows % 2)):
                raise LBurstValueError(f"{name} must be a positive (for stripes: even) number of rows, got {rows}")
        self.precision = precision
        self.tiled = tiled
        self.stripe_rows = stripe_rows
        self.head_band_rows = head_band_rows
        self.config = net.config
        self.body = fold_batchnorm(net.ops).eval().to(memory_format=torch.channels_last)
        pool = next(i for i, op in enumerate(self.body) if isinstance(op, nn.MaxPool2d))
        self.pool_index = pool  # body[:pool + 1] is striped, body[pool + 1:] runs on the whole map
        if any(c.kernel_size != (3, 3) or c.dilation != (1, 1) or c.padding != (1, 1) for c in self._front_convs()):
            raise LBurstValueError("striped layers must be 3x3 convs with padding 1")
        heads = torch.cat([net.sal.weight, net.clf.weight])[:, :, 0, 0]  # (3, D): sal, clf0, clf1
        self.register_buffer("head_weight", heads.detach().clone())
        self.register_buffer("head_bias", torch.cat([net.sal.bias, net.clf.bias]).detach().clone())

    def _tiled(self, x: torch.Tensor) -> bool:
        return self.tiled and x.device.type == "cpu"

    def raw(self, x: torch.Tensor) -> torch.Tensor:
        """The half-resolution raw descriptor map (B, D, H//2, W//2)."""
        x = x.contiguous(memory_format=torch.channels_last)
        if not self._tiled(x):
            return self.body(x)
        return self.body[self.pool_index + 1 :](self._striped_front(x))

    def _front_convs(self) -> list[nn.Conv2d]:
        """The convs before the max-pool (each followed by a ReLU)."""
        return [op for op in self.body[: self.pool_index] if isinstance(op, nn.Conv2d)]

    def _striped_front(self, x: torch.Tensor) -> torch.Tensor:
        """The full-resolution 3x3 conv + ReLU layers and the 2x2 max-pool, in stripes of rows.

        A stripe of output rows ``[r0, r1)`` (``r0`` even, so the pool pairs the same rows)
        reads one input row of context per conv above and below it.  Inside the image each
        conv uses up one context row on that side; where the stripe reaches the image's top
        or bottom, each conv pads that side with zeros as the whole-map conv does.  Every
        output row then sees exactly what it sees in the whole map."""
        height, width = x.shape[-2:]
        convs = self._front_convs()
        channels = max(c.out_channels for c in convs)
        rows = self.stripe_rows or max(2, STRIPE_BYTES // (4 * channels * width) // 2 * 2)
        halo = len(convs)
        stripes, pooled_rows = [], height // 2 * 2  # the pool drops an odd last row (still context)
        for r0 in range(0, pooled_rows, rows):
            r1 = min(pooled_rows, r0 + rows)
            a, z = max(r0 - halo, 0), min(r1 + halo, height)
            top, bottom = int(a == 0), int(z == height)  # image borders: zero padding at every conv
            y = x[:, :, a:z]
            for conv in convs:
                y = F.conv2d(
                    F.pad(y, (0, 0, top, bottom)) if top or bottom else y, conv.weight, conv.bias, padding=(0, 1)
                ).relu_()
            first = a if top else a + halo  # image row of y's first row
            stripes.append(F.max_pool2d(y[:, :, r0 - first : r1 - first], 2))
        return torch.cat(stripes, dim=2)

    def _heads(self, half: torch.Tensor) -> torch.Tensor:
        """Head pre-activations (B, 3, 2h, 2w) of the x2-upsampled map, from the half map (B, D, h, w).

        The map is upsampled, squared and projected in bands of rows, so the 128-channel
        full-resolution map never leaves the cache.  Each band is upsampled with one
        half-resolution row of context above and below (where the map has one), and the
        two output rows that context adds on each side are dropped: the band starts an
        even number of output rows into the map, so every kept row is interpolated with
        the same weights, and at the map's border the same clamp, as in the whole map.
        The result equals upsampling the whole map up to the order of float sums.
        """
        weight = self.head_weight[:, :, None, None]
        if not self._tiled(half):
            up = F.interpolate(half, scale_factor=2.0, mode="bilinear", align_corners=False)
            return F.conv2d(up * up, weight, self.head_bias)
        dim, h, w = half.shape[1:]
        rows = self.head_band_rows or max(1, HEAD_BAND_BYTES // (4 * dim * w))
        bands = []
        for r0 in range(0, h, rows):
            r1 = min(h, r0 + rows)
            a, z = max(r0 - 1, 0), min(r1 + 1, h)  # with context rows
            up = F.interpolate(half[:, :, a:z], scale_factor=2.0, mode="bilinear", align_corners=False)
            up = up[:, :, 2 * (r0 - a) : up.shape[2] - 2 * (z - r1)]
            bands.append(F.conv2d(up * up, weight, self.head_bias))
        return torch.cat(bands, dim=2)

    def core(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(repeatability, reliability, half)`` at the network's output size ``2 * (H // 2)``.

        With ``precision`` ``'bf16'`` or ``'fp16'`` the backbone runs under autocast and
        the heads in fp32 (so the 3x3 maxima do not tie on rounded values)."""
        if self._autocast is None:
            half = self.raw(x)
        else:
            with torch.autocast(device_type=x.device.type, dtype=self._autocast):
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
    """Zero-pad maps one pixel short along odd input dimensions (see :mod:`lburst.model.network`)."""
    pad_h, pad_w = size[0] - repeatability.shape[-2], size[1] - repeatability.shape[-1]
    if pad_w or pad_h:
        repeatability = F.pad(repeatability, (0, pad_w, 0, pad_h))
        reliability = F.pad(reliability, (0, pad_w, 0, pad_h))
    return repeatability, reliability


def descriptor_stride(map_width: int, image_width: int) -> int:
    """Pixels of the image per pixel of a raw descriptor map: 2 for the Fast-Quad-L2-Net's
    half map (``W // 2`` wide), 4 for the light network's quarter map (``ceil(W / 4)`` wide,
    :mod:`lburst.model.lite`)."""
    return 2 if map_width > (image_width + 3) // 4 else 4


def descriptors_at(half: torch.Tensor, y: torch.Tensor, x: torch.Tensor, stride: int = 2) -> torch.Tensor:
    """L2-normalised descriptors (K, D) at full-resolution integer pixels (y, x) of image 0,
    interpolated from the raw map (1, D, h, w) exactly as bilinear upsampling by ``stride``
    (2: the half map, 4: the light network's quarter map) does."""
    h, w = half.shape[-2:]

    half = half.float()

    def taps(i: torch.Tensor, n: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        src = ((i.to(torch.float32) + 0.5) / stride - 0.5).clamp(min=0)
        i0 = src.floor().long().clamp(max=n - 1)
        lam = src - i0
        return i0, (i0 + 1).clamp(max=n - 1), lam

    y0, y1, ly = taps(y, h)
    x0, x1, lx = taps(x, w)
    rows = _rows(half[0], torch.cat([y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1]))
    d00, d01, d10, d11 = rows.reshape(4, len(y), half.shape[1])
    lx, ly = lx[:, None], ly[:, None]
    d = (d00 * (1 - lx) + d01 * lx) * (1 - ly) + (d10 * (1 - lx) + d11 * lx) * ly
    return F.normalize(d, p=2, dim=1)


def _rows(m: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Descriptors (K, D) at flat pixel ``index`` of the map ``m`` (D, h, w), gathered in
    whichever memory layout ``m`` has (a gather of whole rows on channels-last maps, of
    columns on channels-first ones), which is faster than indexing ``m[:, y, x]`` (docs/speed.md)."""
    pixels = m.permute(1, 2, 0)
    if pixels.is_contiguous():
        return pixels.reshape(-1, m.shape[0])[index]
    return m.reshape(m.shape[0], -1).index_select(1, index).t()
