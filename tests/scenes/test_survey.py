"""The lawnmower survey of the synthetic night flight: parallel lines, each the reverse of
the last, joined by semicircular turns, flown at constant speed; and the arc path as before."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from lburst.cli import main as lburst_main
from lburst.scenes import night_flight as nf
from lburst.scenes.city import CityConfig

# small images and a coarse ground texture keep the tests fast
SMALL = dict(width=160, height=120, city=CityConfig(ground_texel=0.25, wall_texel=0.1, roof_texel=0.2))
# a heading that is not an axis, so that a mix-up of x and y shows
SURVEY = dict(survey_lines=4, line_length=40.0, line_spacing=20.0, heading_deg=30.0, burst_spacing=5.0)


def frame(cfg: nf.NightFlightConfig) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors on the ground along the heading and to its left."""
    psi = np.radians(cfg.heading_deg)
    return np.array([np.cos(psi), np.sin(psi)]), np.array([-np.sin(psi), np.cos(psi)])


def ground_axis(R: np.ndarray) -> np.ndarray:
    """The camera's optical axis projected on the ground, as a unit vector."""
    return R[2, :2] / np.linalg.norm(R[2, :2])


def test_survey_lines_are_straight_parallel_and_reversed():
    cfg = nf.NightFlightConfig(**SURVEY)
    forward, left = frame(cfg)
    length = 4 * 40.0 + 3 * np.pi * 20.0 / 2
    assert nf.path_length(cfg) == pytest.approx(length, abs=1e-9)
    assert cfg.n_bursts == int(length // 5.0) + 1 == 51
    ref = nf.reference(cfg)
    centres = np.array([ref.centers()[nf.burst_name(i)] for i in range(cfg.n_bursts)])
    np.testing.assert_allclose(centres[:, 2], cfg.altitude, atol=1e-9)
    lines = np.array([nf.survey_line(cfg, i) for i in range(cfg.n_bursts)])
    assert set(lines) == {-1, 0, 1, 2, 3}
    for i in range(4):
        on = centres[lines == i, :2]
        assert len(on) >= 8
        np.testing.assert_allclose(on @ left, i * cfg.line_spacing, atol=1e-6)  # sideways offset, to the left
        along = on @ forward
        assert along.min() > -1e-6 and along.max() < cfg.line_length + 1e-6
        steps = np.diff(along)
        np.testing.assert_allclose(steps, (-1) ** i * cfg.burst_spacing, atol=1e-6)  # odd lines flown back
        np.testing.assert_allclose(np.linalg.norm(np.diff(on, axis=0), axis=1), cfg.burst_spacing, atol=1e-6)
    # the bursts on a turn lie on the semicircle beyond the end of the line before
    for b in np.flatnonzero(lines == -1):
        i = (b * cfg.burst_spacing) // (cfg.line_length + np.pi * cfg.line_spacing / 2)
        end = (i % 2 == 0) * cfg.line_length
        centre = end * forward + (i + 0.5) * cfg.line_spacing * left
        offset = centres[b, :2] - centre
        assert np.linalg.norm(offset) == pytest.approx(cfg.line_spacing / 2, abs=1e-6)
        assert (offset @ forward) * (1 if i % 2 == 0 else -1) > 0
    assert ref.length == pytest.approx(np.linalg.norm(np.diff(centres, axis=0), axis=1).sum(), abs=1e-9)
    assert length - 2 * cfg.burst_spacing < ref.length < length


def test_the_whole_path_is_flown_at_constant_speed():
    """Dense samples of the camera centre are ``speed * dt`` apart (a semicircle of radius
    r shortens a 0.05 m chord by 1e-6 of it) and add up to the path length."""
    cfg = nf.NightFlightConfig(**SURVEY, speed=4.0)
    times = np.linspace(0.0, nf.path_length(cfg) / cfg.speed, 5001)
    dt = times[1]
    centres = np.array([-R.T @ t for R, t in (nf.camera_pose(cfg, time) for time in times)])
    steps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert 0.04 < cfg.speed * dt < 0.06
    assert steps.max() < cfg.speed * dt + 1e-9 and steps.min() > cfg.speed * dt * (1 - 1e-5)
    assert steps.sum() == pytest.approx(nf.path_length(cfg), abs=0.05)
    forward, left = frame(cfg)
    np.testing.assert_allclose(centres[-1, :2], 3 * cfg.line_spacing * left, atol=1e-6)  # L even: ends at x = 0
    r = cfg.line_spacing / 2
    assert (centres[:, :2] @ forward).max() == pytest.approx(cfg.line_length + r, abs=1e-4)
    assert (centres[:, :2] @ forward).min() == pytest.approx(-r, abs=1e-4)


def test_camera_looks_along_the_direction_of_travel():
    shaky = nf.NightFlightConfig(**SURVEY)
    steady = dataclasses.replace(shaky, shake_deg=0.0)
    forward, _ = frame(shaky)
    headings = {}
    common = nf.reference(shaky).centers()
    for b in range(shaky.n_bursts):
        line = nf.survey_line(shaky, b)
        along = common[nf.burst_name(b)][:2] @ forward
        if line < 0 or not 1.0 < along < shaky.line_length - 1.0:  # the whole burst on the line
            continue
        poses = nf.burst_poses(shaky, b)
        centres = np.array([-R.T @ t for R, t in poses])
        travel = (centres[-1] - centres[0])[:2]
        travel /= np.linalg.norm(travel)
        np.testing.assert_allclose(travel, (-1) ** line * forward, atol=1e-9)
        R = poses[len(poses) // 2][0]
        assert ground_axis(R) @ travel > np.cos(np.radians(2.0))  # the wobble is 0.3 deg
        assert np.degrees(np.arccos(-R[2, 2])) == pytest.approx(shaky.pitch_deg, abs=1.0)
        R = nf.reference(steady).poses[nf.burst_name(b)][0]
        np.testing.assert_allclose(ground_axis(R), (-1) ** line * forward, atol=1e-9)
        headings.setdefault(line, []).append(np.degrees(np.arctan2(R[2, 1], R[2, 0])))
    for line in range(1, 4):
        turn = (headings[line][0] - headings[line - 1][0]) % 360
        assert turn == pytest.approx(180.0, abs=1e-6)
        np.testing.assert_allclose(headings[line], headings[line][0], atol=1e-6)


# camera_pose of the arc path computed before surveys were added: (config, time, R, t)
ARC_POSES = [
    (
        {},
        0.0,
        [
            0.004000738255513385,
            -0.9999857351797057,
            -0.0035388600585730817,
            -0.8203173434090477,
            -0.0012579932881224263,
            -0.5719072246048387,
            0.5718946145888534,
            0.005191039394026121,
            -0.8203106746314328,
        ],
        [0.14155440234292327, 22.876288984193547, 32.81242698525731],
    ),
    (
        {},
        7.3,
        [
            0.16547610800937526,
            -0.9862111071616533,
            0.0023042979529022205,
            -0.8066558299570356,
            -0.13669206408144882,
            -0.5749970883521753,
            0.5673834943619666,
            0.09328950491957418,
            -0.8181522099202966,
        ],
        [-3.0390399881965466, 52.72479202161375, 11.827133304348308],
    ),
    (
        {"heading_deg": 40.0, "turn_deg": -120.0, "n_bursts": 6},
        3.21,
        [
            -0.14337559193478486,
            -0.9896469188132874,
            -0.006512735271495799,
            -0.8131106256799803,
            0.12154615251521968,
            -0.5692781773571318,
            0.5641759920837301,
            -0.07632502140264018,
            -0.8221191769228021,
        ],
        [6.639897790619069, 34.43500757557254, 24.757551368334262],
    ),
    (
        {"turn_deg": 0.0},
        5.5,
        [
            0.006920588989590073,
            -0.9999749980997581,
            -0.0014521099909377802,
            -0.8220498649891155,
            -0.0048623670133889465,
            -0.5693947460755184,
            0.569373449433159,
            0.0051342538324204165,
            -0.8220629626240133,
        ],
        [-0.13223179757621578, 45.38216113022141, 17.22474864554866],
    ),
    (
        {"turn_deg": 380.0},
        -0.1,
        [
            -0.024180163611431514,
            -0.9997056368148656,
            -0.0019898262005499335,
            -0.8176644052255151,
            0.02092219439312084,
            -0.5753148548481788,
            0.575187134865627,
            -0.01228419726154113,
            -0.8179296170103576,
        ],
        [0.07490407915114305, 22.603666866289508, 33.004827151702194],
    ),
]


@pytest.mark.parametrize("kwargs, time, R, t", ARC_POSES)
def test_arc_path_is_unchanged(kwargs, time, R, t):
    cfg = nf.NightFlightConfig(**kwargs)
    assert cfg.survey_lines == 0 and cfg.n_bursts == kwargs.get("n_bursts", 15)
    R_now, t_now = nf.camera_pose(cfg, time)
    np.testing.assert_allclose(R_now.ravel(), R, rtol=0, atol=1e-13)
    np.testing.assert_allclose(t_now, t, rtol=0, atol=1e-12)


def test_arc_configuration_and_reference_are_unchanged():
    cfg = nf.NightFlightConfig(n_bursts=4, width=160, height=120)
    assert nf.reference(cfg).length == pytest.approx(23.969549854889976, abs=1e-12)
    keys = list(nf.NightFlightConfig().to_dict())
    assert keys[0] == "n_bursts" and keys[-1] == "city" and not set(keys) & set(nf.SURVEY_FIELDS)
    with pytest.raises(ValueError, match="survey"):
        nf.survey_line(cfg, 0)


def test_rendered_survey_overlaps_across_lines_and_writes_its_lines(tmp_path):
    """At nadir, a burst on line 0 shares ground with the burst on line 1 closest to it,
    more than with any other burst on line 1, and nothing with line 2 (two spacings away)."""
    cfg = nf.NightFlightConfig(
        survey_lines=3, line_length=32.0, frames_per_burst=1, pitch_deg=0.0, shake_deg=0.0, **SMALL
    )
    out = tmp_path / "survey"
    ref = nf.make_night_flight(out, cfg, progress=False)
    lines = json.loads((out / nf.SURVEY_FILE).read_text())
    assert lines == {nf.burst_name(i): nf.survey_line(cfg, i) for i in range(cfg.n_bursts)}
    assert set(lines.values()) == {-1, 0, 1, 2} and len(lines) == cfg.n_bursts == 22
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == sorted(lines)
    centres = ref.centers()
    on = {i: [int(n) for n, line in lines.items() if line == i] for i in range(3)}
    city = nf.make_city(cfg)
    for a in on[0]:
        dist = [np.linalg.norm(centres[nf.burst_name(b)] - centres[nf.burst_name(a)]) for b in on[1]]
        overlaps = nf.view_overlaps(cfg, city, pairs=[(a, b) for b in on[1]])
        assert overlaps[np.argmin(dist)] > 0.25 and overlaps[np.argmin(dist)] == overlaps.max()
        far = on[2][np.argmin([np.linalg.norm(centres[nf.burst_name(b)] - centres[nf.burst_name(a)]) for b in on[2]])]
        assert nf.view_overlaps(cfg, city, pairs=[(a, far)])[0] < 0.02


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(survey_lines=1), "survey_lines"),
        (dict(survey_lines=-2), "survey_lines"),
        (dict(survey_lines=2.0), "survey_lines"),
        (dict(survey_lines=3, line_spacing=-4.0), "line_spacing"),
        (dict(survey_lines=3, line_spacing=0.0), "line_spacing"),
        (dict(survey_lines=3, line_length=float("nan")), "line_length"),
        (dict(line_length=float("inf")), "line_length"),
    ],
)
def test_bad_survey_values_are_refused(kwargs, field):
    with pytest.raises(ValueError, match=field):
        nf.NightFlightConfig(**kwargs)


def test_survey_configuration_round_trips():
    cfg = nf.NightFlightConfig(n_bursts=3, **SURVEY)
    assert cfg.n_bursts == 51  # a survey's path sets its bursts
    data = json.loads(json.dumps(cfg.to_dict()))
    assert data["survey_lines"] == 4 and data["line_spacing"] == 20.0
    assert nf.NightFlightConfig.from_dict(data) == cfg
    odd = nf.NightFlightConfig(line_length=50.0)  # an arc that keeps a non-default survey field
    assert nf.NightFlightConfig.from_dict(json.loads(json.dumps(odd.to_dict()))) == odd
    assert dataclasses.replace(cfg, burst_spacing=10.0).n_bursts == int(nf.path_length(cfg) // 10.0) + 1


def test_command_line_survey(tmp_path, capsys):
    out = tmp_path / "flight"
    argv = ["simulate", "flight", str(out), "--size", "48x32", "--frames", "1", "--daylight"]
    survey = ["--survey", "2", "--line-length", "16", "--line-spacing", "20", "--pitch", "10"]
    assert lburst_main(argv + survey) == 0
    printed = capsys.readouterr().out
    cfg = nf.NightFlightConfig.from_dict(json.loads((out / nf.CONFIG_FILE).read_text()))
    assert (cfg.survey_lines, cfg.line_length, cfg.line_spacing, cfg.pitch_deg) == (2, 16.0, 20.0, 10.0)
    assert cfg.n_bursts == 8 and "a survey of 2 lines, 8 bursts" in printed
    assert len(json.loads((out / nf.SURVEY_FILE).read_text())) == 8

    for extra in (["--survey", "3", "--loop"], ["--survey", "3", "--bursts", "5"]):
        assert lburst_main(argv + extra) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--survey" in err[0], err
    assert lburst_main(argv + ["--survey", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "argument --survey: must be an integer >= 2, got 1" in err[0], err
