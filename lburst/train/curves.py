"""Loss curves of a training run (``log.csv``) as a PNG."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from lburst.burst.io import atomic_path  # noqa: E402

COMPONENTS = ("loss", "cosim", "peaky", "reliability", "ap")


def read_log(path: str | Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in ("step",) + COMPONENTS}


def plot_curves(runs: dict[str, str | Path], out: str | Path, smooth: int = 200) -> Path:
    """One panel per loss component, one line per run (``label -> log.csv``), moving
    average over ``smooth`` steps."""
    fig, axes = plt.subplots(1, len(COMPONENTS), figsize=(4 * len(COMPONENTS), 3.2))
    for label, path in runs.items():
        log = read_log(path)
        k = max(1, min(smooth, len(log["step"]) // 5))
        kernel = np.ones(k) / k
        for ax, name in zip(axes, COMPONENTS):
            values = np.convolve(log[name], kernel, mode="valid")
            ax.plot(log["step"][k - 1 :], values, label=label)
    for ax, name in zip(axes, COMPONENTS):
        ax.set_title(name + (" (reliability AP, higher is better)" if name == "ap" else ""), fontsize=9)
        ax.set_xlabel("step")
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.tight_layout()
    out = Path(out)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return out
