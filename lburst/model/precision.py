"""Numeric precision of the networks: autocast dtypes, and whether the CPU has native bf16."""

from __future__ import annotations

import warnings
from pathlib import Path

import torch

from lburst.errors import LBurstValueError

#: autocast dtype of each precision the network can run in (``None``: plain fp32)
AUTOCAST_DTYPES: dict[str, torch.dtype | None] = {"fp32": None, "bf16": torch.bfloat16, "fp16": torch.float16}


def autocast_dtype(precision: str) -> torch.dtype | None:
    """The autocast dtype of ``precision`` (``None`` for fp32); ``ValueError`` for another name."""
    if precision not in AUTOCAST_DTYPES:
        raise LBurstValueError(f"precision must be fp32, bf16 or fp16, got {precision!r}")
    return AUTOCAST_DTYPES[precision]


NATIVE_BF16_FLAGS = ("avx512_bf16", "amx_bf16")  # /proc/cpuinfo flags of CPUs with bf16 arithmetic


def cpu_flags() -> set[str] | None:
    """The CPU's feature flags from ``/proc/cpuinfo``, or ``None`` where it cannot be read."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return None


def check_precision(precision: str, device: torch.device | str) -> None:
    """Warn when ``bf16`` runs on a CPU without native bf16 (no ``avx512_bf16`` or ``amx_bf16``):
    it works there, emulated, about 3x slower than fp32."""
    autocast_dtype(precision)
    if precision != "bf16" or torch.device(device).type != "cpu":
        return
    flags = cpu_flags()
    if flags is not None and not flags.intersection(NATIVE_BF16_FLAGS):
        warnings.warn(
            "--precision bf16 on a CPU without native bf16 (no avx512_bf16 or amx_bf16 in /proc/cpuinfo) "
            "runs about 3x slower than fp32",
            RuntimeWarning,
            stacklevel=2,
        )


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo``), for the tables of the speed scripts."""
    import platform

    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "cpu"
