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
