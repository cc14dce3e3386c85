"""Where lburst finds the optional shared data folder (never part of the package)."""

from __future__ import annotations

import os
from pathlib import Path


def shared_dir() -> Path:
    """``$LBURST_SHARED`` if set, else ``../shared`` relative to the working directory."""
    return Path(os.environ.get("LBURST_SHARED", Path.cwd().parent / "shared"))
