"""Matching metrics of the homography benchmark on hand-computed cases."""

import numpy as np
import pytest

from lburst.bench.metrics import match_errors, mma, repeatability, rotation_deg

SHIFT = np.array([[1, 0, 10.0], [0, 1, -5.0], [0, 0, 1]])


def test_mma_counts_matches_within_each_threshold():
    kp1 = np.array([[10, 10], [20, 20], [30, 30], [40, 40]], float)
    # true positions: (20, 5), (30, 15), (40, 25), (50, 35); errors 0.5, 2, 4, 20
    kp2 = np.array([[20.5, 5], [30, 17], [40, 29], [70, 35]], float)
    errors = match_errors(SHIFT, kp1, kp2, np.array([[0, 0], [1, 1], [2, 2], [3, 3]]))
    np.testing.assert_allclose(errors, [0.5, 2, 4, 20])
    np.testing.assert_allclose(mma(errors, (1, 3, 5, 10, 20)), [0.25, 0.5, 0.75, 0.75, 1.0])
    assert mma(np.zeros(0), (1, 3)).tolist() == [0, 0]


def test_repeatability_ignores_points_projecting_outside_and_averages_both_ways():
    kp1 = np.array([[10, 10], [50, 50], [95, 10]], float)  # (95, 10) -> (105, 5): outside a 100-wide image 2
    kp2 = np.array([[21, 5], [60, 48], [80, 80]], float)
    # 1 -> 2: of the 2 inside, (10,10)->(20,5) has (21,5) at 1 px; (50,50)->(60,45) nearest (60,48) at 3 px
    # 2 -> 1: (21,5)->(11,10) ok, (60,48)->(50,53) 3 px ok, (80,80)->(70,85) far from all
    rep = repeatability(SHIFT, kp1, kp2, (100, 100), (100, 100), threshold=3)
    assert rep == pytest.approx((2 / 2 + 2 / 3) / 2)
    assert repeatability(SHIFT, kp1, kp2, (100, 100), (100, 100), threshold=2) == pytest.approx((1 / 2 + 1 / 3) / 2)


def test_rotation_of_a_homography():
    angle = np.radians(30)
    rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    assert rotation_deg(rot, (100, 200)) == pytest.approx(30, abs=1e-6)
    assert rotation_deg(SHIFT, (100, 200)) == pytest.approx(0, abs=1e-9)
