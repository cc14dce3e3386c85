"""Memory a step will need, checked before it allocates: a step whose estimate passes half of
the machine's memory stops with one line giving the figure and what lowers it, as
:meth:`lburst.LBurst.dense` and ``lburst train`` (:mod:`lburst.train.memory`) do, instead of a
``MemoryError`` traceback or a machine that swaps.  Estimates are per step (a burst, a frame
being rendered, a network's weights), measured where their docstrings say.
"""

from __future__ import annotations

import os

from lburst.errors import LBurstValueError

GIB = 2**30


def memory_limit_bytes() -> int | None:
    """Half of the machine's physical memory (``None`` where the OS does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(need: float, what: str, lower: str, limit: int | None = None) -> None:
    """``ValueError`` when ``need`` bytes (what ``what`` needs) are more than ``limit`` (default:
    half of the machine's memory; no check where unknown): ``'WHAT needs about N GiB, more than
    half of this machine's memory (M GiB): LOWER'``, ``lower`` saying what lowers the figure."""
    limit = memory_limit_bytes() if limit is None else limit
    if limit is None or need <= limit:
        return
    raise LBurstValueError(
        f"{what} needs about {gib(need)}, more than half of this machine's memory ({gib(limit)}): {lower}"
    )


def gib(size: float) -> str:
    """``size`` bytes in GiB as the errors say it: ``'768.0 GiB'``, ``'3.2e+04 GiB'`` when huge."""
    value = size / GIB
    return f"{value:.1f} GiB" if value < 1e4 else f"{value:.2g} GiB"
