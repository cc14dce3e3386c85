"""The network as the detector runs it: one backend per :class:`lburst.LBurst`, chosen once.

A backend runs normalised bursts ``x`` (B, 3N, h, w) through the network:
:meth:`Backend.run` gives the maps ``(repeatability, reliability, raw descriptor map)`` (B, 1, h, w),
(B, 1, h, w), (B, D, h / s, w / s) with ``s`` the map's stride (:func:`lburst.model.fast.descriptor_stride`).

- :class:`TorchBackend`: the network's inference form in torch (runtimes ``torch``, ``torch-bf16``),
  on any torch device;
- :class:`RunnerBackend`: any other runner with that signature (ONNX Runtime, OpenVINO, a
  callable of the caller's), on the CPU.

Either keeps the torch network when there is one: an extraction that asks for another
``precision`` runs its inference form at that precision, and one that asks for the plain
network (``fast=False``) runs it as published.  :func:`open_backend` builds the backend of a
:class:`lburst.model.runtimes.Runtime`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path

import torch
from torch import nn

from lburst.errors import LBurstValueError
from lburst.model.lite import LiteNet
from lburst.model.network import LBurstNet, check_device, check_precision
from lburst.model.runtimes import Calibration, Runner, Runtime, inference_form, make_runner

Maps = tuple[torch.Tensor, torch.Tensor, torch.Tensor]


class Backend(ABC):
    """Runs the network (see the module docstring).  ``name``: the runtime's name (what
    :attr:`lburst.LBurst.runtime` says); ``frames``: the bursts' frame count N; ``net``: the torch
    network, if any; ``device``: where the tensors it returns are."""

    def __init__(self, name: str, frames: int, net: LBurstNet | LiteNet | None, device: torch.device) -> None:
        self.name = name
        self.frames = frames
        self.net = net
        self.device = device
        self._runner: Runner | None = None
        self._variants: dict[str, nn.Module] = {}  # the torch network's inference form by precision

    @property
    @abstractmethod
    def runner(self) -> Runner:
        """What runs the network in fp32: ``x -> maps``."""

    @property
    @abstractmethod
    def cpu_only(self) -> bool:
        """Whether the runner runs on the CPU only (it is not a torch module)."""

    @abstractmethod
    def channels_last(self, precision: str) -> bool:
        """Whether the levels of an extraction in ``precision`` run through a torch module (which
        wants channels-last input)."""

    def run(self, x: torch.Tensor, precision: str = "fp32") -> Maps:
        """The maps of ``x``; a ``precision`` other than fp32 runs the torch network's inference form
        in it (autocast backbone) where there is a torch network."""
        if precision == "fp32" or self.net is None:
            return self.runner(x)
        if precision not in self._variants:
            check_precision(precision, self.device)
            self._variants[precision] = inference_form(self.net, precision).to(self.device).eval()
        return self._variants[precision](x)

    def plain(self, x: torch.Tensor) -> dict[str, torch.Tensor] | None:
        """The plain network's dense outputs (``descriptors``, ``repeatability``, ``reliability``),
        as the published code computes them; ``None`` without a torch network."""
        return None if self.net is None else self.net(x)

    @property
    def descriptor_dim(self) -> int:
        """D, the descriptors' size (128 for the shipped weights, and without a torch network)."""
        return self.net.config.dim if self.net is not None and hasattr(self.net.config, "dim") else 128

    def to(self, device: str | torch.device) -> Backend:
        """Move every torch module to ``device``; ``ValueError`` for a device that is not there, and
        for any but the CPU when the runner runs on the CPU only."""
        if self.cpu_only and str(device).split(":")[0] != "cpu":
            raise LBurstValueError(f"runtime {self.name!r} runs on the CPU only; load the weights with runtime='torch'")
        device = check_device(device)
        for module in (self.net, self._runner, *self._variants.values()):
            if isinstance(module, nn.Module):
                module.to(device)
        self.device = device
        return self


class TorchBackend(Backend):
    """The network's inference form in torch (:func:`lburst.model.runtimes.inference_form`), built
    on first use, in ``precision`` (``'fp32'`` or ``'bf16'``)."""

    def __init__(
        self, net: LBurstNet | LiteNet, device: torch.device, precision: str = "fp32", name: str = "torch"
    ) -> None:
        super().__init__(name, net.config.frames, net.eval().to(device), device)
        self.precision = precision

    @property
    def runner(self) -> Runner:
        if self._runner is None:
            self._runner = inference_form(self.net, self.precision).to(self.device).eval()
        return self._runner

    @property
    def cpu_only(self) -> bool:
        return False

    def channels_last(self, precision: str) -> bool:
        return True


class RunnerBackend(Backend):
    """A given runner (ONNX Runtime, OpenVINO, or any callable ``x -> maps``), with the torch
    network ``net`` beside it when there is one."""

    def __init__(
        self,
        runner: Runner,
        name: str,
        frames: int,
        net: LBurstNet | LiteNet | None = None,
        device: torch.device | str = "cpu",
    ) -> None:
        device = torch.device(device)
        super().__init__(name, frames, net.eval().to(device) if net is not None else None, device)
        self._runner = runner

    @property
    def runner(self) -> Runner:
        return self._runner

    @property
    def cpu_only(self) -> bool:
        return not isinstance(self._runner, nn.Module)

    def channels_last(self, precision: str) -> bool:
        return self.net is not None and (precision != "fp32" or not self.cpu_only)


def open_backend(
    runtime: Runtime,
    net: LBurstNet | LiteNet,
    device: torch.device,
    *,
    threads: int | None = None,
    meta: dict | None = None,
    onnx_path: str | Path | None = None,
    calibration: Calibration | None = None,
) -> Backend:
    """The backend of ``net`` on ``runtime`` (the other arguments: as
    :func:`lburst.model.runtimes.make_runner`)."""
    if runtime.engine == "torch":
        return TorchBackend(net, device, runtime.precision, runtime.name)
    runner = make_runner(runtime, net, threads=threads, meta=meta, onnx_path=onnx_path, calibration=calibration)
    return RunnerBackend(runner, runtime.name, net.config.frames, net, device)
