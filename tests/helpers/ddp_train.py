"""Run by tests/train/test_train_loop.py under torchrun: a tiny data-parallel training run on the CPU."""

import sys

import torch

from lburst.train.loop import TrainConfig, train
from lburst.train.pairs import PairConfig

TINY = PairConfig(frames=3, crop=64, long_side=(160, 256), max_burst_motion=6, max_pair_shift=6)

if __name__ == "__main__":
    photos, out = sys.argv[1], sys.argv[2]
    torch.set_num_threads(1)
    cfg = TrainConfig(frames=3, batch_size=2, steps=2, patch=8, workers=0, pair=TINY)
    train([photos], out, cfg, device="cpu", progress=False)
