""":class:`StrEnum`: an enum whose members are their string values, on every Python that
lburst supports (``enum.StrEnum`` is Python 3.11+; ``requires-python`` says 3.10)."""

from __future__ import annotations

from enum import Enum


class StrEnum(str, Enum):
    """Members are ``str`` and equal to their values; ``str()``, ``format()`` and f-strings give
    the value (``str(Status.COMPLETE) == 'complete'``), as ``enum.StrEnum`` does."""

    def __str__(self) -> str:
        return str(self.value)

    def __format__(self, spec: str) -> str:
        return format(str(self.value), spec)
