"""Pairs from positions (each image with its k nearest images within a radius, as hloc's
pairs_from_poses), the default for a large scene with positions, and the views that the
positions show turned against the views they are paired with (lburst.sfm.turns)."""

import math

import numpy as np
import pytest

from lburst.errors import LBurstValueError
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.pairs import make_pairs, pair_plan, position_pairs
from lburst.sfm.positions import describe, write_positions
from lburst.sfm.turns import find_turns, headings, is_path, switch_on, turn_between, turned_pairs


def line(n: int, spacing: float = 8.0) -> np.ndarray:
    return np.array([[i * spacing, 0.0, 40.0] for i in range(n)])


def test_each_image_is_paired_with_its_k_nearest_by_position():
    # two parallel lines 24 m apart, 8 m between images, flown as a lawnmower (0-4 east, 5-9 west)
    east = line(5)
    west = line(5)[::-1] + [0, 24, 0]
    pairs = position_pairs(np.vstack([east, west]), neighbours=2, radius=100)
    assert pairs == sorted(set(pairs)) and all(i < j for i, j in pairs)
    assert (0, 1) in pairs and (0, 2) in pairs and (0, 9) not in pairs  # 8 and 16 m, not 24 m
    nearest = position_pairs(np.vstack([east, west]), neighbours=3, radius=100)
    assert (0, 9) in nearest and (4, 5) in nearest  # the image 24 m across on the other line


def test_the_radius_bounds_the_neighbours():
    centres = np.array([[0, 0, 0], [5, 0, 0], [100, 0, 0], [104, 0, 0.0]])
    assert position_pairs(centres, neighbours=3, radius=10) == [(0, 1), (2, 3)]
    assert position_pairs(centres, neighbours=3, radius=200) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]


def test_ties_go_to_the_lower_index_and_the_pairs_repeat():
    # 1, 2 and 3 lie 5 m from image 0, each 1 m from a companion (4, 5, 6) that is its own nearest
    centres = np.array([[0, 0, 0], [5, 0, 0], [-5, 0, 0], [0, 5, 0], [6, 0, 0], [-6, 0, 0], [0, 6, 0.0]])
    assert position_pairs(centres, neighbours=1, radius=50) == [(0, 1), (1, 4), (2, 5), (3, 6)]
    assert position_pairs(centres[[0, 3, 2, 1, 6, 5, 4]], 1, 50) == [(0, 1), (1, 4), (2, 5), (3, 6)]
    assert position_pairs(centres.copy(), 1, 50) == position_pairs(centres, 1, 50)


def test_images_without_a_position_are_paired_with_their_neighbours_in_order():
    centres = line(6)
    centres[3] = np.nan
    pairs = position_pairs(centres, neighbours=1, radius=100, overlap=1)
    assert pairs == [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5)]  # 3 with its neighbours in order, not 2-4 across it
    assert position_pairs(centres, neighbours=1, radius=100) == [(0, 1), (1, 2), (4, 5)]  # overlap 0: 3 alone


def test_pairs_by_position_need_positions_and_say_so():
    with pytest.raises(LBurstValueError, match=r"^--pairs positions needs the images' positions"):
        make_pairs(5, "positions", 1)
    lone = np.full((5, 3), np.nan)
    lone[0] = 0
    with pytest.raises(LBurstValueError, match="--pairs positions"):
        make_pairs(5, "positions", 1, lone)
    for bad in ({"neighbours": 0}, {"radius": 0.0}, {"radius": float("nan")}):
        with pytest.raises(LBurstValueError, match="--pair-"):
            ReconstructOptions(**bad)


def test_positions_are_the_default_for_a_large_scene_with_them():
    opts = ReconstructOptions()
    assert pair_plan(21, opts, recording=False, positions=True).mode == "positions"
    assert pair_plan(21, opts, recording=False, positions=False).mode == "sequential"
    assert pair_plan(20, opts, recording=False, positions=True).mode == "exhaustive"
    assert pair_plan(50, opts, recording=True, positions=True).mode == "sequential"
    plan = pair_plan(50, ReconstructOptions(pairs="positions", neighbours=4, radius=30.0), recording=False)
    assert (plan.mode, plan.neighbours, plan.radius) == ("positions", 4, 30.0)
    assert make_pairs(50, plan.mode, plan.overlap, line(50), plan) == position_pairs(line(50), 4, 30.0)


def test_headings_follow_the_travel_over_a_baseline_that_noise_does_not_turn():
    rng = np.random.default_rng(0)
    east, west = line(10), line(10)[::-1] + [0, 24, 0]
    centres = np.vstack([east, west])
    noisy = centres + rng.normal(0, 2.0, centres.shape)
    heading = headings(noisy, 8.0)
    assert all(turn_between(h, 0) < 30 for h in heading[1:8])  # along the lines, not at their ends
    assert all(turn_between(h, 180) < 30 for h in heading[12:19])
    dense = line(40, spacing=2.0)  # 2 m apart, as noisy as the receiver: image to image, the noise turns them
    dense_noisy = dense + rng.normal(0, 2.0, dense.shape)
    assert max(turn_between(h, 0) for h in headings(dense_noisy, 0.0)[4:-4]) > 30
    assert max(turn_between(h, 0) for h in headings(dense_noisy, 8.0)[4:-4]) < 30
    assert np.isnan(headings(np.zeros((4, 3)), 1.0)).all()  # a platform that did not move has no heading
    assert turn_between(170, -170) == pytest.approx(20) and turn_between(0, 180) == pytest.approx(180)


def test_pairs_turned_by_over_90_degrees_are_found():
    heading = np.array([0.0, 10.0, 95.0, 185.0, np.nan])
    assert turned_pairs(heading, [(0, 1), (0, 2), (1, 3), (0, 3), (3, 4)]) == [(0, 2), (1, 3), (0, 3)]
    assert turned_pairs(heading, [(0, 1), (0, 2), (0, 3)], limit=100) == [(0, 3)]  # 95 degrees is not over 100
    # a lawnmower's lines: the pairs across them are turned, those along a line are not
    centres = np.vstack([line(10), line(10)[::-1] + [0, 24, 0]])
    pairs = position_pairs(centres, 4, 100)
    across = [(i, j) for i, j in pairs if (i < 10) != (j < 10)]
    assert across == [(0, 19), (1, 18), (8, 11), (9, 10)]
    # 9 and 10 end and start the lines: both head partly across (24 m across, 8 m along), 37 degrees apart
    assert turned_pairs(headings(centres, 8.0), pairs) == [(0, 19), (1, 18), (8, 11)]
    found = find_turns(centres, pairs, std=2.0)
    assert (found["turned_pairs"], found["of"], found["rotations"]) == (3, len(pairs), None)
    # a gentle arc (30 degrees over the flight) and a straight line turn nothing
    arc = np.array([[100 * math.sin(a), 100 * (1 - math.cos(a)), 40] for a in np.radians(np.linspace(0, 30, 20))])
    assert find_turns(arc, position_pairs(arc, 6, 100), std=2.0) is None
    assert find_turns(line(20), position_pairs(line(20), 6, 100), std=2.0) is None


def test_a_photo_set_in_no_order_has_no_headings_to_turn():
    centres = np.vstack([line(10), line(10)[::-1] + [0, 24, 0]])
    assert is_path(centres)
    shuffled = centres[np.random.default_rng(1).permutation(len(centres))]
    assert not is_path(shuffled)
    assert find_turns(shuffled, position_pairs(shuffled, 4, 100), std=2.0) is None
    assert find_turns(centres, position_pairs(centres, 4, 100), std=2.0) is not None


def test_the_report_says_when_rotation_sets_were_switched_on():
    found = {"turned_pairs": 7, "of": 30, "limit_deg": 90.0, "rotations": None}
    on = switch_on(found, "lburst-lite", rotated=True, has_sets=True)
    data = {"source": "f", "images": 3, "of": 3, "used": True, "turns": on}
    assert (
        "positions: 7 of 30 pairs join views turned by over 90 degrees: rotation sets on (rotations=2"
        in describe(data)[1]
    )
    kept = switch_on(found, "lburst,rotations=1", rotated=False, has_sets=True)
    assert kept["rotations"] is None and "sets its own rotations" in describe({**data, "turns": kept})[1]
    assert "has no rotation sets" in switch_on(found, "sift", rotated=False, has_sets=False)["note"]


def test_a_positions_file_round_trip_keeps_the_pairs(tmp_path):
    from lburst.sfm.positions import read_positions

    centres = np.vstack([line(10), line(10)[::-1] + [0, 24, 0]])
    names = [f"{i:04d}" for i in range(20)]
    write_positions(tmp_path / "p.txt", dict(zip(names, centres)))
    assert position_pairs(read_positions(tmp_path / "p.txt", names), 4, 100) == position_pairs(centres, 4, 100)


def test_a_receivers_noise_turns_no_pair_of_the_dense_loop():
    """The 1000 keyframes 2.4 m apart of docs/large_surveys.md, with 2 m of noise on each coordinate:
    headings image to image turn by up to 180 degrees; over 16 m none is turned against its pairs."""
    from lburst.scenes.night_flight import NightFlightConfig, gnss_positions

    cfg = NightFlightConfig(n_bursts=1000, burst_spacing=2392 / 999, turn_deg=380.0, width=320, height=240)
    gnss = gnss_positions(cfg, 2.0)
    centres = np.array([gnss[name] for name in sorted(gnss)])
    pairs = position_pairs(centres, 10, 100)
    assert turned_pairs(headings(centres, 0.0), pairs)  # the noise alone turns pairs image to image
    assert turned_pairs(headings(centres, 8.0), pairs) == [] and find_turns(centres, pairs, std=2.0) is None
