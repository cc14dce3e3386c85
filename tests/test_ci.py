"""The CI's size check refuses large tracked files."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

CHECK = Path(__file__).resolve().parents[1] / ".ci" / "check_sizes.py"


def git(repo: Path, *args: str) -> None:
    subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True)


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    git(tmp_path, "init", "-q")
    (tmp_path / "small.txt").write_text("ok\n")
    git(tmp_path, "add", "small.txt")
    return tmp_path


def check(repo: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(CHECK)], cwd=repo, capture_output=True, text=True)


def test_small_files_pass(repo):
    out = check(repo)
    assert out.returncode == 0, out.stderr
    assert "1 tracked files" in out.stdout


def test_a_file_above_10_mb_is_refused_once_added(repo):
    big = repo / "weights.pt"
    with open(big, "wb") as f:
        f.truncate(10 * 1000 * 1000 + 1)
    assert check(repo).returncode == 0  # untracked: not our business
    git(repo, "add", "weights.pt")
    out = check(repo)
    assert out.returncode == 1
    assert "weights.pt: 10.0 MB (limit 10 MB per file)" in out.stderr


def test_training_runs_above_15_mb_in_all_are_refused(repo):
    for run in ("a", "b"):
        (repo / "training" / run).mkdir(parents=True)
        with open(repo / "training" / run / "last.pt", "wb") as f:
            f.truncate(8 * 1000 * 1000)
    git(repo, "add", "training")
    out = check(repo)
    assert out.returncode == 1
    assert "training/: 16.0 MB tracked (limit 15 MB)" in out.stderr
