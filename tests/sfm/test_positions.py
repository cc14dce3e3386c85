"""Position priors (GNSS): the positions file read strictly, and the priors COLMAP gets."""

import numpy as np
import pytest

from lburst.scenes.night_flight import NightFlightConfig, gnss_positions, reference
from lburst.sfm.colmap import ColmapJob, default_camera, pycolmap, write_database
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.positions import PositionsError, read_positions, write_positions

NAMES = ["0000", "0001", "0002"]


def test_a_written_file_reads_back_and_unnamed_images_have_none(tmp_path):
    path = tmp_path / "positions.txt"
    write_positions(path, {"0002": np.array([1.0, -2.5, 40.0]), "0000": np.array([0.0, 0.0, 40.125])})
    got = read_positions(path, NAMES)
    np.testing.assert_array_equal(got[0], [0.0, 0.0, 40.125])
    np.testing.assert_array_equal(got[2], [1.0, -2.5, 40.0])
    assert np.isnan(got[1]).all()


@pytest.mark.parametrize(
    "text, problem",
    [
        ("0000 1 2\n", ":1: expected 'NAME X Y Z', got 3 fields"),
        ("# header\n0000 1 2 north\n", ":2: 0000: X Y Z must be numbers"),
        ("0000 1 2 nan\n", ":1: 0000: X Y Z must be finite"),
        ("0000 1 2 3\n0000 1 2 3\n", ":2: 0000 is given twice"),
        ("0009 1 2 3\n", ": 0009 is not an image of the scene"),
        ("# nothing\n\n", ": no position in the file"),
    ],
)
def test_a_bad_file_is_refused_with_its_line_and_problem(tmp_path, text, problem):
    path = tmp_path / "positions.txt"
    path.write_text(text)
    with pytest.raises(PositionsError) as err:
        read_positions(path, NAMES)
    assert str(err.value).startswith(str(path)) and problem in str(err.value)


def test_a_missing_file_and_a_bad_std_are_refused(tmp_path):
    with pytest.raises(PositionsError, match="cannot read the positions file"):
        read_positions(tmp_path / "none.txt", NAMES)
    for std in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="standard deviation"):
            ReconstructOptions(position_std=std)


def test_the_simulated_receiver_is_the_truth_plus_seeded_noise():
    cfg = NightFlightConfig(n_bursts=40)
    truth = {name: -R.T @ t for name, (R, t) in reference(cfg).poses.items()}
    logged = gnss_positions(cfg, 2.0)
    error = np.array([logged[name] - truth[name] for name in truth])
    assert 1.5 < error.std() < 2.5 and abs(error.mean()) < 0.5
    again = gnss_positions(cfg, 2.0)
    assert all(np.array_equal(again[n], logged[n]) for n in truth)
    exact = gnss_positions(cfg, 0.0)
    assert all(np.allclose(exact[n], truth[n]) for n in truth)


def test_the_database_holds_each_given_prior_with_its_covariance(tmp_path):
    cams = [default_camera(320, 240)]
    job = ColmapJob(
        NAMES, str(tmp_path), cams, [0, 0, 0], positions=[[1.0, 2.0, 3.0], None, [4.0, 5.0, 6.0]], position_std=3.0
    )
    keypoints = [np.zeros((5, 2), np.float32)] * 3
    ids = write_database(tmp_path / "database.db", job, keypoints, np.zeros((0, 2), int), [])
    with pycolmap.Database.open(str(tmp_path / "database.db")) as db:
        priors = db.read_all_pose_priors()
        assert len(priors) == 2
        data = {p.corr_data_id: p for p in priors}
        for i in (0, 2):
            prior = data[db.read_image(ids[i]).data_id]
            np.testing.assert_array_equal(prior.position, job.positions[i])
            np.testing.assert_array_equal(prior.position_covariance, np.eye(3) * 9.0)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """Five single-frame bursts of the daylight flight, 256x192, and a receiver's log 0.5 m off."""
    from lburst.scenes.night_flight import make_night_flight

    out = tmp_path_factory.mktemp("flight")
    cfg = NightFlightConfig.daylight(n_bursts=5, frames_per_burst=1, width=256, height=192, noise="none")
    make_night_flight(out, cfg, progress=False)
    write_positions(out / "gnss.txt", gnss_positions(cfg, 0.5))
    return out, {name: -R.T @ t for name, (R, t) in reference(cfg).poses.items()}


def centre_errors(result, truth) -> np.ndarray:
    """Distance (m) of each registered camera, in the model's own frame, from its true centre."""
    return np.array(
        [np.linalg.norm(-np.asarray(R).T @ np.asarray(t) - truth[name]) for name, (R, t) in result.poses.items()]
    )


def test_with_priors_the_model_comes_out_in_their_frame(flight, tmp_path):
    from lburst.sfm import reconstruct_scene

    scene, truth = flight
    options = dict(progress=False, single_camera=True, extra={"max_num_trials": 2000})
    free = reconstruct_scene(scene, "sift,max_features=1500", tmp_path / "free", ReconstructOptions(**options))
    held = reconstruct_scene(
        scene,
        "sift,max_features=1500",
        tmp_path / "held",
        ReconstructOptions(**options, positions=scene / "gnss.txt", position_std=0.5),
    )
    assert free.registered == held.registered == free.names
    assert centre_errors(free, truth).min() > 5  # COLMAP's own frame: arbitrary origin, scale and heading
    assert centre_errors(held, truth).max() < 1.0  # the receiver's frame, within its noise
    assert held.metrics["ate_percent"] < 2.0


def test_priors_are_refused_with_the_global_mapper():
    with pytest.raises(ValueError, match="--positions needs the incremental mapper"):
        ReconstructOptions(mapper="global", positions="gnss.txt")


def test_a_file_may_name_the_images_as_the_outputs_do(tmp_path):
    path = tmp_path / "positions.txt"
    path.write_text("0000.png 1 2 3\n0002.JPG 4 5 6\n")
    got = read_positions(path, NAMES)
    np.testing.assert_array_equal(got[[0, 2]], [[1, 2, 3], [4, 5, 6]])
    path.write_text("0000.png 1 2 3\n0000 1 2 3\n")
    with pytest.raises(PositionsError, match="0000.png and 0000 are the same image"):
        read_positions(path, NAMES)
    path.write_text("0000.npz 1 2 3\n")
    with pytest.raises(PositionsError, match="0000.npz is not an image of the scene"):
        read_positions(path, NAMES)


def test_a_scene_without_images_is_refused_in_one_line(tmp_path):
    path = tmp_path / "positions.txt"
    path.write_text("0000 1 2 3\n")
    with pytest.raises(PositionsError, match="the scene has no images to give positions to"):
        read_positions(path, [])


@pytest.mark.parametrize(
    "rows, says",
    [
        ([(8.5417, 47.3769, 400.0), (8.5419, 47.3771, 401.0), (8.5421, 47.3773, 402.0)], "longitude and latitude"),
        ([(0.0, 0.0, 0.04), (0.008, 0.0, 0.04), (0.016, 0.001, 0.04)], "they span 0.016 m: kilometres"),
    ],
)
def test_positions_spread_below_their_std_are_refused_as_not_metres(tmp_path, rows, says):
    from lburst.sfm.positions import file_priors

    path = tmp_path / "positions.txt"
    path.write_text("".join(f"{n} {x} {y} {z}\n" for n, (x, y, z) in zip(NAMES, rows)))
    with pytest.raises(
        PositionsError, match=f"^{path}: the 3 positions cannot place the model with priors of 2 m"
    ) as err:
        file_priors(path, NAMES, 2.0)
    assert says in str(err.value)


def test_metres_spread_over_the_std_are_taken(tmp_path):
    from lburst.sfm.positions import file_priors

    path = tmp_path / "positions.txt"
    path.write_text("0000 0 0 40\n0001 8 0 40\n0002 16 1 40\n")
    priors = file_priors(path, NAMES, 2.0)
    assert priors.count == 3 and priors.origin is None and priors.source == f"the positions file {path}"


@pytest.mark.parametrize("std", [1e-9, 0.009, 1001.0])
def test_a_std_outside_a_centimetre_to_a_kilometre_is_refused(std):
    with pytest.raises(ValueError, match=r"standard deviation \(m\) must be a number >= 0.01 and <= 1000"):
        ReconstructOptions(position_std=std)
    assert ReconstructOptions(position_std=0.01).position_std == 0.01


def test_few_registered_images_with_a_prior_are_said_not_to_place_the_model():
    from lburst.sfm.positions import Priors, describe, prior_fit

    names = ["a", "b", "c", "d"]
    priors = Priors(np.array([[0, 0, 0], [8, 0, 0], [16, 0, 0], [24, 0, 0.0]]), "the positions file p.txt")
    fit = prior_fit(priors, names, {"a": np.zeros(3), "b": np.array([8.0, 0, 3])}, True, 2.0)
    assert fit["registered_with_prior"] == 2 and not fit["in_frame"]
    assert fit["model_to_priors"] == {"mean": 1.5, "rms": pytest.approx(np.sqrt(4.5)), "max": 3.0}
    lines = describe(fit)
    assert lines[0] == "positions: 4 of 4 images from the positions file p.txt; held by the mapper"
    assert "only 2 registered image(s) have a position, 3 are needed to place the model" in lines[-1]
    placed = prior_fit(priors, names, {n: c for n, c in zip(names, priors.centres)}, True, 2.0)
    assert placed["in_frame"] and placed["notes"] == []


def test_a_model_far_from_its_priors_is_flagged():
    from lburst.sfm.positions import Priors, prior_fit

    names = ["a", "b", "c"]
    priors = Priors(np.array([[0, 0, 0], [8, 0, 0], [16, 0, 0.0]]), "p")
    fit = prior_fit(priors, names, {n: c + [0, 30, 0] for n, c in zip(names, priors.centres)}, True, 2.0)
    assert "the cameras lie 30 m RMS from their positions" in fit["notes"][0]


def test_a_name_matching_no_image_is_refused_before_any_feature_is_computed(flight, tmp_path):
    from lburst.sfm import reconstruct_scene

    scene, _ = flight
    (tmp_path / "p.txt").write_text("0000.png 0 0 40\n0009 8 0 40\n")
    with pytest.raises(PositionsError, match="0009 is not an image of the scene"):
        reconstruct_scene(
            scene, "sift", tmp_path / "out", ReconstructOptions(progress=False, positions=tmp_path / "p.txt")
        )
    assert not (tmp_path / "out" / "features").exists() and not (tmp_path / "out" / "images").exists()


def test_priors_held_too_tightly_still_place_the_model_and_say_so(flight, tmp_path):
    """0.5 m of receiver noise held at 0.01 m: COLMAP's pose-prior alignment finds no inliers and
    keeps its own frame (43 m from the priors); a similarity fitted to them puts the model there."""
    from lburst.sfm import reconstruct_scene

    scene, truth = flight
    held = reconstruct_scene(
        scene,
        "sift,max_features=1500",
        tmp_path / "tight",
        ReconstructOptions(
            progress=False,
            single_camera=True,
            extra={"max_num_trials": 2000},
            positions=scene / "gnss.txt",
            position_std=0.01,
            num_threads=1,
        ),
    )
    assert held.registered == held.names
    assert centre_errors(held, truth).max() < 1.5
    assert held.positions["aligned_after_mapping"] and held.positions["model_to_priors"]["rms"] < 1.0
    assert "a similarity fitted to them put the model in their frame" in held.positions["notes"][-1]
