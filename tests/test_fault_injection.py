"""Fault injection: ``lburst extract`` and ``lburst reconstruct`` killed with SIGKILL at
random points (seeded), then run again to the end, give the outputs of a run that was
never interrupted: the same features (``.npz`` and ``features.h5``), images, registered
images, metrics, poses and model files, and no temporary file left behind.

Each kill comes a random time after the command has written its first file into its output
folder (its work has begun: the imports and the method are loaded), drawn up to the length
of that work in an uninterrupted run (the first kill in its first half, so that it lands
before the end: a test in which no run was killed fails).  Only processes these tests start
are signalled: the command itself, and at the end anything left in the session it was started
in.  COLMAP runs on one thread, so that its results repeat.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pycolmap")

LBURST = [sys.executable, "-c", "import sys; from lburst.cli import main; sys.exit(main())"]
TIMEOUT_S = 600.0


def _environment() -> dict[str, str]:
    """One thread for torch and OpenCV in the commands."""
    return {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENCV_FOR_THREADS_NUM": "1"}


def _wrote_since(folder: Path, since: float) -> bool:
    """Whether a file under ``folder`` was written at or after ``since`` (``time.time()``)."""
    try:
        return any(p.stat().st_mtime >= since for p in folder.rglob("*") if p.is_file())
    except FileNotFoundError:  # a temporary renamed while we looked
        return False


def _end_session(proc: subprocess.Popen) -> None:
    """SIGKILL whatever is left in the session ``proc`` was started in (its pid is the session's id)."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:  # the COLMAP child dies with its parent: give it a moment
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.05)
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def _run(args: list[str], out: Path, kill_after: float | None = None) -> tuple[int, float]:
    """Run ``lburst ARGS`` in a session of its own; with ``kill_after``, SIGKILL it that many
    seconds after it has written its first file into ``out``.  Returns its exit status and the
    seconds from that first file to its end."""
    since = time.time() - 0.01  # file times may round down
    proc = subprocess.Popen(
        [*LBURST, *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_environment(), start_new_session=True
    )
    err: list[bytes] = []
    reader = threading.Thread(target=lambda: err.extend(iter(lambda: proc.stderr.read1(4096), b"")), daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + TIMEOUT_S
        while not _wrote_since(out, since) and proc.poll() is None:
            assert time.monotonic() < deadline, f"lburst {args[0]} did not start its work"
            time.sleep(0.005)
        began = time.monotonic()
        if kill_after is not None:
            time.sleep(kill_after)
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=TIMEOUT_S)
        seconds = time.monotonic() - began
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        _end_session(proc)
        reader.join(timeout=10)
    if kill_after is None:
        assert proc.returncode == 0, b"".join(err).decode(errors="replace")
    return proc.returncode, seconds


def _uninterrupted(args: list[str], out: Path) -> float:
    """Run ``lburst ARGS`` to its end; returns the seconds of its work (after its first file)."""
    return _run(args, out)[1]


def _kill_repeatedly(args: list[str], out: Path, rng: np.random.Generator, span: float, kills: int) -> int:
    """Kill ``lburst ARGS`` ``kills`` times at random points of its work (the first in its first
    half, the others up to ``span`` seconds in: a resumed run has less to do), then run it to
    the end; returns how many runs were killed before they finished.  A run that was not
    killed must have finished."""
    killed = 0
    for i in range(kills):
        status, _ = _run(args, out, kill_after=float(rng.uniform(0.0, span / 2 if i == 0 else span)))
        assert status in (0, -signal.SIGKILL), f"lburst {args[0]} ended with {status}, neither killed nor done"
        killed += status == -signal.SIGKILL
    _run(args, out)
    return killed


def _no_temporaries(folder: Path) -> None:
    left = [p for p in folder.rglob("*") if ".tmp" in p.name]
    assert not left, f"temporary files left: {left}"


def _assert_same_npz(a: Path, b: Path) -> None:
    with np.load(a) as x, np.load(b) as y:
        assert sorted(x.files) == sorted(y.files), a.name
        for key in x.files:
            np.testing.assert_array_equal(x[key], y[key], err_msg=f"{a.name}: {key}")


def _assert_same_h5(a: Path, b: Path) -> None:
    import h5py

    with h5py.File(a) as x, h5py.File(b) as y:
        assert sorted(x) == sorted(y)
        for group in x:
            assert sorted(x[group]) == sorted(y[group])
            for key in x[group]:
                np.testing.assert_array_equal(x[group][key][()], y[group][key][()], err_msg=f"{group}/{key}")


def _flight(folder: Path, bursts: int, size: tuple[int, int]) -> Path:
    from lburst.scenes.night_flight import NightFlightConfig, make_night_flight

    cfg = NightFlightConfig(n_bursts=bursts, frames_per_burst=5, width=size[0], height=size[1], noise="none")
    make_night_flight(folder, cfg, progress=False)
    return folder


def check_extract(scene: Path, tmp_path: Path, seed: int, kills: int) -> int:
    bursts = sorted(str(p) for p in scene.iterdir() if p.is_dir())
    args = lambda out: ["extract", *bursts, "--out", str(out), "--top-k", "300", "--h5"]  # noqa: E731
    span = _uninterrupted(args(tmp_path / "whole"), tmp_path / "whole")
    killed = _kill_repeatedly(args(tmp_path / "killed"), tmp_path / "killed", np.random.default_rng(seed), span, kills)
    whole, again = tmp_path / "whole", tmp_path / "killed"
    names = sorted(p.name for p in whole.glob("*.npz"))
    assert len(names) == len(bursts)
    assert sorted(p.name for p in again.iterdir()) == sorted(p.name for p in whole.iterdir())
    for name in names:
        _assert_same_npz(whole / name, again / name)
    _assert_same_h5(whole / "features.h5", again / "features.h5")
    _no_temporaries(again)
    return killed


def _result(out: Path) -> dict:
    data = json.loads((out / "result.json").read_text())
    data.pop("out_dir")
    return data


def check_reconstruct(scene: Path, tmp_path: Path, seed: int, kills: int) -> int:
    def args(out):
        return [
            "reconstruct",
            str(scene),
            "--method",
            "sift",
            "--out",
            str(out),
            "--threads",
            "1",
            "--camera",
            "reference",
            "--fix-intrinsics",
        ]

    whole, again = tmp_path / "whole", tmp_path / "killed"
    span = _uninterrupted(args(whole), whole)
    killed = _kill_repeatedly(args(again), again, np.random.default_rng(seed), span, kills)
    expected = _result(whole)
    assert expected["error"] is None and len(expected["registered"]) >= 2
    assert _result(again) == expected  # registered images, poses, cameras, metrics
    for folder, pattern in (("features", "*.npz"), ("images", "*.png"), ("colmap/model", "*")):
        names = sorted(p.name for p in (whole / folder).glob(pattern))
        assert names and sorted(p.name for p in (again / folder).glob(pattern)) == names
        for name in names:
            if name.endswith(".npz"):
                _assert_same_npz(whole / folder / name, again / folder / name)
            else:
                assert (whole / folder / name).read_bytes() == (again / folder / name).read_bytes(), name
    assert (whole / "colmap" / "model.ply").read_bytes() == (again / "colmap" / "model.ply").read_bytes()
    _no_temporaries(again)
    return killed


@pytest.fixture(scope="module")
def tiny_flight(tmp_path_factory) -> Path:
    return _flight(tmp_path_factory.mktemp("fault") / "scene", bursts=4, size=(128, 96))


def test_killed_extract_reruns_to_the_uninterrupted_features(tiny_flight, tmp_path):
    assert check_extract(tiny_flight, tmp_path, seed=0, kills=2) >= 1  # a run was killed before its end


def test_killed_reconstruct_reruns_to_the_uninterrupted_model(tiny_flight, tmp_path):
    assert check_reconstruct(tiny_flight, tmp_path, seed=1, kills=2) >= 1


@pytest.mark.slow
def test_extract_and_reconstruct_killed_many_times(tmp_path):
    scene = _flight(tmp_path / "scene", bursts=8, size=(256, 192))
    killed = check_extract(scene, tmp_path / "extract", seed=2, kills=6)
    killed += check_reconstruct(scene, tmp_path / "reconstruct", seed=3, kills=6)
    assert killed >= 6  # most kills land before the end of the work
