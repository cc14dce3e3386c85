"""File names that are not valid UTF-8: images are read and written through bytes (OpenCV's
``imread``/``imwrite`` crash the process on such a name), and APIs that need a path refuse them."""

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lburst.burst.io import BurstError, load_burst, opencv_path, save_burst

BAD = os.fsdecode(b"bad\xffname")  # a lone surrogate in the str
RUN_CLI = "import sys; from lburst.cli import main; sys.exit(main(sys.argv[1:]))"


def _frames(n=3, h=40, w=48):
    return np.random.default_rng(0).integers(0, 255, (n, h, w, 3), dtype=np.uint8)


def test_burst_round_trip_in_a_folder_whose_name_is_not_utf8(tmp_path):
    folder = tmp_path / BAD
    save_burst(_frames(), folder)
    np.testing.assert_array_equal(load_burst(folder), _frames())


def test_video_with_a_name_that_is_not_utf8_is_refused_with_a_burst_error(tmp_path):
    path = tmp_path / f"{BAD}.avi"
    path.write_bytes(b"not really a video")
    with pytest.raises(BurstError, match="not valid UTF-8"):
        load_burst(path)
    with pytest.raises(BurstError, match="not valid UTF-8"):
        opencv_path(path)


def test_extract_on_a_folder_whose_name_is_not_utf8_does_not_crash(tmp_path):
    folder = tmp_path / BAD
    save_burst(_frames(), folder)
    out = tmp_path / f"out{BAD}"
    proc = subprocess.run(
        [sys.executable, "-c", RUN_CLI, "extract", os.fsencode(folder), "--out", os.fsencode(out), "--method", "sift"],
        capture_output=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr.decode(errors="replace")[-2000:]
    assert len(np.load(out / f"{BAD}.npz")["keypoints"]) > 0


def test_no_module_hands_opencv_a_raw_path():
    """Only :mod:`lburst.burst.io` calls OpenCV with a file name, and only through ``opencv_path``."""
    root = Path(__file__).resolve().parents[2] / "lburst"
    raw = re.compile(r"cv2\.(imread|imwrite|imreadmulti|VideoCapture|VideoWriter)\((?!opencv_path\()")
    offenders = [
        f"{path.relative_to(root)}:{n}"
        for path in root.rglob("*.py")
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if raw.search(line)
    ]
    assert not offenders
