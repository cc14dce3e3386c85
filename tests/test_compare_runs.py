"""scripts/compare_runs.py: two output folders compared as data, not as bytes of run records."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "compare_runs.py"


def _run_folder(root: Path, keypoints: np.ndarray, seconds: float) -> Path:
    (root / "features").mkdir(parents=True)
    np.savez(root / "features" / "a.npz", keypoints=keypoints, _meta=np.array(str(root)))
    with h5py.File(root / "features.h5", "w") as f:
        f.create_dataset("a.png/keypoints", data=keypoints)
    (root / "result.json").write_text(
        json.dumps({"out_dir": str(root.resolve()), "ate": 0.1, "features_seconds": seconds})
    )
    (root / "run.log").write_text(f"took {seconds}")
    return root


def _compare(a: Path, b: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), str(a), str(b)], capture_output=True, text=True)


def test_runs_that_differ_only_in_paths_and_timings_are_equal(tmp_path):
    kp = np.arange(6, dtype=np.float32).reshape(3, 2)
    done = _compare(_run_folder(tmp_path / "a", kp, 1.0), _run_folder(tmp_path / "b", kp, 2.0))
    assert done.returncode == 0 and done.stdout.strip().endswith("3 items compared, 0 differ")


def test_a_changed_array_or_a_missing_file_is_named(tmp_path):
    kp = np.arange(6, dtype=np.float32).reshape(3, 2)
    a, b = _run_folder(tmp_path / "a", kp, 1.0), _run_folder(tmp_path / "b", kp + np.float32(1e-6), 1.0)
    (a / "pairs.txt").write_text("a.png b.png\n")
    done = _compare(a, b)
    assert done.returncode == 1
    lines = done.stdout.splitlines()
    assert "features/a.npz: keypoints differs" in lines and "features.h5: a.png/keypoints differs" in lines
    assert f"pairs.txt: only in {a}" in lines


def test_runs_started_with_relative_folders_are_equal(tmp_path):
    """``lburst reconstruct --out runs/a`` records the folder as given: compared from the folder
    above, ``runs/a`` and ``runs/b`` are each run's own path."""
    kp = np.arange(6, dtype=np.float32).reshape(3, 2)
    for name in ("a", "b"):
        root = _run_folder(tmp_path / "runs" / name, kp, 1.0)
        (root / "result.json").write_text(json.dumps({"out_dir": f"runs/{name}", "names": ["0000.png"]}))
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "runs/a", "runs/b"], capture_output=True, text=True, cwd=tmp_path
    )
    assert done.returncode == 0 and done.stdout.strip().endswith("3 items compared, 0 differ"), done.stdout
