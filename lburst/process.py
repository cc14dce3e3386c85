"""Process lifetime and exclusive use of output folders: a child that dies with its parent
(:func:`die_with_parent`) and a lock that one process at a time holds on a folder
(:func:`folder_lock`).  Imports nothing heavy (the COLMAP child uses it)."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterator

from lburst.errors import LBurstOSError


class FolderInUse(LBurstOSError):
    """Another process holds the lock on an output folder (:func:`folder_lock`)."""


@contextlib.contextmanager
def folder_lock(folder: str | Path) -> Iterator[None]:
    """Hold an exclusive lock on ``folder`` (through ``folder/.lock``) while the block runs.

    Raises :class:`FolderInUse` at once if another process holds it; the operating system
    releases the lock when its holder dies, so a killed run leaves none behind."""
    import fcntl

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise FolderInUse(
                f"{folder}: in use by another lburst process (lock {folder / '.lock'}); "
                f"wait for it to finish or use another --out"
            ) from None
        yield


def die_with_parent(parent: int) -> None:
    """Have the operating system kill this process (SIGKILL) when process ``parent`` dies
    (Linux ``prctl(PR_SET_PDEATHSIG)``; elsewhere nothing).  Exits at once if ``parent``
    is already gone."""
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:
        os._exit(1)
