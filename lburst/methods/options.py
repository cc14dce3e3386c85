"""Converting method options given as strings (``NAME,KEY=VALUE``) to typed values."""

from __future__ import annotations


def as_bool(value: str | bool) -> bool:
    """``'1'/'true'/'yes'`` -> True, ``'0'/'false'/'no'`` -> False (case-insensitive)."""
    if isinstance(value, bool):
        return value
    if str(value).lower() in ("1", "true", "yes"):
        return True
    if str(value).lower() in ("0", "false", "no"):
        return False
    raise ValueError(f"expected a boolean, got {value!r}")


def as_floats(value: str | tuple | list, count: int | None = None) -> tuple[float, ...]:
    """``'a:b'`` or ``'a;b'`` (colon/semicolon separated, since commas separate options) or a sequence -> floats."""
    if isinstance(value, str):
        parts = value.replace(";", ":").split(":")
        values = tuple(float(p) for p in parts if p.strip())
    else:
        values = tuple(float(v) for v in value)
    if count is not None and len(values) != count:
        raise ValueError(f"expected {count} numbers, got {value!r}")
    return values


def check_known(options: dict, known: set[str], method: str) -> None:
    """Raise ``ValueError`` naming any option not in ``known``."""
    unknown = set(options) - known
    if unknown:
        raise ValueError(f"unknown options {sorted(unknown)} for method {method!r}; known: {sorted(known)}")
