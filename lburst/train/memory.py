"""What one training step needs in memory, estimated before the first batch is drawn.

A step holds, for each of the ``2 x batch`` bursts of ``crop x crop`` pixels, the
activations the backward pass keeps and the full-resolution descriptor maps of the losses.
:func:`step_bytes` counts the network's activations per pixel with forward hooks on a
small input (exact for any architecture) and adds the losses' share per pixel; both
factors were fitted to the peak resident memory of one step
(``/usr/bin/time -f %M lburst train --preset aligned --steps 1 --workers 0 --batch-size B``,
B = 1, 4, 16) of the Fast-Quad-L2-Net and of the light network: 5.8 and 4.5 GB predicted at
batch 16 against 5.8 and 4.5 GB measured, 1.9 and 1.5 GB at batch 4 against 1.8 and 1.4 GB.
"""

from __future__ import annotations

import torch

from lburst.errors import LBurstValueError
from lburst.model.extractor import memory_limit_bytes

#: Bytes per burst pixel that the losses hold beside the network (fitted, see above).
LOSS_BYTES_PER_PIXEL = 3072
#: Share of the forward activations (float32) that a step keeps at its peak (fitted).
KEPT_ACTIVATIONS = 0.44
#: The process before the first step (interpreter, torch, the network, the optimizer).
BASE_BYTES = 512 * 2**20


def activations_per_pixel(net: torch.nn.Module, channels: int, side: int = 64) -> float:
    """Elements that the leaf modules of ``net`` output per input pixel (one forward pass of
    a ``side x side`` zero input without gradient)."""
    total = 0

    def count(_module, _inputs, output) -> None:
        nonlocal total
        values = output.values() if isinstance(output, dict) else output
        values = [values] if torch.is_tensor(values) else values
        total += sum(v.numel() for v in values if torch.is_tensor(v))

    leaves = [m for m in net.modules() if not any(True for _ in m.children())]
    hooks = [m.register_forward_hook(count) for m in leaves]
    try:
        with torch.no_grad():
            net(torch.zeros(1, channels, side, side))
    finally:
        for h in hooks:
            h.remove()
    return total / side**2


def pair_bytes(net: torch.nn.Module, channels: int, crop: int) -> float:
    """Estimated memory that one pair of ``crop`` px bursts adds to a training step."""
    per_pixel = activations_per_pixel(net, channels) * 4 * KEPT_ACTIVATIONS + LOSS_BYTES_PER_PIXEL
    return 2 * crop**2 * per_pixel


def step_bytes(net: torch.nn.Module, channels: int, batch_size: int, crop: int) -> int:
    """Estimated peak memory of one training step of ``batch_size`` pairs of ``crop`` px bursts."""
    return int(BASE_BYTES + batch_size * pair_bytes(net, channels, crop))


def check_step_memory(
    net: torch.nn.Module, channels: int, batch_size: int, crop: int, limit: int | None = None
) -> None:
    """``ValueError`` naming the figure and ``--batch-size`` when one step would need more
    than ``limit`` bytes (default: half of the machine's memory; no check where unknown)."""
    limit = memory_limit_bytes() if limit is None else limit
    if limit is None:
        return
    one = pair_bytes(net, channels, crop)  # one forward pass with hooks, for both figures
    need = BASE_BYTES + batch_size * one
    if need <= limit:
        return
    fits = max(0, int((limit - BASE_BYTES) // one))
    raise LBurstValueError(
        f"--batch-size {batch_size}: a training step of {batch_size} pairs of {crop}-px bursts needs about "
        f"{need / 2**30:.1f} GiB, more than half of this machine's memory ({limit / 2**30:.1f} GiB); "
        f"lower --batch-size (about {fits} fit)"
    )
