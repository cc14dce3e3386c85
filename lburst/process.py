"""Process lifetime, process-wide state and exclusive use of output folders: a child that dies
with its parent (:func:`die_with_parent`), a command's changes to the process undone when it
returns (:func:`state_kept`, :func:`environment_kept`) and a lock that one process at a time holds on a folder
(:func:`folder_lock`).  Imports nothing heavy (the COLMAP child uses it)."""

from __future__ import annotations

import contextlib
import functools
import os
from pathlib import Path
from typing import Callable, Iterator, TypeVar

from lburst.errors import LBurstOSError

F = TypeVar("F", bound=Callable)


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


@contextlib.contextmanager
def environment_kept() -> Iterator[None]:
    """Put ``os.environ`` back as it was when the block ends: variables that the block (or a
    library it calls, such as Dask's nanny, which sets ``OMP_NUM_THREADS=1`` and others in its
    own process before it spawns a worker) added, changed or removed."""
    before = dict(os.environ)
    try:
        yield
    finally:
        for key in set(os.environ) - set(before):
            del os.environ[key]
        for key, value in before.items():
            if os.environ.get(key) != value:
                os.environ[key] = value


@contextlib.contextmanager
def state_kept() -> Iterator[None]:
    """Restore, when the block ends, the process-wide state that a command may change: torch's
    thread count and global random state (``--threads``, a training run's seed), OpenCV's
    thread count, the environment (:func:`environment_kept`), the warnings format and the
    error handler of stdout and stderr.  A command
    called in-process (``lburst.cli.main([...])``) so leaves its caller as it found it.

    torch and OpenCV are looked at only where the caller has imported them already (this
    module imports nothing heavy): what a process that had not imported them does after the
    block is its own first use."""
    import sys
    import warnings

    torch = sys.modules.get("torch")
    cv2 = sys.modules.get("cv2")
    threads = torch.get_num_threads() if torch is not None else None
    rng = torch.get_rng_state() if torch is not None else None
    cv2_threads = cv2.getNumThreads() if cv2 is not None else None
    formatwarning = warnings.formatwarning
    errors = {stream: getattr(stream, "errors", None) for stream in (sys.stdout, sys.stderr)}
    try:
        with environment_kept():
            yield
    finally:
        warnings.formatwarning = formatwarning
        for stream, handler in errors.items():
            if handler is not None and hasattr(stream, "reconfigure") and stream.errors != handler:
                stream.reconfigure(errors=handler)
        if torch is not None:
            if torch.get_num_threads() != threads:
                torch.set_num_threads(threads)
            torch.set_rng_state(rng)
        if cv2 is not None and cv2.getNumThreads() != cv2_threads:
            cv2.setNumThreads(cv2_threads)


def keeps_state(function: F) -> F:
    """``function`` run inside :func:`state_kept`: it leaves its caller's process as it found it."""

    @functools.wraps(function)
    def kept(*args, **kwargs):
        with state_kept():
            return function(*args, **kwargs)

    return kept  # type: ignore[return-value]
