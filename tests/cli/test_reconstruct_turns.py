"""`lburst reconstruct` on a survey whose positions show its lines flown both ways: the learned
method extracts with rotation sets, and stdout, report.md and result.json say so."""

import json

import pytest

from lburst.scenes.night_flight import NightFlightConfig, gnss_positions
from lburst.sfm.positions import write_positions


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    """Two survey lines of 24 m, 16 m apart, flown both ways: 10 daylight bursts of 5 frames, 256x192."""
    from lburst.scenes.night_flight import make_night_flight

    out = tmp_path_factory.mktemp("survey")
    cfg = NightFlightConfig.daylight(
        survey_lines=2, line_length=24.0, line_spacing=16.0, frames_per_burst=5, width=256, height=192, noise="none"
    )
    make_night_flight(out, cfg, progress=False)
    write_positions(out / "gnss.txt", gnss_positions(cfg, 0.5))
    return out


@pytest.mark.slow
def test_turned_pairs_switch_the_rotation_sets_on_and_the_run_says_so(survey, tmp_path, capsys):
    from lburst.cli import main

    out = tmp_path / "out"
    args = ["reconstruct", str(survey), "--method", "lburst-lite,top_k=600", "--out", str(out), "--threads", "1"]
    main([*args, "--positions", str(survey / "gnss.txt")])  # its exit status is the model's checks'
    captured = capsys.readouterr()
    said = "pairs join views turned by over 90 degrees: rotation sets on (rotations=2"
    assert said in captured.err  # as the run decides, before the features
    result = json.loads((out / "result.json").read_text())
    assert result["method"] == "lburst-lite,top_k=600,rotations=2"
    turns = result["positions"]["turns"]
    assert turns["rotations"] == 2 and 0 < turns["turned_pairs"] < turns["of"] == result["metrics"]["pairs"]
    assert said in captured.out and said in (out / "report.md").read_text()


def test_pairs_by_position_without_positions_is_one_line_before_any_feature(survey, tmp_path, capsys):
    from lburst.cli import main

    out = tmp_path / "out"
    assert main(["reconstruct", str(survey), "--method", "sift", "--out", str(out), "--pairs", "positions"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "lburst reconstruct: error: --pairs positions needs the images' positions (--positions FILE, or an input "
        "that carries them: EXIF GPS, a DJI .SRT, a bag's NavSatFix), and at least 2 images have one"
    ]
    assert not (out / "features").exists() and not (out / "images").exists()
