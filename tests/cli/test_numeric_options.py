"""Every numeric command-line option is checked once, by lburst.numbers: finite, in range,
an integer where a count is meant, with an error that names the option (before, `--every 0`
was read as 10, `--fps nan` named keyframes `f000000_tnans`, `--sigma -5` ran, `--threads -3`
reached COLMAP's `Check failed`, `--workers 1000` started 1000 loaders)."""

import argparse
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import lburst
from lburst.burst.raw import Normalisation
from lburst.cli import main
from lburst.cli.numbers import integer, real
from lburst.numbers import check_integer, check_real

CLI = Path(lburst.__file__).parent / "cli"
EXAMPLES = int(os.environ.get("LBURST_HYPOTHESIS_EXAMPLES", "40"))  # `make test-slow`: 2000


def test_no_numeric_option_bypasses_the_checks():
    raw = [f"{p.name}: {m}" for p in CLI.glob("*.py") for m in re.findall(r"type=(?:int|float)\b", p.read_text())]
    assert raw == []


@pytest.mark.parametrize(
    "argv, option, message",
    [
        (["extract", "b", "--out", "o", "--every", "0"], "--every", "must be an integer >= 1, got 0"),
        (["extract", "b", "--out", "o", "--fps", "nan"], "--fps", "must be a finite number"),
        (["extract", "b", "--out", "o", "--fps", "inf"], "--fps", "must be a finite number"),
        (["extract", "b", "--out", "o", "--start", "-1"], "--start", ">= 0"),
        (["bench", "homography", "d", "--sigma", "-5"], "--sigma", ">= 0, got -5"),
        (["bench", "homography", "d", "--sigma", "nan"], "--sigma", "finite"),
        (["reconstruct", "s", "--out", "o", "--threads", "-3"], "--threads", ">= 1"),
        (["train", "--out", "r", "--time-budget", "-5"], "--time-budget", "> 0"),
        (["train", "--out", "r", "--workers", "1000"], "--workers", "<= 64"),
        (["train", "--out", "r", "--batch-size", "100000"], "--batch-size", "<= 512"),
        (["train", "--out", "r", "--steps", "2.5"], "--steps", "must be an integer"),
    ],
)
def test_a_bad_number_is_one_line_naming_the_option(argv, option, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"lburst {argv[0]}"), err  # no usage lines before it
    assert f"argument {option}" in err and message in err, err


@pytest.mark.parametrize("gain", ["inf", "nan", "-1", "0"])
def test_a_raw_gain_that_is_not_a_positive_finite_number_is_refused(gain):
    with pytest.raises(ValueError, match="raw gain must be"):
        Normalisation(gain=gain)


@settings(max_examples=EXAMPLES, deadline=None)
@given(
    st.one_of(
        st.text(max_size=12),
        st.integers(-(10**6), 10**6).map(str),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
    )
)
@example("0").via("the lower bound")
@example("1").via("the lower bound")
@example("1000").via("the upper bound")
@example("1001").via("the upper bound")
@example(" 1000 ").via("the upper bound")
def test_integer_options_accept_exactly_the_integers_in_range(text):
    parse = integer(1, 1000)
    try:
        value = int(text.strip())
    except ValueError:
        value = None
    if value is not None and 1 <= value <= 1000:
        assert parse(text) == value
    else:
        with pytest.raises(argparse.ArgumentTypeError, match="must be an integer >= 1 and <= 1000"):
            parse(text)


@settings(max_examples=EXAMPLES, deadline=None)
@given(st.one_of(st.text(max_size=12), st.floats(allow_nan=True, allow_infinity=True).map(repr)))
@example("0").via("the open lower bound")
@example("-0.0").via("the open lower bound")
@example("5e-324").via("the open lower bound")
@example("255").via("the upper bound")
@example(repr(math.nextafter(255, math.inf))).via("the upper bound")
@example("256").via("the upper bound")
def test_real_options_accept_exactly_the_finite_numbers_in_range(text):
    parse = real(0, 255, low_open=True)
    try:
        value = float(text.strip())
    except ValueError:
        value = None
    if value is not None and math.isfinite(value) and 0 < value <= 255:
        assert parse(text) == value
    else:
        with pytest.raises(argparse.ArgumentTypeError, match="must be a"):
            parse(text)


@settings(max_examples=EXAMPLES, deadline=None)
@given(
    st.one_of(
        st.integers(), st.floats(allow_nan=True, allow_infinity=True), st.booleans(), st.none(), st.text(max_size=4)
    )
)
@example(0).via("the bounds")
@example(-1).via("the bounds")
@example(10).via("the bounds")
@example(11).via("the bounds")
@example(1).via("the bounds")
@example(2).via("the bounds")
@example(-1.0).via("the bounds")
@example(1.0).via("the bounds")
@example(math.nextafter(1, math.inf)).via("the bounds")
@example(math.nextafter(-1, -math.inf)).via("the bounds")
@example(np.int64(10)).via("NumPy integers")
@example(np.float32(1.0)).via("NumPy floats")
def test_the_api_checks_agree_with_the_cli(value):
    numeric = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if numeric and isinstance(value, (int, np.integer)) and 0 <= value <= 10:
        assert check_integer(value, "n", 0, 10) == value
    else:
        with pytest.raises(ValueError, match="^n must be an integer"):
            check_integer(value, "n", 0, 10)
    if numeric and math.isfinite(value) and -1 <= value <= 1:
        assert check_real(value, "x", -1, 1) == float(value)
    else:
        with pytest.raises(ValueError, match="^x must be a"):
            check_real(value, "x", -1, 1)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"fps": math.nan}, "--fps must be a finite number"),
        ({"fps": math.inf}, "--fps must be a finite number"),
        ({"every": 0}, "--every must be an integer >= 1"),
        ({"every": 2.5}, "--every must be an integer"),
        ({"start": -1}, "--start must be an integer >= 0"),
        ({"max_frames": 0}, "max_frames must be an integer >= 1"),
    ],
)
def test_the_api_checks_recording_options_as_the_cli_does(options, message):
    from lburst.burst.sources import RecordingOptions

    with pytest.raises(ValueError, match=message):
        RecordingOptions(**options)


@settings(max_examples=EXAMPLES, deadline=None)
@given(
    st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=9, max_size=9),
    st.integers(0, 3),
)
def test_the_homography_reader_accepts_exactly_the_finite_invertible_matrices(values, rank_cut):
    from lburst.bench.sequences import check_homography

    h = np.array(values, np.float64).reshape(3, 3)
    if rank_cut and np.all(np.isfinite(h)):  # make some matrices singular on purpose
        h[rank_cut - 1] = 0.0
    usable = bool(np.all(np.isfinite(h)))
    if usable:
        with np.errstate(all="ignore"):
            s = np.linalg.svd(h, compute_uv=False)
        usable = s[0] > 0 and s[-1] > 1e-9 * s[0]
    if usable:
        assert check_homography(h, "H1to2p") is h
    else:
        with pytest.raises(ValueError, match=r"^H1to2p: homography (holds NaN or inf|is singular)"):
            check_homography(h, "H1to2p")


@settings(max_examples=EXAMPLES, deadline=None)
@given(
    st.lists(st.floats(-2, 2, allow_nan=False, width=64), min_size=3, max_size=3),
    st.sampled_from(["rotation", "scaled", "mirrored", "nan", "inf"]),
    st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=3, max_size=3),
    st.floats(allow_nan=True, allow_infinity=True, width=64),
)
def test_the_reference_reader_accepts_exactly_finite_rotations_and_positive_focal_lengths(
    tmp_path_factory, angles, kind, t, focal
):
    import json

    from scipy.spatial.transform import Rotation

    from lburst.sfm.reference import Reference

    R = Rotation.from_rotvec(angles).as_matrix()
    R = {"scaled": 1.5 * R, "mirrored": -R, "nan": R + np.nan, "inf": R + np.inf}.get(kind, R)
    data = {
        "source": "test",
        "camera": {"model": "PINHOLE", "width": 64, "height": 48, "params": [focal, focal, 32.0, 24.0]},
        "images": {"0000": {"R": R.tolist(), "t": t}},
    }
    path = tmp_path_factory.mktemp("ref") / "reference.json"
    path.write_text(json.dumps(data))
    usable = kind == "rotation" and all(math.isfinite(v) for v in t) and math.isfinite(focal) and focal > 0
    if usable:
        assert np.allclose(Reference.load(path).poses["0000"][0], R)
    else:
        with pytest.raises(ValueError, match=re.escape(str(path))):
            Reference.load(path)
