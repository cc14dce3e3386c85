"""The training losses: minimal for perfect predictions, gradients flow, AP is exact."""

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from lburst.train.losses import (
    APSampling,
    cosim_loss,
    peaky_loss,
    quantized_ap,
    reliability_ap_loss,
    spread_loss,
    warp_to_a,
)


def _shift_flow(h, w, dx, dy, b=1):
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    flow = torch.stack([xs + dx, ys + dy], -1)[None].repeat(b, 1, 1, 1)
    mask = (flow[..., 0] >= 0) & (flow[..., 0] <= w - 1) & (flow[..., 1] >= 0) & (flow[..., 1] <= h - 1)
    return flow, mask


def brute_force_ap(scores, labels):
    order = np.argsort(-scores, kind="stable")
    hits = labels[order]
    precision_at_hits = np.cumsum(hits)[hits] / (np.flatnonzero(hits) + 1)
    return precision_at_hits.mean()


def test_warp_to_a_follows_the_flow():
    b = torch.rand(1, 1, 20, 30)
    flow, _ = _shift_flow(20, 30, 3, 2)
    warped = warp_to_a(b, flow)
    assert torch.allclose(warped[0, 0, :18, :27], b[0, 0, 2:, 3:], atol=1e-5)


def test_quantized_ap_matches_brute_force_on_bin_centres():
    rng = np.random.default_rng(0)
    centres = np.linspace(1, 0, 20)
    for _ in range(20):
        picks = rng.choice(20, size=12, replace=False)  # distinct bins: no ties
        scores = centres[picks]
        labels = rng.random(12) < 0.4
        labels[0] = True
        ap = quantized_ap(torch.tensor(scores[None], dtype=torch.float64), torch.tensor(labels[None]))
        assert ap.item() == pytest.approx(brute_force_ap(scores, labels), abs=1e-9)


def test_quantized_ap_ignores_entries_not_kept():
    scores = torch.tensor([[0.5, 1.0, 0.0]])
    labels = torch.tensor([[True, False, False]])
    assert quantized_ap(scores, labels, bins=3).item() == pytest.approx(0.5)
    keep = torch.tensor([[True, False, True]])
    assert quantized_ap(scores, labels, bins=3, keep=keep).item() == pytest.approx(1.0)


def test_cosim_loss_is_zero_for_consistent_maps_and_positive_otherwise():
    torch.manual_seed(0)
    h, w, dx, dy = 48, 64, 5, 3
    big = torch.rand(1, 1, h + dy, w + dx)
    rep_a = big[..., :h, :w]
    rep_b = torch.zeros(1, 1, h, w)
    rep_b[..., : h - dy, : w - dx] = big[..., dy:h, dx:w]  # B sees A's content shifted by (-dx, -dy)
    # content at A (x, y) is big[y, x] = B (x - dx, y - dy)
    flow, mask = _shift_flow(h, w, -dx, -dy)
    assert cosim_loss(rep_a, rep_b, flow, mask).item() == pytest.approx(0, abs=1e-5)
    assert cosim_loss(rep_a, torch.rand(1, 1, h, w), flow, mask).item() > 0.05


def test_peaky_loss_prefers_peaks():
    flat = torch.full((1, 1, 64, 64), 0.5)
    peaks = torch.zeros(1, 1, 64, 64)
    peaks[..., 8::17, 8::17] = 1.0
    assert peaky_loss(peaks).item() < peaky_loss(flat).item()
    assert peaky_loss(flat).item() == pytest.approx(1.0)


def test_reliability_loss_rewards_matching_descriptors_and_gradients_flow():
    torch.manual_seed(0)
    h, w, dx, dy = 64, 64, 4, -3
    big = F.normalize(torch.randn(1, 16, h + 10, w + 10), dim=1)
    desc_a = big[..., 5 : 5 + h, 5 : 5 + w]
    desc_b = big[..., 5 - dy : 5 - dy + h, 5 - dx : 5 - dx + w]  # A(x, y) = B(x + dx, y + dy)
    flow, mask = _shift_flow(h, w, dx, dy)
    rel = torch.full((1, 1, h, w), 0.9, requires_grad=True)
    gen = torch.Generator().manual_seed(0)
    loss_good, ap_good = reliability_ap_loss(desc_a, desc_b, rel, flow, mask, gen)
    assert ap_good.item() > 0.95
    loss_good.backward()
    assert rel.grad is not None and rel.grad.abs().sum() > 0
    rand_b = F.normalize(torch.randn(1, 16, h, w), dim=1)
    loss_bad, ap_bad = reliability_ap_loss(desc_a, rand_b, rel, flow, mask, gen)
    assert ap_bad.item() < 0.5 and loss_bad.item() > loss_good.item()


def test_the_reliability_loss_reaches_the_image_border_only_when_asked():
    """APSampling.border: R2D2's 16 px leave the border's reliability untrained (why lburst-b5's
    keypoints avoid the borders); 0 trains it wherever the target lies inside B."""
    torch.manual_seed(3)
    h = w = 64
    desc = F.normalize(torch.randn(1, 8, h, w), dim=1)
    flow, mask = _shift_flow(h, w, 0, 0)
    ring = torch.ones(h, w, dtype=torch.bool)
    ring[16:-16, 16:-16] = False
    for border, trained in ((16, False), (0, True)):
        rel = torch.full((1, 1, h, w), 0.5, requires_grad=True)
        gen = torch.Generator().manual_seed(0)
        loss, _ = reliability_ap_loss(desc, desc, rel, flow, mask, gen, APSampling(border=border, query_stride=1))
        loss.backward()
        assert bool((rel.grad[0, 0][ring] != 0).any()) is trained
        # targets must keep the candidate disc inside B: the outer 7 px stay untrained
        assert not (rel.grad[0, 0, :7] != 0).any()


def test_a_batch_scores_each_query_against_its_own_images_distractors():
    """The batch's loss is the mean of each image's loss alone (equal query counts)."""
    torch.manual_seed(4)
    h = w = 40
    desc_a = F.normalize(torch.randn(3, 8, h, w), dim=1)
    desc_b = F.normalize(desc_a + 0.5 * torch.randn(3, 8, h, w), dim=1)
    rel = torch.rand(3, 1, h, w)
    flow, mask = _shift_flow(h, w, 0, 0, b=3)
    cfg = APSampling(border=8)
    batch_loss, batch_ap = reliability_ap_loss(desc_a, desc_b, rel, flow, mask, torch.Generator().manual_seed(5), cfg)
    alone = [
        reliability_ap_loss(
            desc_a[i : i + 1],
            desc_b[i : i + 1],
            rel[i : i + 1],
            flow[:1],
            mask[:1],
            torch.Generator().manual_seed(5),
            cfg,
        )
        for i in range(3)
    ]
    assert batch_loss.item() == pytest.approx(sum(x[0].item() for x in alone) / 3, abs=1e-6)
    assert batch_ap.item() == pytest.approx(sum(x[1].item() for x in alone) / 3, abs=1e-6)


def test_descriptor_gradients_flow_through_the_ap_loss():
    torch.manual_seed(1)
    h = w = 48
    desc_a = torch.randn(1, 8, h, w, requires_grad=True)
    desc_b = torch.randn(1, 8, h, w, requires_grad=True)
    flow, mask = _shift_flow(h, w, 0, 0)
    loss, _ = reliability_ap_loss(
        F.normalize(desc_a, dim=1),
        F.normalize(desc_b, dim=1),
        torch.full((1, 1, h, w), 0.5),
        flow,
        mask,
        None,
        APSampling(border=8),
    )
    loss.backward()
    assert desc_a.grad.abs().sum() > 0 and desc_b.grad.abs().sum() > 0


def test_collapsed_reliability_stops_descriptor_learning_unless_ap_is_weighted_in():
    """Why TrainConfig.ap_weight exists: with rel = 0 the R2D2 loss gives descriptors no gradient."""
    torch.manual_seed(2)
    h = w = 48
    desc_a = torch.randn(1, 8, h, w, requires_grad=True)
    desc_b = torch.randn(1, 8, h, w)
    flow, mask = _shift_flow(h, w, 0, 0)
    rel = torch.zeros(1, 1, h, w)
    loss, ap = reliability_ap_loss(
        F.normalize(desc_a, dim=1), F.normalize(desc_b, dim=1), rel, flow, mask, None, APSampling(border=8)
    )
    (grad,) = torch.autograd.grad(loss, desc_a, retain_graph=True)
    assert grad.abs().max() == 0
    (grad,) = torch.autograd.grad(loss + 0.25 * (1 - ap), desc_a)
    assert grad.abs().max() > 0


def test_logit_margin_loss_is_zero_inside_the_margin_and_pulls_saturated_logits_back():
    from lburst.train.losses import logit_margin_loss

    inside = torch.linspace(-4, 4, 50)
    assert logit_margin_loss(inside, 4.0) == 0
    z = torch.tensor([-19.0, -2.0, 9.0], requires_grad=True)
    loss = logit_margin_loss(z, 4.0)
    assert torch.isclose(loss, torch.tensor((15.0**2 + 5.0**2) / 3))
    loss.backward()
    assert z.grad[0] < 0 < z.grad[2] and z.grad[1] == 0  # descent moves -19 up and 9 down


def test_saturated_reliability_recovers_only_with_the_logit_margin_loss():
    """Why TrainConfig.rel_logit_weight exists: a saturated softmax passes no gradient."""
    from lburst.model.network import LBurstNet, NetConfig
    from lburst.train.losses import logit_margin_loss

    torch.manual_seed(0)
    net = LBurstNet(NetConfig(frames=1))
    x = torch.randn(1, 3, 32, 32)
    with torch.no_grad():
        net.clf.bias.copy_(torch.tensor([25.0, -25.0]))  # reliability ~ 1e-22: collapsed
    out = net(x, reliability_logits=True)
    z = out["reliability_logits"]
    assert torch.allclose(z, torch.log(out["reliability"]) - torch.log1p(-out["reliability"]), atol=1e-3, rtol=1e-4)
    rel_only = (0.5 - out["reliability"] * 0.3).mean()  # the reliability loss with AP 0.8 > base
    (g,) = torch.autograd.grad(rel_only, net.clf.bias, retain_graph=True)
    assert g.abs().max() < 1e-12
    (g,) = torch.autograd.grad(rel_only + 0.01 * logit_margin_loss(z), net.clf.bias)
    assert g[1] < -0.1  # descent raises the class-1 logit


def test_a_lower_base_keeps_pixels_reliable_whose_descriptors_still_match_under_noise():
    """TrainConfig.rel_base: descent raises reliability where AP passes the base, lowers it elsewhere."""
    torch.manual_seed(0)
    h, w, dx, dy = 64, 64, 2, 1
    big = F.normalize(torch.randn(1, 16, h + 10, w + 10), dim=1)
    desc_a = big[..., 5 : 5 + h, 5 : 5 + w]
    clean_b = big[..., 5 - dy : 5 - dy + h, 5 - dx : 5 - dx + w]
    desc_b = F.normalize(clean_b + 0.6 * torch.randn(1, 16, h, w), dim=1)  # noisy: AP between the bases
    flow, mask = _shift_flow(h, w, dx, dy)
    grads = {}
    for base in (0.5, 0.3):
        rel = torch.full((1, 1, h, w), 0.5, requires_grad=True)
        loss, ap = reliability_ap_loss(
            desc_a, desc_b, rel, flow, mask, torch.Generator().manual_seed(0), APSampling(base=base)
        )
        loss.backward()
        grads[base] = rel.grad.sum().item()
    assert 0.3 < ap.item() < 0.5
    assert grads[0.5] > 0 > grads[0.3]  # base 0.5: reliability goes down; base 0.3: up


def test_spread_loss_is_the_common_component_and_its_gradient_removes_it():
    gen = torch.Generator().manual_seed(0)
    spread = F.normalize(torch.randn(2, 128, 8, 8, generator=gen), dim=1)
    assert spread_loss(spread) < 0.01  # random unit vectors: no common component
    common = F.normalize(torch.randn(128, generator=gen), dim=0).view(1, 128, 1, 1)
    raw = (spread + 2 * common).requires_grad_(True)
    shared = F.normalize(raw, dim=1)
    mean = shared.mean(dim=(0, 2, 3))
    torch.testing.assert_close(spread_loss(shared), mean.square().sum())
    assert spread_loss(shared) > 0.5
    spread_loss(shared).backward()
    with torch.no_grad():  # one gradient step on the raw descriptors lowers it
        stepped = F.normalize(raw - 5 * raw.grad, dim=1)
    assert spread_loss(stepped) < spread_loss(shared.detach())
    # weighted: only the weighted pixels count
    mixed = torch.cat([spread, F.normalize(spread + 2 * common, dim=1)], dim=0)
    weight = torch.zeros(4, 1, 8, 8)
    weight[2:] = 1
    torch.testing.assert_close(spread_loss(mixed, weight), spread_loss(mixed[2:]))
    assert spread_loss(mixed, 1 - weight) < 0.01
