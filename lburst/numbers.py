"""Numbers given on the command line or to the API, checked once: finite, in range, integer
where a count is meant.

:func:`check_integer` and :func:`check_real` check a value given in Python and name it in
the error; :mod:`lburst.cli.numbers` makes the same checks the ``type=`` of every numeric
command-line option (argparse names the option in its one-line error).
"""

from __future__ import annotations

import math

import numpy as np

from lburst.errors import LBurstValueError


def bounds_text(low, high, low_open: bool = False) -> str:
    """``'>= 1 and <= 10'``: the bounds as the errors say them."""
    parts = []
    if low is not None:
        parts.append(f"{'>' if low_open else '>='} {low:g}")
    if high is not None:
        parts.append(f"<= {high:g}")
    return " and ".join(parts)


def check_integer(value, name: str, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int if it is an integer (not a bool, not a float) within ``[low, high]``;
    else ``ValueError`` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise LBurstValueError(
            f"{name} must be an integer{' ' + bounds_text(low, high) if bounds_text(low, high) else ''}, got {value!r}"
        )
    value = int(value)
    if (low is not None and value < low) or (high is not None and value > high):
        raise LBurstValueError(f"{name} must be an integer {bounds_text(low, high)}, got {value}")
    return value


def check_real(value, name: str, low: float | None = None, high: float | None = None, low_open: bool = False) -> float:
    """``value`` as a float if it is a finite number within its bounds (``low_open``: above
    ``low``, not equal); else ``ValueError`` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise LBurstValueError(f"{name} must be a number, got {value!r}")
    value = float(value)
    bounds = bounds_text(low, high, low_open)
    if not math.isfinite(value):
        raise LBurstValueError(f"{name} must be a finite number{' ' + bounds if bounds else ''}, got {value}")
    too_low = low is not None and (value <= low if low_open else value < low)
    if too_low or (high is not None and value > high):
        raise LBurstValueError(f"{name} must be a number {bounds}, got {value:g}")
    return value
