"""COLMAP faults: the child dies with its parent, one process at a time uses a job folder,
an abort shows its ``Check failed:`` line, and a bad ``reference.json`` fails before COLMAP runs."""

import json
import os
import re
import signal
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest

from lburst.process import FolderInUse, folder_lock
from lburst.sfm import ReconstructionError, reconstruct_scene
from lburst.sfm.colmap import ColmapError, check_camera, failure_summary, run_job_subprocess
from lburst.sfm.options import ReconstructOptions

GLOG_ABORT = """I0101 10:00:00.000000 123 misc.cc:44] Feature matching
F0101 10:00:01.000000 123 camera.cc:120] Check failed: params_.size() == NumParams() (2 vs. 4)
*** Check failure stack trace: ***
    @     0x7f0000000001  google::LogMessage::Fail()
    @     0x7f0000000002  colmap::Camera::Verify()
    @     0x7f0000000003  (unknown)
"""


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie is dead
        return f.read().split(")")[-1].split()[0] != "Z"


def test_an_abort_shows_its_check_failed_line_not_stack_frames():
    assert failure_summary(GLOG_ABORT) == "Check failed: params_.size() == NumParams() (2 vs. 4)"
    assert (
        failure_summary("a\nTraceback (most recent call last):\n  x\nFileNotFoundError: job.json\n")
        == "FileNotFoundError: job.json"
    )


def test_a_failed_child_names_its_error(tmp_path):
    with pytest.raises(ColmapError, match="(?s)exited with 1.*FileNotFoundError"):
        run_job_subprocess(tmp_path)  # no job.json


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_the_child_dies_with_its_parent(sig):
    """The parent starts a child as run_job_subprocess does (``--parent``); killing the parent kills it."""
    child = (
        "import os, sys, time; from lburst.process import die_with_parent; "
        "die_with_parent(int(sys.argv[1])); time.sleep(120)"
    )
    parent = (
        "import os, subprocess, sys, time; "
        f"c = subprocess.Popen([sys.executable, '-c', {child!r}, str(os.getpid())]); "
        "print(c.pid, flush=True); time.sleep(120)"
    )
    proc = subprocess.Popen([sys.executable, "-c", parent], stdout=subprocess.PIPE, text=True)
    pid = int(proc.stdout.readline())
    time.sleep(1.0)  # the child has called prctl
    assert _alive(pid)
    proc.send_signal(sig)
    proc.wait(timeout=30)
    deadline = time.monotonic() + 10
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    if _alive(pid):
        os.kill(pid, signal.SIGKILL)
        pytest.fail("the child outlived its parent")


def test_one_process_at_a_time_holds_a_job_folder(tmp_path):
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from lburst.process import folder_lock\n"
            "with folder_lock(sys.argv[1]):\n print('held', flush=True); time.sleep(120)",
            str(tmp_path),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout.readline().strip() == "held"
    with pytest.raises(FolderInUse, match="in use by another lburst process"):
        with folder_lock(tmp_path):
            pass
    with pytest.raises(FolderInUse):
        run_job_subprocess(tmp_path)  # a second COLMAP on the same folder is refused
    holder.kill()
    holder.wait()
    with folder_lock(tmp_path):  # a killed holder leaves no lock behind
        pass


def test_camera_parameter_counts_are_checked():
    check_camera({"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 50.0, 32.0, 24.0]})
    for camera, problem in [
        ({"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 32.0]}, "takes 4"),
        ({"model": "NOPE", "width": 64, "height": 48, "params": [1.0]}, "unknown camera"),
        ({"model": "PINHOLE", "width": 0, "height": 48, "params": [1.0] * 4}, "positive"),
        ({"model": "PINHOLE", "width": 64, "height": 48}, "lacks"),
    ]:
        with pytest.raises(ValueError, match=problem):
            check_camera(camera)


def test_a_bad_reference_json_fails_before_colmap_runs(tmp_path):
    scene, out = tmp_path / "scene", tmp_path / "out"
    scene.mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        cv2.imwrite(str(scene / f"{i}.png"), rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
    pose = {"R": np.eye(3).tolist(), "t": [0.0, 0.0, 0.0]}
    reference = {
        "source": "test",
        "camera": {"model": "PINHOLE", "width": 64, "height": 48, "params": [50.0, 32.0]},
        "images": {str(i): pose for i in range(3)},
    }
    path = scene / "reference.json"
    path.write_text(json.dumps(reference))
    too_few = f"{path}: malformed reference file: camera.params needs at least 4 values, got [50.0, 32.0]"
    with pytest.raises(ReconstructionError, match=f"^{re.escape(too_few)}$"):  # the file named once, no repr
        reconstruct_scene(scene, "sift", out, ReconstructOptions(camera="reference", progress=False))
    assert not (out / "colmap" / "colmap.log").exists()
    reference["camera"]["params"] = [50.0, 50.0, 32.0, 24.0, 0.1]
    path.write_text(json.dumps(reference))
    too_many = f"{path}: camera of image '0': PINHOLE takes 4 params, got 5"
    with pytest.raises(ReconstructionError, match=f"^{re.escape(too_many)}$"):
        reconstruct_scene(scene, "sift", out, ReconstructOptions(camera="reference", progress=False))
    assert not (out / "colmap" / "colmap.log").exists()
    del reference["images"]
    path.write_text(json.dumps(reference))
    with pytest.raises(ReconstructionError, match=f"^{re.escape(str(path))}: malformed reference file: no images$"):
        reconstruct_scene(scene, "sift", out, ReconstructOptions(progress=False))
