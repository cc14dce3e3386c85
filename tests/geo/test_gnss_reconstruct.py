"""Positions the input carries, used by default: a scene of JPEG photos with EXIF GPS comes out
in metres east, north and up of the first fix, with a LAS cloud and GeoJSON cameras that GIS
tools place, and says so; --no-positions leaves it in COLMAP's frame.  Priors from a track at
keyframe times, with an SRT shorter than its video."""

import json

import numpy as np
import pytest

pytest.importorskip("pyproj")
pytest.importorskip("piexif")
pytest.importorskip("laspy")

from lburst.geo.fixes import Fix, GnssTrack  # noqa: E402
from lburst.scenes.flight_gnss import FLIGHT_ORIGIN  # noqa: E402
from lburst.scenes.night_flight import NightFlightConfig, reference  # noqa: E402
from lburst.sfm.positions import track_priors  # noqa: E402


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    """Five daylight photos of the flight, 256x192, as JPEG with each camera's exact position in EXIF."""
    from lburst.burst.io import read_image
    from lburst.geo.exif import write_gps_jpeg
    from lburst.scenes.night_flight import make_night_flight

    work = tmp_path_factory.mktemp("photos")
    cfg = NightFlightConfig.daylight(n_bursts=5, frames_per_burst=1, width=256, height=192, noise="none")
    make_night_flight(work / "bursts", cfg, progress=False)
    truth = {name: -R.T @ t for name, (R, t) in reference(cfg).poses.items()}
    scene = work / "scene"
    scene.mkdir()
    for name, centre in truth.items():
        lat, lon, alt = FLIGHT_ORIGIN.to_geodetic(centre)
        write_gps_jpeg(scene / f"{name}.jpg", read_image(work / "bursts" / name / "frame_000.png"), lat, lon, alt)
    return scene, truth


def _reconstruct(scene, out, *flags):
    from lburst.cli import main

    args = ["reconstruct", str(scene), "--method", "sift,max_features=1500", "--out", str(out), "--threads", "1"]
    assert main([*args, "--single-camera", *flags]) == 0
    from lburst.sfm.result import ReconstructionResult

    return ReconstructionResult.load(out / "result.json")


def test_exif_positions_are_held_by_default_and_the_model_is_georeferenced(photos, tmp_path, capsys):
    import laspy

    scene, truth = photos
    held = _reconstruct(scene, tmp_path / "held")
    assert held.registered == held.names
    first = truth["0000"]
    errors = [np.linalg.norm(-R.T @ t - (truth[n] - first)) for n, (R, t) in held.poses.items()]
    assert max(errors) < 0.5  # east, north, up of the first photo's fix: the flight's frame shifted
    positions = held.positions
    assert positions["images"] == 5 and positions["used"] and positions["in_frame"]
    assert positions["source"] == f"the EXIF GPS of 5 of 5 frames of {scene}"
    lat, lon, _ = FLIGHT_ORIGIN.to_geodetic(first)
    assert positions["origin"]["latitude"] == pytest.approx(lat, abs=1e-8)
    assert positions["origin"]["crs"] == "EPSG:32632" and positions["model_to_priors"]["max"] < 0.5
    las = laspy.read(tmp_path / "held" / "model.las")
    assert las.header.parse_crs().to_epsg() == 32632 and len(las.x) == positions["georeferenced"]["points3D"] > 100
    cameras = json.loads((tmp_path / "held" / "cameras.geojson").read_text())["features"]
    lon0, lat0, _ = cameras[0]["geometry"]["coordinates"]
    assert [c["properties"]["name"] for c in cameras] == held.names and abs(lat0 - lat) * 111_000 < 0.5
    said = "positions: 5 of 5 images from the EXIF GPS of 5 of 5 frames"
    assert said in (tmp_path / "held" / "report.md").read_text()
    printed = capsys.readouterr().out
    assert said in printed and "positions: the model in EPSG:32632: model.las" in printed


def test_no_positions_leaves_the_model_in_colmaps_frame(photos, tmp_path, capsys):
    scene, truth = photos
    first = truth["0000"]
    free = _reconstruct(scene, tmp_path / "free", "--no-positions")
    assert free.positions is None and not (tmp_path / "free" / "model.las").exists()
    assert min(np.linalg.norm(-R.T @ t - (truth[n] - first)) for n, (R, t) in free.poses.items()) > 2
    assert "positions:" not in capsys.readouterr().out


def test_keyframes_after_the_end_of_the_subtitles_have_no_prior_and_a_note():
    fixes = [Fix(47.0 + i * 1e-5, 8.0, 400.0, f"v.SRT at {i / 10:.3f} s", i / 10) for i in range(11)]
    names = [f"k{i}" for i in range(4)]
    priors = track_priors(GnssTrack("v.SRT (DJI subtitles, 11 fixes)", fixes), names, [0.0, 0.55, 1.0, 3.0], 2.0)
    assert priors.count == 3 and np.isnan(priors.centres[3]).all()
    np.testing.assert_allclose(priors.centres[1], [0, 5.5 * 1.1119, 0], atol=0.01)
    assert priors.notes == [
        "1 of 4 images lie outside v.SRT (DJI subtitles, 11 fixes)'s time or in a gap of it "
        "(its fixes from 0.000 s to 1.000 s), without a position: k3"
    ]


def test_a_platform_that_did_not_move_gives_no_priors_and_says_why():
    fixes = [Fix(47.0, 8.0, 400.0 + i * 0.01, f"f{i}", i / 10) for i in range(5)]
    priors = track_priors(GnssTrack("hover", fixes), ["a", "b"], [0.0, 0.4], 2.0)
    assert priors.count == 0 and "cannot place the model with priors of 2 m" in priors.notes[-1]
