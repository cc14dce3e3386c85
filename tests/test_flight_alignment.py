"""scripts/flight_alignment.py: a burst's warps against the renderer's exact motion."""

from __future__ import annotations

import numpy as np

from lburst.burst.align import estimate_warps
from lburst.scenes import night_flight as nf


def test_the_common_frame_stays_put_and_an_affine_warp_follows_the_others_better(load_script):
    me = load_script("flight_alignment")
    cfg = nf.NightFlightConfig.daylight()  # the night flight, noise-free
    city = nf.make_city(cfg)
    positions, seen = me.true_positions(cfg, city, 1)
    grid = np.stack(np.meshgrid(np.arange(cfg.width), np.arange(cfg.height)), -1).reshape(-1, 2).astype(float)
    np.testing.assert_allclose(positions[2][seen], grid[seen], atol=1e-6)
    burst = np.clip(nf.render_burst(cfg, 1, city, noisy=False), 0, 255).astype(np.uint8)

    def worst(warp: str) -> float:
        warps = estimate_warps(burst, warp=warp)
        return max(
            float(np.median(np.linalg.norm(grid @ w[:, :2].T + w[:, 2] - q, axis=1)[seen]))
            for w, q in zip(warps, positions)
        )

    rigid, affine = worst("rigid"), worst("affine")
    assert affine < 0.5 * rigid, (rigid, affine)


def test_keypoints_are_counted_per_1000_pixels_of_each_residual_band(load_script):
    me = load_script("flight_alignment")
    residual = np.full((10, 100), 0.5)  # 1,000 px: 600 under 1.5 px, 200 at 2, 100 at 3, 100 at 9
    residual[6:8], residual[8], residual[9] = 2.0, 3.0, 9.0
    residual[0, 0] = np.nan  # no surface: counted nowhere
    keypoints = np.array([[1.0, 0.0], [2.0, 1.0], [5.0, 6.0], [5.0, 9.0], [6.0, 9.0], [0.0, 0.0]])
    found = me.keypoint_density({"a": keypoints}, {"a": residual})
    np.testing.assert_allclose(found["area_share"], [599 / 999, 200 / 999, 100 / 999, 100 / 999], atol=1e-4)
    np.testing.assert_allclose(found["keypoints_per_1000px"], [2000 / 599, 1000 / 200, 0, 2000 / 100], atol=1e-3)
