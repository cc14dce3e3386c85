"""The ``type=`` of every numeric command-line option: :mod:`lburst.numbers`' checks, with
argparse naming the option in its one-line error (``argument --every: must be an integer >=
1, got 0``)."""

from __future__ import annotations

import argparse
from typing import Callable

from lburst.numbers import bounds_text, check_integer, check_real


def integer(low: int | None = None, high: int | None = None) -> Callable[[str], int]:
    """An argparse ``type``: the text as an integer within ``[low, high]``."""

    def parse(text: str) -> int:
        try:
            value = int(text.strip())
        except ValueError:
            bounds = bounds_text(low, high)
            raise argparse.ArgumentTypeError(
                f"must be an integer{' ' + bounds if bounds else ''}, got {text!r}"
            ) from None
        try:
            return check_integer(value, "it", low, high)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("it ")) from None

    parse.__name__ = "integer"
    return parse


def real(low: float | None = None, high: float | None = None, low_open: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: the text as a finite number within its bounds."""

    def parse(text: str) -> float:
        try:
            value = float(text.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
        try:
            return check_real(value, "it", low, high, low_open)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("it ")) from None

    parse.__name__ = "number"
    return parse
