"""Sub-pixel keypoints (``subpixel=true``): the parabola vertex of each repeatability peak."""

import numpy as np
import pytest
import torch

from lburst.methods import create
from lburst.model.extractor import LBurst, subpixel_offsets
from lburst.model.network import LBurstNet, NetConfig, save_checkpoint


def _peak_map(h, w, y0, x0, shape):
    yy, xx = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    if shape == "parabola":
        rep = 1 - 0.03 * (yy - y0) ** 2 - 0.05 * (xx - x0) ** 2
    else:
        rep = torch.exp(-((yy - y0) ** 2 + (xx - x0) ** 2) / (2 * 1.5**2))
    return rep[None, None]


@pytest.mark.parametrize("y0, x0", [(10.3, 7.8), (4.5, 12.0), (8.0, 8.49)])
def test_the_vertex_of_a_sampled_parabola_is_found_exactly(y0, x0):
    rep = _peak_map(20, 24, y0, x0, "parabola")
    y, x = torch.tensor([round(y0)]), torch.tensor([round(x0)])
    dy, dx = subpixel_offsets(rep, y, x)
    assert float(y + dy) == pytest.approx(y0, abs=1e-5) and float(x + dx) == pytest.approx(x0, abs=1e-5)


def test_a_gaussian_peak_is_found_within_a_twentieth_of_a_pixel():
    rng = np.random.default_rng(3)
    for y0, x0 in rng.uniform(5, 15, (20, 2)):
        rep = _peak_map(20, 20, y0, x0, "gaussian")
        y, x = torch.tensor([round(y0)]), torch.tensor([round(x0)])
        dy, dx = subpixel_offsets(rep, y, x)
        before = max(abs(round(y0) - y0), abs(round(x0) - x0))
        after = max(abs(float(y + dy) - y0), abs(float(x + dx) - x0))
        assert after < 0.05 and (before < 0.05 or after < before / 3)


def test_peaks_on_the_border_or_on_a_plateau_keep_their_pixel():
    rep = torch.zeros(1, 1, 6, 6)
    rep[0, 0, 0, 3] = 1.0  # on the top border: no neighbour above
    rep[0, 0, 0, 2] = 0.5
    rep[0, 0, 3, 5] = 1.0  # on the right border
    rep[0, 0, 3, 4] = 0.8
    rep[0, 0, 2:5, 1] = 0.7  # flat along y
    dy, dx = subpixel_offsets(rep, torch.tensor([0, 3, 3]), torch.tensor([3, 5, 1]))
    assert dy[0] == 0 and dx[0] < 0  # x still refined towards the brighter left neighbour
    assert dx[1] == 0 and dy[1] == 0
    assert dy[2] == 0


def test_extraction_moves_keypoints_by_at_most_half_a_level_pixel_and_keeps_descriptors(tmp_path):
    torch.manual_seed(0)
    model = LBurst(LBurstNet(NetConfig(frames=1)).eval())
    image = np.random.default_rng(0).integers(0, 256, (300, 400, 3), dtype=np.uint8)
    plain = model.extract(image, rel_thr=0, rep_thr=0, top_k=None)
    fine = model.extract(image, rel_thr=0, rep_thr=0, top_k=None, subpixel=True)
    assert np.array_equal(plain["descriptors"], fine["descriptors"])
    assert np.array_equal(plain["scales"], fine["scales"])
    moved = np.abs(fine["keypoints"] - plain["keypoints"])
    level_pixel = plain["scales"][:, None] / 32  # full-resolution pixels per level pixel
    assert (moved <= 0.51 * level_pixel).all()  # level sizes are rounded: 1 % slack
    assert (moved > 1e-3).mean() > 0.5  # most peaks are not exactly on a pixel centre

    save_checkpoint(LBurstNet(NetConfig(frames=1)), tmp_path / "net.pt")
    assert create(f"lburst:{tmp_path / 'net.pt'},subpixel=true").options["subpixel"] is True
