"""In-burst motion beyond a translation: rotation, zoom and non-uniform flow."""

import numpy as np
import pytest

from lburst.burst.motion import BurstMotion, sample_motion
from lburst.simulate import simulate_burst


def _blob_image(h=120, w=160, at=(100.0, 40.0)):
    ys, xs = np.mgrid[0:h, 0:w]
    img = 255 * np.exp(-((xs - at[0]) ** 2 + (ys - at[1]) ** 2) / (2 * 2.0**2))
    return np.repeat(img[..., None], 3, 2).round().astype(np.uint8)


def _centroid(frame):
    g = frame[..., 0].astype(np.float64)
    ys, xs = np.mgrid[0 : g.shape[0], 0 : g.shape[1]]
    return np.array([(g * xs).sum() / g.sum(), (g * ys).sum() / g.sum()])


def test_common_frame_is_identity_and_translation_matches_the_shift():
    m = BurstMotion(shift=(1.5, -2.0))
    assert np.allclose(
        BurstMotion(rotation_deg=3, zoom=0.02, flow_px=2).source_points(0, (40, 30)),
        np.stack(np.mgrid[0:30, 0:40][::-1], -1),
    )
    pts = m.source_points(2, (40, 30))
    assert np.allclose(pts[10, 20], [20 - 3.0, 10 + 4.0])


@pytest.mark.parametrize(
    "motion",
    [
        BurstMotion(rotation_deg=1.0),
        BurstMotion(zoom=0.01),
        BurstMotion(shift=(1.0, 0.5), rotation_deg=-0.8, zoom=0.01),
    ],
)
def test_a_blob_moves_where_the_affine_part_sends_it(motion):
    img = _blob_image()
    burst = simulate_burst(img, 5, motion=motion)
    assert np.array_equal(burst[2], img)
    for i, k in enumerate(range(-2, 3)):
        expected = motion.affine(k, (160, 120)) @ np.array([100.0, 40.0, 1.0])
        assert np.allclose(_centroid(burst[i]), expected[:2], atol=0.15), (k, _centroid(burst[i]), expected)


def test_non_uniform_flow_is_smooth_seeded_and_grows_with_k():
    m = BurstMotion(flow_px=1.0, flow_seed=3)
    d = m.field((160, 120))
    assert d.shape == (120, 160, 2) and np.abs(d).max() > 0.2
    assert np.abs(np.diff(d, axis=1)).max() < 0.1  # smooth: under 0.1 px change per pixel
    assert np.array_equal(d, BurstMotion(flow_px=1.0, flow_seed=3).field((160, 120)))
    assert not np.array_equal(d, BurstMotion(flow_px=1.0, flow_seed=4).field((160, 120)))
    grid = np.stack(np.mgrid[0:120, 0:160][::-1], -1)
    assert np.allclose(grid - m.source_points(-2, (160, 120)), -2 * d, atol=1e-4)


def test_sample_motion_is_seeded_and_bounded():
    a = sample_motion(np.random.default_rng(1), 3.0, 1.0, 0.01, 1.0)
    b = sample_motion(np.random.default_rng(1), 3.0, 1.0, 0.01, 1.0)
    assert a == b
    assert max(map(abs, a.shift)) <= 3 and abs(a.rotation_deg) <= 1 and abs(a.zoom) <= 0.01
    assert sample_motion(np.random.default_rng(1), 2.0).is_translation


def test_frame_points_invert_source_points():
    m = BurstMotion(shift=(1.0, -0.5), rotation_deg=0.7, zoom=0.01, flow_px=1.0, flow_seed=5)
    size = (96, 64)
    for k in (-2, 1, 2):
        p = m.frame_points(k, size)
        # S_k(p) must give back the common-frame grid: sample S_k at p
        s = m.source_points(k, size)
        import cv2

        back = cv2.remap(s, p[..., 0], p[..., 1], cv2.INTER_LINEAR)
        grid = np.stack(np.mgrid[0:64, 0:96][::-1], -1)
        inside = (p[..., 0] > 1) & (p[..., 0] < 94) & (p[..., 1] > 1) & (p[..., 1] < 62)
        err = np.abs(back - grid)[inside]  # cv2.remap quantises positions to 1/32 px
        assert err.max() < 0.1 and err.mean() < 0.02
