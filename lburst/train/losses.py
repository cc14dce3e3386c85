"""R2D2's self-supervised losses, for a pair of bursts related by a dense flow.

Shapes: maps are ``(B, 1, H, W)``, descriptors ``(B, D, H, W)`` (L2-normalised),
``flow`` ``(B, H, W, 2)`` absolute (x, y) positions in B of A's pixels, ``mask``
``(B, H, W)`` bool.  Pixel centres are at integer coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F


def warp_to_a(map_b: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """Sample ``map_b`` (B, C, H, W) at ``flow`` (B, H, W, 2): B's values seen from A's pixels."""
    h, w = map_b.shape[-2:]
    grid = torch.stack([(2 * flow[..., 0] + 1) / w - 1, (2 * flow[..., 1] + 1) / h - 1], -1)
    return F.grid_sample(map_b, grid, mode="bilinear", padding_mode="border", align_corners=False)


def cosim_loss(
    rep_a: torch.Tensor, rep_b: torch.Tensor, flow: torch.Tensor, mask: torch.Tensor, patch: int = 16
) -> torch.Tensor:
    """1 - mean cosine similarity of ``patch`` x ``patch`` patches (stride patch/2) of A's
    repeatability and B's warped onto A; pixels outside the overlap are left out and patches
    more than half outside it are skipped."""
    warped = warp_to_a(rep_b, flow)
    stride = patch // 2
    m = mask[:, None].to(rep_a.dtype)
    pa = F.unfold(rep_a * m, patch, stride=stride)  # (B, patch^2, L), pixels outside the overlap zeroed
    pb = F.unfold(warped * m, patch, stride=stride)
    valid = F.unfold(m, patch, stride=stride).mean(1) > 0.5  # (B, L)
    cos = (F.normalize(pa, dim=1) * F.normalize(pb, dim=1)).sum(1)
    if not valid.any():
        return rep_a.sum() * 0
    return 1 - cos[valid].mean()


def peaky_loss(rep: torch.Tensor, patch: int = 16) -> torch.Tensor:
    """1 - mean(local max - local mean) over (patch+1)^2 windows of the 3x3-smoothed map."""
    rep = F.avg_pool2d(rep, 3, stride=1, padding=1, count_include_pad=False)
    local_max = F.max_pool2d(rep, patch + 1, stride=1, padding=patch // 2)
    local_mean = F.avg_pool2d(rep, patch + 1, stride=1, padding=patch // 2, count_include_pad=False)
    return 1 - (local_max - local_mean).mean()


def quantized_ap(
    scores: torch.Tensor, labels: torch.Tensor, bins: int = 20, keep: torch.Tensor | None = None
) -> torch.Tensor:
    """Differentiable average precision of each row of ``scores`` (Q, M) with bool ``labels``.

    Scores (similarities, clamped to [0, 1]) are soft-assigned to ``bins`` equally spaced
    bin centres from 1 down to 0 with triangular weights; precision and recall are
    accumulated bin by bin from the highest similarity.  With scores exactly on bin
    centres this is the exact AP (ties within a bin count as one rank).  Entries whose
    ``keep`` is False take no part.
    """
    centres = torch.linspace(1, 0, bins, device=scores.device, dtype=scores.dtype)
    x = scores.clamp(0, 1)[:, None, :]  # (Q, 1, M)
    weight = (1 - (x - centres[None, :, None]).abs() * (bins - 1)).clamp(min=0)  # (Q, bins, M)
    if keep is not None:
        weight = weight * keep[:, None, :]
    count = weight.sum(-1)
    positives = (weight * labels[:, None, :].to(weight.dtype)).sum(-1)
    precision = positives.cumsum(-1) / (count.cumsum(-1) + 1e-16)
    recall = positives / positives.sum(-1, keepdim=True).clamp(min=1e-16)
    return (precision * recall).sum(-1)


@dataclass(frozen=True)
class APSampling:
    """Where the reliability loss samples queries, positives and negatives (R2D2's values).

    Attributes:
        query_stride: grid spacing of query pixels in A (random offset per batch).
        border: query pixels this close to A's border are skipped.
        neighbourhood: radius of the candidate disc around a query's target in B.
        pos_radius: candidates within this distance of the target are positives
            (the best-scoring one is kept).
        neg_radius: candidates at least this far are negatives; also every pixel of a
            ``distractor_stride`` grid of B farther than this.
        base: AP assumed for unreliable pixels (reliability-weighted loss).
        bins: quantisation bins of the AP.
    """

    query_stride: int = 8
    border: int = 16
    neighbourhood: int = 7
    pos_radius: float = 3.0
    neg_radius: float = 5.0
    distractor_stride: int = 8
    base: float = 0.5
    bins: int = 20


def _gather(desc: torch.Tensor, batch: torch.Tensor, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Descriptors (..., D) at integer pixels (x, y) of image ``batch``."""
    return desc.permute(0, 2, 3, 1)[batch, y, x]


def reliability_ap_loss(
    desc_a: torch.Tensor,
    desc_b: torch.Tensor,
    rel_a: torch.Tensor,
    flow: torch.Tensor,
    mask: torch.Tensor,
    generator: torch.Generator | None = None,
    cfg: APSampling = APSampling(),
) -> tuple[torch.Tensor, torch.Tensor]:
    """R2D2's reliability loss ``1 - AP * rel - (1 - rel) * base`` averaged over queries.

    Returns ``(loss, mean AP)``; the mean AP keeps its gradient (for an unweighted
    descriptor term, see :class:`lburst.train.loop.TrainConfig`).
    """
    bsz, _, h, w = desc_a.shape
    dev = desc_a.device
    off = torch.randint(0, cfg.query_stride, (2,), generator=generator).tolist()
    qy, qx = torch.meshgrid(
        torch.arange(cfg.border + off[1], h - cfg.border, cfg.query_stride, device=dev),
        torch.arange(cfg.border + off[0], w - cfg.border, cfg.query_stride, device=dev),
        indexing="ij",
    )
    qx, qy = qx.reshape(-1), qy.reshape(-1)
    batch = torch.arange(bsz, device=dev).repeat_interleave(len(qx))
    qx, qy = qx.repeat(bsz), qy.repeat(bsz)
    target = flow[batch, qy, qx]  # (Q, 2)
    r = cfg.neighbourhood
    valid = mask[batch, qy, qx] & (target[:, 0] >= r) & (target[:, 0] <= w - 1 - r)
    valid &= (target[:, 1] >= r) & (target[:, 1] <= h - 1 - r)
    batch, qx, qy, target = batch[valid], qx[valid], qy[valid], target[valid]
    if len(batch) == 0:
        zero = desc_a.sum() * 0
        return zero, zero
    query = _gather(desc_a, batch, qx, qy)  # (Q, D)

    # candidates in a disc around the rounded target
    oy, ox = torch.meshgrid(torch.arange(-r, r + 1, device=dev), torch.arange(-r, r + 1, device=dev), indexing="ij")
    disc = (ox**2 + oy**2) <= r * r
    ox, oy = ox[disc], oy[disc]
    cx = target[:, :1].round().long() + ox[None]  # (Q, C)
    cy = target[:, 1:].round().long() + oy[None]
    dist = torch.hypot(cx - target[:, :1], cy - target[:, 1:])
    cand = _gather(desc_b, batch[:, None].expand_as(cx), cx, cy)  # (Q, C, D)
    near_scores = (cand * query[:, None]).sum(-1)
    pos_scores = near_scores.masked_fill(dist > cfg.pos_radius, -2).max(1).values  # best positive

    # distractors: a regular grid of B
    s = cfg.distractor_stride
    gy, gx = torch.meshgrid(
        torch.arange(s // 2, h, s, device=dev), torch.arange(s // 2, w, s, device=dev), indexing="ij"
    )
    gx, gy = gx.reshape(-1), gy.reshape(-1)
    grid_desc = desc_b.permute(0, 2, 3, 1)[:, gy, gx]  # (B, G, D)
    # queries are in batch order: one (Q_b, D) x (D, G) product per image, never a (Q, G, D) copy
    counts = torch.bincount(batch, minlength=bsz).tolist()
    far_scores = torch.cat([q @ grid_desc[b].T for b, q in enumerate(query.split(counts))])
    far_dist = torch.hypot(gx[None] - target[:, :1], gy[None] - target[:, 1:])

    # column 0: the best positive; then negatives near the target and far distractors,
    # leaving out candidates between pos_radius and neg_radius (neither)
    scores = torch.cat([pos_scores[:, None], near_scores, far_scores], 1)
    labels = torch.zeros_like(scores, dtype=torch.bool)
    labels[:, 0] = True
    keep = torch.cat([labels[:, :1], dist >= cfg.neg_radius, far_dist >= cfg.neg_radius], 1)
    ap = quantized_ap(scores, labels, cfg.bins, keep)
    rel = rel_a[batch, 0, qy, qx]
    loss = 1 - ap * rel - (1 - rel) * cfg.base
    return loss.mean(), ap.mean()


def logit_margin_loss(logits: torch.Tensor, margin: float = 4.0) -> torch.Tensor:
    """``mean(max(|z| - margin, 0)^2)``: zero while the reliability's logit ``z`` stays in
    ``[-margin, margin]``, where the softmax still passes a gradient (``sigmoid(4) = 0.982``).

    Without it, a reliability pushed to 0 early (AP below the base) saturates: the logits
    of a 5-frame run reached a median of -19 by step 300 (gradient ~5e-9) and it still had
    no pixel above the 0.7 keypoint threshold at step 903.
    """
    return torch.relu(logits.abs() - margin).square().mean()


def spread_loss(desc: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """Squared norm of the mean descriptor of ``desc`` (B, D, H, W), each pixel weighted by
    ``weight`` (B, 1, H, W; no gradient; ``None``: all alike).

    0 when the unit descriptors share no common component.  Trained on noisy bursts
    without it, lburst-b5's keypoint descriptors kept a mean of norm 0.56 (0.17 over all
    pixels), which makes the descriptors near that mean the nearest neighbour of many and
    loses mutual matches (docs/training.md); the training step counts only the pixels the
    detector would keep."""
    desc = desc.float()
    if weight is None:
        return desc.mean(dim=(0, 2, 3)).square().sum()
    w = weight.detach().float()
    mean = (desc * w).sum(dim=(0, 2, 3)) / w.sum().clamp_min(1e-12)
    return mean.square().sum()


def distillation_loss(student: dict[str, torch.Tensor], teacher: dict[str, torch.Tensor]) -> torch.Tensor:
    """Dense self-distillation: the network on the noisy burst (``student``) against the
    same network on the noise-free burst (``teacher``, no gradient), at every pixel:
    ``mean(1 - cos(descriptors)) + mean|repeatability| + mean|reliability|`` differences."""
    desc = 1 - (student["descriptors"] * teacher["descriptors"].detach()).sum(1)
    rep = (student["repeatability"] - teacher["repeatability"].detach()).abs()
    rel = (student["reliability"] - teacher["reliability"].detach()).abs()
    return desc.mean() + rep.mean() + rel.mean()
