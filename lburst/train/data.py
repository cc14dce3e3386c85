"""Training data: photo folders to an endless, seeded stream of burst pairs.

Sample ``i`` is drawn with ``numpy.random.default_rng([seed, i])``, so the stream is
the same on every run and a resumed run continues it exactly where it stopped.

A fixed tenth of the photos is held out for validation (:func:`is_validation_photo`,
a rule on the file name, so ``train/`` and ``train512/`` split alike) and never trained
on: :func:`list_photos` leaves it out unless asked for it.
"""

from __future__ import annotations

import signal
import zlib
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
import torch
from torch.utils.data import Dataset, Sampler

from lburst.burst.io import IMAGE_SUFFIXES, decode_file
from lburst.errors import LBurstFileNotFoundError, LBurstOSError, LBurstValueError
from lburst.train.pairs import PairConfig, training_pair

Split = Literal["train", "validation", "all"]


def is_validation_photo(path: str | Path) -> bool:
    """The held-out tenth: photos whose file stem has a CRC-32 divisible by 10."""
    return zlib.crc32(Path(path).stem.encode()) % 10 == 0


def list_photos(folders: list[str | Path], split: Split = "train") -> list[Path]:
    """Images under ``folders`` (recursively), sorted; error if there are none.

    ``split``: ``'train'`` leaves out the validation tenth (:func:`is_validation_photo`),
    ``'validation'`` keeps only it, ``'all'`` keeps every photo."""
    if split not in ("train", "validation", "all"):
        raise LBurstValueError(f"split must be 'train', 'validation' or 'all', got {split!r}")
    photos: list[Path] = []
    for folder in folders:
        folder = Path(folder)
        if not folder.is_dir():
            raise LBurstFileNotFoundError(f"{folder}: training photo folder not found")
        found = sorted(p for p in folder.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
        photos += [p for p in found if split == "all" or is_validation_photo(p) == (split == "validation")]
    if not photos:
        raise LBurstFileNotFoundError(
            f"no {split} photos ({', '.join(sorted(IMAGE_SUFFIXES))}) under {', '.join(map(str, folders))}"
        )
    return photos


class PairDataset(Dataset):
    """Index ``i`` gives pair ``i`` of the stream as tensors:
    ``burst_a``, ``burst_b`` (N, 3, crop, crop) float32 0..255, ``flow`` (crop, crop, 2), ``mask``
    and, with ``clean``, ``clean_a`` (burst A before the noise)."""

    def __init__(self, photos: list[Path], cfg: PairConfig, seed: int = 0, clean: bool = False) -> None:
        self.photos = photos
        self.cfg = cfg
        self.seed = seed
        self.clean = clean

    def __len__(self) -> int:
        return 2**62

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        rng = np.random.default_rng([self.seed, index])
        for _ in range(10):
            path = self.photos[rng.integers(len(self.photos))]
            photo = decode_file(path, cv2.IMREAD_COLOR)
            if photo is not None:
                break
        else:
            raise LBurstOSError(f"could not read training photos (last tried {path})")
        pair = training_pair(cv2.cvtColor(photo, cv2.COLOR_BGR2RGB), rng, self.cfg)
        item = {
            "burst_a": torch.from_numpy(pair.burst_a).permute(0, 3, 1, 2),
            "burst_b": torch.from_numpy(pair.burst_b).permute(0, 3, 1, 2),
            "flow": torch.from_numpy(pair.flow),
            "mask": torch.from_numpy(pair.mask),
        }
        if self.clean:
            item["clean_a"] = torch.from_numpy(pair.clean_a).permute(0, 3, 1, 2)
        return item


def init_worker(_: int) -> None:
    """Loader workers use one thread each: the parallelism is across workers.  They ignore
    SIGINT and SIGTERM, so a signal sent to the whole process group (Ctrl-C, ``pkill``,
    a service manager) reaches the training process, which saves and stops, instead of
    killing a worker and with it every step since the last checkpoint; the DataLoader ends
    its workers when the training process exits."""
    cv2.setNumThreads(1)
    torch.set_num_threads(1)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


class StreamSampler(Sampler[int]):
    """Indices ``start, start + stride, ...`` of the endless stream (``stride`` > 1 for
    data-parallel ranks, each starting at its own offset)."""

    def __init__(self, start: int, stride: int = 1) -> None:
        self.start = start
        self.stride = stride

    def __iter__(self):
        i = self.start
        while True:
            yield i
            i += self.stride
