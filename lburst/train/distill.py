"""Dense distillation of the light network (:mod:`lburst.model.lite`) from a frozen teacher.

The teacher (lburst-b5, a Fast-Quad-L2-Net) runs in its inference form
(:class:`lburst.model.fast.FastLBurstNet`: no 128-channel full-resolution map) on the same
noisy bursts A and B as the student.  The student learns, at every pixel:

- its raw quarter-resolution descriptors, against the teacher's descriptors at the same
  points (the mean of each 2x2 block of the teacher's half map, which is where bilinear
  upsampling puts a quarter-map node): ``1 - cos``; a student with a half-resolution map
  (``desc_stride`` 2) learns the teacher's half map itself;
- its repeatability and reliability, against the teacher's, at full resolution: ``|s - t|``;

beside R2D2's self-supervised repeatability losses on the pair (cosine similarity through
the true flow, peakiness).  With ``ap_weight`` > 0 the descriptors also learn to match
across the pair: ``ap_weight * (1 - AP)``, R2D2's quantised AP of the student's own
descriptors (upsampled as at test time) through the true flow
(:func:`lburst.train.losses.reliability_ap_loss`); distillation alone teaches each view
separately, and the light network then matched less well across strong viewpoint changes
than its teacher.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from lburst.model.fast import FastLBurstNet
from lburst.model.lite import LiteNet
from lburst.model.network import autocast_dtype
from lburst.train.losses import cosim_loss, peaky_loss, reliability_ap_loss


def teacher_form(teacher: torch.nn.Module, precision: str = "fp32") -> FastLBurstNet:
    """The frozen teacher's inference form (whole-map layers, the batch's device)."""
    return FastLBurstNet(teacher, precision, tiled=False).eval()


@torch.no_grad()
def teacher_targets(teacher: FastLBurstNet, x: torch.Tensor, stride: int = 4) -> dict[str, torch.Tensor]:
    """``repeatability``, ``reliability`` (B, 1, H, W) and ``descriptors`` at the nodes of a
    student's raw map, unit length, from the teacher on ``x``: the quarter-map nodes
    (B, D, ceil(H/4), ceil(W/4)) for ``stride`` 4, the teacher's half map for 2."""
    rep, rel, half = teacher(x)
    nodes = F.avg_pool2d(half.float(), 2, ceil_mode=True) if stride == 4 else half.float()
    return {"repeatability": rep.float(), "reliability": rel.float(), "descriptors": F.normalize(nodes, dim=1)}


def lite_distillation_step(
    net: LiteNet | torch.nn.Module,
    teacher: FastLBurstNet,
    batch: dict[str, torch.Tensor],
    normalised: torch.Tensor,
    patch: int = 16,
    distill_weight: float = 1.0,
    precision: str = "fp32",
    ap_weight: float = 0.0,
    generator: torch.Generator | None = None,
) -> dict[str, torch.Tensor]:
    """Losses of one batch for the light network: ``normalised`` holds bursts A then B
    ``(2B, 3N, H, W)``; ``batch`` their ``flow`` and ``mask``.  Returns ``loss``, ``cosim``,
    ``peaky``, ``distill`` (descriptors + repeatability + reliability) and its three parts."""
    dtype = autocast_dtype(precision)
    n = batch["flow"].shape[0]
    size = normalised.shape[-2:]
    stride = getattr(net, "module", net).config.desc_stride
    target = teacher_targets(teacher, normalised, stride)
    with torch.autocast(device_type=normalised.device.type, dtype=dtype, enabled=dtype is not None):
        desc, heads = net(normalised, raw=True)  # through the module (a DDP wrapper syncs its gradients)
    rep, rel, _ = LiteNet.maps(heads.float(), size)
    desc = F.normalize(desc.float(), dim=1)
    t_desc = target["descriptors"]
    h, w = min(desc.shape[-2], t_desc.shape[-2]), min(desc.shape[-1], t_desc.shape[-1])
    d_desc = (1 - (desc[..., :h, :w] * t_desc[..., :h, :w]).sum(1)).mean()
    d_rep = (rep - target["repeatability"]).abs().mean()
    d_rel = (rel - target["reliability"]).abs().mean()
    distill = d_desc + d_rep + d_rel
    cosim = cosim_loss(rep[:n], rep[n:], batch["flow"], batch["mask"], patch)
    peaky = (peaky_loss(rep[:n], patch) + peaky_loss(rep[n:], patch)) / 2
    loss = distill_weight * distill + cosim + peaky
    extra = {}
    if ap_weight > 0:
        full = F.interpolate(desc, scale_factor=float(stride), mode="bilinear", align_corners=False)
        full = F.normalize(full[..., : size[0], : size[1]], dim=1)
        _, ap = reliability_ap_loss(full[:n], full[n:], rel[:n].detach(), batch["flow"], batch["mask"], generator)
        loss = loss + ap_weight * (1 - ap)
        extra["ap"] = ap
    return {
        **extra,
        "loss": loss,
        "cosim": cosim,
        "peaky": peaky,
        "distill": distill,
        "distill_desc": d_desc,
        "distill_rep": d_rep,
        "distill_rel": d_rel,
    }
