"""Data-parallel training across processes started by ``torchrun`` (one per GPU).

``torchrun --nproc_per_node K -m lburst.cli train ...`` starts K processes with
``RANK``, ``WORLD_SIZE`` and ``LOCAL_RANK`` set; :func:`setup` joins them (NCCL on
GPUs, Gloo on the CPU) and :class:`Context` says which one this is.  Rank ``r`` of
``K`` draws samples ``r, r + K, r + 2K, ...`` of the training stream, so together the
ranks see the stream a single process would see with a K times larger batch.  Only
rank 0 logs and writes files; the losses it logs are the means over the ranks.
Without those variables everything is a single process and no collective is called.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.distributed as dist
from torch import nn


@dataclass(frozen=True)
class Context:
    """This process's place in the run: ``rank`` of ``world`` processes, on ``device``."""

    rank: int = 0
    world: int = 1
    device: torch.device = torch.device("cpu")

    @property
    def main(self) -> bool:
        """Rank 0: the process that logs and writes files."""
        return self.rank == 0

    def wrap(self, net: nn.Module) -> nn.Module:
        """``net`` in DistributedDataParallel when there are several processes."""
        if self.world == 1:
            return net
        ids = [self.device.index] if self.device.type == "cuda" else None
        return nn.parallel.DistributedDataParallel(net, device_ids=ids)

    def mean(self, values: dict[str, torch.Tensor]) -> dict[str, float]:
        """Each scalar averaged over the ranks (one all-reduce)."""
        keys = sorted(values)
        stacked = torch.stack([values[k].detach().float().reshape(()) for k in keys])
        if self.world > 1:
            dist.all_reduce(stacked)
            stacked /= self.world
        return dict(zip(keys, stacked.tolist()))

    def any(self, flag: bool) -> bool:
        """True on every rank if it is true on one (so all ranks stop at the same step)."""
        if self.world == 1:
            return flag
        t = torch.tensor([float(flag)], device=self.device)
        dist.all_reduce(t, op=dist.ReduceOp.MAX)
        return bool(t.item())

    def close(self) -> None:
        if self.world > 1:
            dist.barrier()
            dist.destroy_process_group()


def setup(device: str | torch.device | None = None) -> Context:
    """The context of this process: joins the process group when started by ``torchrun``."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    use_cuda = (device is None and torch.cuda.is_available()) or str(device).startswith("cuda")
    if world == 1:
        return Context(device=torch.device(device or ("cuda" if use_cuda else "cpu")))
    rank, local = int(os.environ["RANK"]), int(os.environ.get("LOCAL_RANK", "0"))
    if use_cuda:
        torch.cuda.set_device(local)
        place = torch.device("cuda", local)
    else:
        place = torch.device("cpu")
    if not dist.is_initialized():
        dist.init_process_group("nccl" if use_cuda else "gloo")
    return Context(rank=rank, world=world, device=place)
