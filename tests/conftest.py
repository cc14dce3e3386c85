"""Shared test fixtures.  Data from ``../shared`` (or ``$LBURST_SHARED``) is optional:
tests that need it skip cleanly when it is absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

torch.set_num_threads(min(2, torch.get_num_threads()))

SHARED = Path(os.environ.get("LBURST_SHARED", Path(__file__).resolve().parents[1].parent / "shared"))


@pytest.fixture(scope="session")
def shared() -> Path:
    """The ``shared`` data folder; skips the test when it is not there."""
    if not (SHARED / "README.md").is_file():
        pytest.skip(f"shared data not found at {SHARED} (set LBURST_SHARED)")
    return SHARED


@pytest.fixture(scope="session")
def anchors(shared: Path) -> Path:
    path = shared / "anchors"
    if not (path / "reference_outputs.npz").is_file():
        pytest.skip(f"published checkpoints not found in {path}")
    return path


@pytest.fixture(scope="session")
def load_script():
    """A function that imports ``scripts/NAME.py`` of the repository as a module."""
    import importlib.util

    folder = Path(__file__).resolve().parents[1] / "scripts"

    def load(name: str):
        spec = importlib.util.spec_from_file_location(name, folder / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load
