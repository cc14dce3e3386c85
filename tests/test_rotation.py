"""Views turned against each other: the pixel map of a turn, rotated benchmark sequences,
extraction at several rotations, and matching through the rotation sets."""

import numpy as np
import pytest
import skimage.data

from lburst import LBurst
from lburst.bench.metrics import project
from lburst.bench.sequences import Sequence, rotate_sequence
from lburst.matching import create
from lburst.methods import create as create_method
from lburst.rotation import map_points, rotate_image, rotation_map, turn_burst


@pytest.mark.parametrize("deg", [0, 90, 180, 270, -90, 450])
def test_quarter_turns_move_every_pixel_where_the_map_says(deg):
    image = np.random.default_rng(0).integers(0, 255, (5, 7, 3), dtype=np.uint8)
    turned, m = rotate_image(image, deg)
    ys, xs = np.mgrid[0:5, 0:7]
    points = np.c_[xs.ravel(), ys.ravel()]
    moved = map_points(points, m)
    assert np.array_equal(moved, np.rint(moved))
    q = moved.astype(int)
    assert turned.shape == ((7, 5, 3) if deg % 180 else (5, 7, 3))
    assert np.array_equal(turned[q[:, 1], q[:, 0]], image[points[:, 1], points[:, 0]])


def test_a_turn_of_90_is_counter_clockwise_as_displayed():
    image = np.zeros((4, 6), np.uint8)
    image[0, 5] = 255  # top right corner
    turned, _ = rotate_image(image, 90)
    assert turned[0, 0] == 255  # now top left


def test_other_angles_keep_the_whole_image_and_move_a_spot_where_the_map_says():
    image = np.zeros((60, 90), np.float32)
    image[10:13, 70:73] = 1.0  # a spot centred at (71, 11)
    turned, m = rotate_image(image, 30)
    assert turned.shape == rotation_map(30, image.shape)[1]
    assert turned.shape[0] >= 60 and turned.shape[1] >= 90
    ys, xs = np.nonzero(turned > 0.5)
    assert np.allclose([xs.mean(), ys.mean()], map_points([[71, 11]], m)[0], atol=0.5)
    with pytest.raises(ValueError, match="finite"):
        rotation_map(float("nan"), image.shape)


def test_rotated_sequence_homographies_land_on_the_same_content():
    rng = np.random.default_rng(1)
    image = rng.integers(0, 255, (40, 50, 3), dtype=np.uint8)
    shift = np.array([[1.0, 0, 3], [0, 1, 2], [0, 0, 1]])
    second = np.zeros_like(image)
    second[2:, 3:] = image[:-2, :-3]
    seq = Sequence("s", [image] + [second] * 5, [shift] * 5)
    turned = rotate_sequence(seq, 180)
    assert turned.images[0] is image
    points = np.array([[10, 10], [30, 20], [45, 5]])
    q = np.rint(project(turned.homographies[0], points)).astype(int)
    assert np.array_equal(turned.images[1][q[:, 1], q[:, 0]], image[points[:, 1], points[:, 0]])
    assert rotate_sequence(seq, 0) is seq


def _features(count, turns, rng):
    d = rng.normal(size=(count, 16)).astype(np.float32)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_matchers_pick_the_rotation_set_whose_descriptors_agree():
    rng = np.random.default_rng(2)
    upright = _features(50, 0, rng)
    a = {"keypoints": rng.random((50, 2), np.float32), "descriptors": upright}
    order = rng.permutation(50)
    sets = [_features(50, t, rng) for t in range(4)]
    sets[2] = upright[order] + 0.01 * rng.normal(size=(50, 16)).astype(np.float32)  # b's set turned by 180
    b = {
        "keypoints": rng.random((200, 2), np.float32),
        "descriptors": np.concatenate(sets).astype(np.float32),
        "rotations": np.repeat(np.arange(4, dtype=np.uint8), 50),
    }
    for spec in ("mnn", "ratio"):
        matches = create(spec)(a, b)
        assert len(matches) == 50
        assert np.array_equal(order[matches[:, 1] - 100], matches[:, 0])
        swapped = create(spec)(b, a)  # only the first has sets: each of its sets against the other
        assert np.array_equal(order[swapped[:, 0] - 100], swapped[:, 1])


@pytest.fixture(scope="module")
def lite():
    return LBurst.pretrained("lburst-b5-lite", runtime="torch", threads=1)


def _burst():
    image = skimage.data.astronaut()[96:352, 64:384]
    rng = np.random.default_rng(3)
    frames = [np.roll(image, (k, 2 * k), (0, 1)) for k in range(-2, 3)]
    return np.clip(np.stack(frames) + rng.normal(0, 10, (5, *image.shape)), 0, 255).astype(np.uint8)


def test_each_rotation_set_is_the_extraction_of_the_turned_burst_mapped_back(lite):
    burst = _burst()
    both = lite.extract(burst, top_k=500, rotations=2)
    assert set(np.unique(both["rotations"])) == {0, 180}
    upright = lite.extract(burst, top_k=500)
    first = both["rotations"] == 0
    assert np.array_equal(both["keypoints"][first], upright["keypoints"])
    turned = lite.extract(turn_burst(burst, 2), top_k=500)
    half, _ = rotation_map(180, burst.shape[1:3])
    back = both["rotations"] == 180
    assert np.allclose(map_points(both["keypoints"][back], half), turned["keypoints"], atol=1e-3)
    assert np.array_equal(both["descriptors"][back], turned["descriptors"])
    with pytest.raises(ValueError, match="rotations"):
        lite.extract(burst, rotations=3)


def test_views_turned_by_180_match_through_the_rotation_sets(lite):
    burst = _burst()
    half, _ = rotation_map(180, burst.shape[1:3])
    a = lite.extract(burst, top_k=500, rotations=2)
    b = lite.extract(turn_burst(burst, 2), top_k=500, rotations=2)
    matches = create("mnn")(a, b)
    errors = np.linalg.norm(map_points(a["keypoints"][matches[:, 0]], half) - b["keypoints"][matches[:, 1]], axis=1)
    assert len(matches) > 200 and np.mean(errors < 1.5) > 0.9
    plain = create("mnn")(lite.extract(burst, top_k=500), lite.extract(turn_burst(burst, 2), top_k=500))
    assert len(plain) < len(matches)


def test_method_spec_takes_rotations_and_refuses_others():
    assert create_method("lburst-lite,rotations=4,runtime=torch").rotations == 4
    with pytest.raises(ValueError, match="rotations must be one of 1, 2, 4, 8"):
        create_method("lburst-lite,rotations=3")


def test_views_turned_by_45_degrees_match_through_eight_rotation_sets(lite):
    burst = _burst()
    turned = np.stack([rotate_image(frame, 45, reflect=True)[0] for frame in burst])
    to_turned, _ = rotation_map(45, burst.shape[1:3])
    a = lite.extract(burst, top_k=500)
    b = lite.extract(turned, top_k=500, rotations=8)
    assert set(np.unique(b["rotations"])) == set(range(0, 360, 45))
    x, y = b["keypoints"].T
    h, w = turned.shape[1:3]
    assert (x >= -0.5).all() and (x <= w - 0.5).all() and (y >= -0.5).all() and (y <= h - 0.5).all()

    def correct(matches, fa, fb):
        e = np.linalg.norm(
            map_points(fa["keypoints"][matches[:, 0]], to_turned) - fb["keypoints"][matches[:, 1]], axis=1
        )
        return int((e < 2).sum()), float(np.mean(e < 2)) if len(e) else 0.0

    found, share = correct(create("mnn")(a, b), a, b)
    assert found > 50 and share > 0.6  # turned twice (45 and back), bilinear both times
    upright = lite.extract(turned, top_k=500)
    plain, _ = correct(create("mnn")(a, upright), a, upright)
    assert plain < found / 3


def test_the_set_is_chosen_on_the_strongest_keypoints_and_matched_whole(monkeypatch):
    from lburst import matching

    rng = np.random.default_rng(5)
    n = 1500
    upright = _features(n, 0, rng)
    a = {"descriptors": upright, "scores": rng.random(n, np.float32)}
    order = rng.permutation(n)
    sets = [_features(n, t, rng) for t in range(4)]
    sets[3] = upright[order] + 0.01 * rng.normal(size=upright.shape).astype(np.float32)
    b = {
        "descriptors": np.concatenate(sets).astype(np.float32),
        "scores": rng.random(4 * n, np.float32),
        "rotations": np.repeat(np.arange(0, 360, 90, dtype=np.uint16), n),
    }
    sizes = []
    real = matching.distinctive_matches
    monkeypatch.setattr(
        matching, "distinctive_matches", lambda da, db: sizes.append((len(da), len(db))) or real(da, db)
    )
    matches = create("mnn")(a, b)
    assert sizes == [(matching.CHOICE_KEYPOINTS, matching.CHOICE_KEYPOINTS)] * 4
    assert len(matches) == n and np.array_equal(order[matches[:, 1] - 3 * n], matches[:, 0])
    top = matching.strongest(a, np.arange(n), 10)
    assert np.array_equal(top, np.sort(np.argsort(-a["scores"])[:10]))
