"""The local metric frame of GNSS positions (east, north, up around the first fix, UTM zone
recorded), jumps a platform cannot fly, and positions at frame times."""

import numpy as np
import pytest

pytest.importorskip("pyproj")

from lburst.geo.fixes import Fix, GnssError, GnssTrack, check_coordinates, drop_jumps, positions_at  # noqa: E402
from lburst.geo.frame import GeoOrigin, utm_epsg  # noqa: E402


def test_east_north_up_round_trips_and_measures_metres():
    origin = GeoOrigin(47.3769, 8.5417, 408.0)
    enu = np.array([[1000.0, -250.0, 40.0], [0.0, 0.0, 0.0], [-3.5, 12.25, -1.0]])
    back = origin.to_geodetic(enu)
    np.testing.assert_allclose(origin.to_enu(back[:, 0], back[:, 1], back[:, 2]), enu, atol=1e-6)
    # 0.001 degrees of latitude is 111.2 m north (WGS 84 at 47 degrees), the Earth curving away below it
    north = origin.to_enu(47.3779, 8.5417, 408.0)
    assert north[0] == pytest.approx(0, abs=1e-6) and north[1] == pytest.approx(111.2, abs=0.1) and north[2] < 0


@pytest.mark.parametrize(
    "lat, lon, epsg",
    [
        (47.3769, 8.5417, 32632),
        (-33.87, 151.21, 32756),
        (60.39, 5.32, 32632),
        (78.2, 15.6, 32633),
        (0.0, -180.0, 32601),
    ],
)
def test_the_utm_zone_of_the_origin(lat, lon, epsg):
    assert utm_epsg(lat, lon) == epsg


def test_utm_coordinates_are_pyprojs():
    import pyproj

    origin = GeoOrigin(47.3769, 8.5417, 408.0)
    utm = origin.to_utm(np.array([[10.0, 20.0, 5.0]]))
    lat, lon, alt = origin.to_geodetic(np.array([10.0, 20.0, 5.0]))
    x, y = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:32632", always_xy=True).transform(lon, lat)
    np.testing.assert_allclose(utm[0], [x, y, alt], atol=1e-6)
    assert origin.to_json()["crs"] == "EPSG:32632"


@pytest.mark.parametrize(
    "lat, lon, alt, problem",
    [
        (90.5, 8.0, 0.0, "latitude 90.5 is outside -90..90"),
        (45.0, 181.0, 0.0, "longitude 181 is outside"),
        (45.0, 8.0, float("nan"), "the altitude must be a finite number"),
    ],
)
def test_coordinates_outside_the_earth_are_refused_naming_where(lat, lon, alt, problem):
    with pytest.raises(GnssError, match=f"^frame 7: {problem}"):
        check_coordinates(lat, lon, alt, "frame 7")


def _track(points, step=1.0):
    """Fixes 1 s apart, ``points`` metres north of 47 N, 8 E."""
    return GnssTrack("log", [Fix(47.0 + n / 111_195, 8.0, 400.0, f"frame {i}", i * step) for i, n in enumerate(points)])


def test_a_fix_farther_than_the_platform_can_fly_is_dropped_and_named():
    track = drop_jumps(_track([0, 5, 10, 900, 20, 25]))
    assert [f.where for f in track.fixes] == ["frame 0", "frame 1", "frame 2", "frame 4", "frame 5"]
    assert len(track.notes) == 1 and "1 fix(es) of log jump" in track.notes[0] and "frame 3 (900 m" in track.notes[0]


def test_a_bad_first_fix_does_not_throw_away_the_track():
    track = drop_jumps(_track([-5000, 5, 10, 15]))
    assert [f.where for f in track.fixes] == ["frame 1", "frame 2", "frame 3"]
    assert "frame 0" in track.notes[0]


def test_a_platform_flying_fast_keeps_every_fix():
    assert len(drop_jumps(_track([0, 50, 100, 150, 200])).fixes) == 5


def test_positions_interpolate_between_fixes_and_none_outside_or_across_a_gap():
    times = np.array([0.0, 1.0, 2.0, 6.0])
    points = np.array([[0, 0, 0], [10, 0, 0], [10, 20, 0], [10, 20, 4.0]])
    got = positions_at(times, points, np.array([0.5, 1.0, 1.5, 2.0, 3.0, 6.0, 6.05, 7.0, -0.05, -1.0]))
    np.testing.assert_allclose(got[:4], [[5, 0, 0], [10, 0, 0], [10, 10, 0], [10, 20, 0]])
    assert np.isnan(got[4]).all()  # 4 s between the fixes on either side: a dropout
    np.testing.assert_allclose(got[5:7], [[10, 20, 4], [10, 20, 4]])  # at the last fix, and within 0.1 s of it
    assert np.isnan(got[7]).all()  # after the track: an SRT shorter than its video
    np.testing.assert_allclose(got[8], [0, 0, 0])
    assert np.isnan(got[9]).all()
