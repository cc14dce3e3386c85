"""A command called in-process, and a test, leave the process as they found it."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import cv2
import numpy as np
import torch

from lburst.cli import main


def test_extract_with_threads_called_in_process_leaves_torchs_thread_count_and_random_state(tmp_path):
    """``--threads`` sets torch's count for the command's own run only (it once stayed at 1 for
    the rest of the process, and a later test measured at one thread)."""
    burst = tmp_path / "burst"
    burst.mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        cv2.imwrite(str(burst / f"{i:02d}.png"), rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
    before = torch.get_num_threads()
    other = 3 if before != 3 else 2
    rng_state, formatwarning = torch.get_rng_state(), warnings.formatwarning
    code = main(["extract", str(burst), "--method", "sift", "--out", str(tmp_path / "out"), "--threads", str(other)])
    assert code == 0
    assert (tmp_path / "out" / "burst.npz").is_file()
    assert torch.get_num_threads() == before
    assert torch.equal(torch.get_rng_state(), rng_state)
    assert warnings.formatwarning is formatwarning


LEAKING_TESTS = """
import os

import torch

THREADS = torch.get_num_threads()


def test_threads():
    torch.set_num_threads(THREADS + 1)


def test_environment():
    os.environ["LBURST_LEAKED"] = "1"


def test_working_directory(tmp_path):
    os.chdir(tmp_path)


def test_seen_after_the_leaks():
    assert torch.get_num_threads() == THREADS and "LBURST_LEAKED" not in os.environ
    assert os.getcwd() == os.environ["PWD_AT_START"]
"""


LEAKING_MODULE_FIXTURE = """
import pytest
import torch


@pytest.fixture(scope="module")
def one_thread():
    torch.set_num_threads(1 if torch.get_num_threads() != 1 else 2)  # as an in-process --threads 1 once did


def test_with_the_fixture(one_thread):
    pass
"""


def test_a_test_that_leaks_process_state_fails_and_the_next_test_finds_it_restored(tmp_path):
    (tmp_path / "conftest.py").write_text((Path(__file__).parent / "conftest.py").read_text())
    (tmp_path / "test_leaks.py").write_text(LEAKING_TESTS)
    (tmp_path / "test_module_leaks.py").write_text(LEAKING_MODULE_FIXTURE)
    env = {k: v for k, v in __import__("os").environ.items() if k != "PYTEST_ADDOPTS"}
    env["PWD_AT_START"] = str(tmp_path)
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "-p",
            "no:randomly",
            "test_leaks.py",
            "test_module_leaks.py",
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = run.stdout
    assert "5 passed, 4 errors" in out, out  # each leak is an error in its test's (or module's) teardown
    assert "a fixture of this module changed process-wide state" in out
    assert "the test changed process-wide state" in out and "torch threads" in out
    assert "$LBURST_LEAKED None -> '1'" in out
    assert "working directory" in out
