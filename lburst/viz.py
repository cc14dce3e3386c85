"""Pictures: keypoints on the common frame and the network's confidence maps."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lburst.burst.io import atomic_path, to_uint8
from lburst.extras import require


def new_figure(figsize: tuple[float, float]):
    """A matplotlib ``Figure`` that is not attached to pyplot, so no backend is chosen or
    forced (``savefig`` renders PNG with Agg) and nothing needs closing."""
    return require("matplotlib.figure", "plotting").Figure(figsize=figsize)


def to_display(image: np.ndarray) -> np.ndarray:
    """An (H, W, 3) uint8 or uint16 image as uint8 for display."""
    return to_uint8(image)


def plot_keypoints_and_maps(
    image: np.ndarray,
    keypoints: np.ndarray,
    repeatability: np.ndarray | None,
    reliability: np.ndarray | None,
    path: str | Path,
    title: str = "",
    max_keypoints: int = 2000,
) -> Path:
    """Save a PNG: ``image`` (H, W, 3) with ``keypoints`` (K, 2) (x, y, pixel centres at
    integer coordinates), and the repeatability and reliability maps (H, W) in red (low)
    to green (high), side by side as in the paper's figures."""
    panels = [("keypoints", None)]
    if repeatability is not None:
        panels.append(("repeatability", repeatability))
    if reliability is not None:
        panels.append(("reliability", reliability))
    h, w = image.shape[:2]
    fig = new_figure((5 * len(panels) * w / max(h, w) + 0.5, 5 * h / max(h, w) + 0.6))
    axes = np.atleast_1d(fig.subplots(1, len(panels)))
    for ax, (name, data) in zip(axes, panels):
        if data is None:
            ax.imshow(to_display(image))
            kp = keypoints[:max_keypoints]
            ax.scatter(kp[:, 0], kp[:, 1], s=4, c="lime", edgecolors="none")
            ax.set_title(
                f"{len(keypoints)} keypoints" + (f" (best {len(kp)} shown)" if len(kp) < len(keypoints) else "")
            )
        else:
            im = ax.imshow(data, cmap="RdYlGn", vmin=0, vmax=1)
            ax.set_title(name)
            fig.colorbar(im, ax=ax, fraction=0.035, pad=0.02)
        ax.set_axis_off()
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    return path
