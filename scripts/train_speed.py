"""Training speed: steps and pairs per second of the LBurst training step on the machine that runs it.

Times the full step (pair generation excluded: it runs in loader workers, see
``pair_s``), forward + three losses + backward + Adam, on random photos' pairs.

    python scripts/train_speed.py --frames 5 1 --out outputs/train_speed.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch


def measure(
    frames: int,
    batch: int,
    crop: int,
    steps: int,
    device: str,
    precision: str = "fp32",
    memory_format: str = "channels_last",
) -> dict:
    import skimage.data

    from lburst.model.network import LBurstNet, NetConfig, training_memory_format
    from lburst.train.loop import training_step
    from lburst.train.pairs import PairConfig, training_pair

    cfg = replace(PairConfig(), frames=frames, crop=crop)
    photos = [skimage.data.astronaut(), skimage.data.chelsea(), skimage.data.coffee()]
    rng = np.random.default_rng(0)
    start = time.perf_counter()
    pairs = [training_pair(photos[i % 3], rng, cfg) for i in range(batch)]
    pair_s = (time.perf_counter() - start) / batch
    batch_t = {
        "burst_a": torch.stack([torch.from_numpy(p.burst_a).permute(0, 3, 1, 2) for p in pairs]).to(device),
        "burst_b": torch.stack([torch.from_numpy(p.burst_b).permute(0, 3, 1, 2) for p in pairs]).to(device),
        "flow": torch.stack([torch.from_numpy(p.flow) for p in pairs]).to(device),
        "mask": torch.stack([torch.from_numpy(p.mask) for p in pairs]).to(device),
    }
    torch.manual_seed(0)
    layout = training_memory_format(device, memory_format)
    net = LBurstNet(NetConfig(frames=frames)).to(device).to(memory_format=layout).train()
    opt = torch.optim.Adam(net.parameters(), lr=1e-4, weight_decay=5e-4)
    times = []
    for i in range(steps + 1):
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        t = time.perf_counter()
        losses = training_step(net, batch_t, 16, precision=precision, memory_format=layout)
        opt.zero_grad(set_to_none=True)
        losses["loss"].backward()
        opt.step()
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        if i:
            times.append(time.perf_counter() - t)
    step_s = statistics.median(times)
    return {
        "frames": frames,
        "batch": batch,
        "crop": crop,
        "device": device,
        "precision": precision,
        "memory_format": memory_format,
        "step_s": step_s,
        "steps_per_s": 1 / step_s,
        "pairs_per_s": batch / step_s,
        "pair_s": pair_s,
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, nargs="+", default=[5, 1])
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--crop", type=int, default=192)
    p.add_argument("--steps", type=int, default=3)
    from lburst.model.network import AUTOCAST_DTYPES

    p.add_argument(
        "--precision",
        nargs="+",
        default=["fp32"],
        choices=list(AUTOCAST_DTYPES),
        help="autocast of the forward pass (each is measured)",
    )
    p.add_argument(
        "--memory-format",
        nargs="+",
        default=["channels_last", "contiguous"],
        choices=("channels_last", "contiguous"),
        help="tensor layouts (each is measured)",
    )
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--out", type=Path)
    args = p.parse_args()
    rows = [
        measure(n, args.batch, args.crop, args.steps, args.device, prec, layout)
        for n in args.frames
        for prec in args.precision
        for layout in args.memory_format
    ]
    print(
        f"\ntraining step, batch {args.batch} pairs of {args.crop} px crops, {args.device}, "
        f"{torch.get_num_threads()} threads, median of {args.steps}\n"
    )
    print("| frames | precision | memory format | s / step | steps / s | pairs / s | s / pair generated (1 worker) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['frames']} | {r['precision']} | {r['memory_format']} | {r['step_s']:.2f} | {r['steps_per_s']:.3f} | {r['pairs_per_s']:.2f} | {r['pair_s']:.3f} |"
        )
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
