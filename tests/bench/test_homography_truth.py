"""Ground-truth homographies are validated where they are read: NaN, inf, all-zero or
rank-2 matrices are refused with an error that names the file, by the reader and by
`lburst bench homography` (which before averaged a NaN sequence in with the others)."""

import cv2
import numpy as np
import pytest

from lburst.bench.sequences import read_sequence
from lburst.cli import main

BAD = {
    "nan": np.array([[1.0, 0, np.nan], [0, 1, 0], [0, 0, 1]]),
    "inf": np.array([[1.0, 0, 0], [0, np.inf, 0], [0, 0, 1]]),
    "zero": np.zeros((3, 3)),
    "rank2": np.array([[1.0, 2, 3], [2, 4, 6], [0, 0, 1]]),
}


def _sequence(folder, h3):
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    for i in range(1, 7):
        cv2.imwrite(str(folder / f"img{i}.png"), rng.integers(0, 256, (64, 80, 3), dtype=np.uint8))
    for k in range(2, 7):
        np.savetxt(folder / f"H1to{k}p", h3 if k == 3 else np.eye(3))
    return folder


@pytest.mark.parametrize("kind", sorted(BAD))
def test_a_broken_homography_is_refused_naming_the_file(tmp_path, kind):
    folder = _sequence(tmp_path / "seq", BAD[kind])
    with pytest.raises(ValueError, match=r"H1to3p: homography (holds NaN or inf|is singular)"):
        read_sequence(folder)


@pytest.mark.parametrize("kind", ["nan", "rank2"])
def test_bench_homography_stops_on_it_in_one_line(tmp_path, capsys, kind):
    _sequence(tmp_path / "data" / "good", np.eye(3))
    _sequence(tmp_path / "data" / "broken", BAD[kind])
    code = main(
        [
            "bench",
            "homography",
            str(tmp_path / "data"),
            "--methods",
            "orb",
            "--sigma",
            "0",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    err = capsys.readouterr().err
    assert code != 0 and "Traceback" not in err
    errors = [line for line in err.replace("\r", "\n").splitlines() if "error:" in line]
    assert len(errors) == 1 and "broken/H1to3p: homography" in errors[0], err
    assert "lburst bench homography: error: " in errors[0] and code == 2, err  # after an unfinished progress bar


def test_a_good_homography_still_reads(tmp_path):
    h = np.array([[0.9, -0.1, 5.0], [0.1, 0.9, -3.0], [1e-4, 0, 1]])
    assert np.allclose(read_sequence(_sequence(tmp_path / "seq", h)).homographies[1], h)
