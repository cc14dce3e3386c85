"""Turn a training run's resumable checkpoint into shippable weights (published layout)."""

from __future__ import annotations

from pathlib import Path

import torch

from lburst.model.network import LBurstNet, config_from_net_string, save_checkpoint


def export_weights(run_checkpoint: str | Path, out: str | Path, **meta) -> Path:
    """Write the weights of ``run_checkpoint`` (a run's ``last.pt``) to ``out`` with
    ``{'net', 'state_dict', 'meta'}`` (``meta``: the run's step, config and ``meta``)."""
    state = torch.load(run_checkpoint, map_location="cpu", weights_only=True)
    net = LBurstNet(config_from_net_string(state["net"]))
    net.load_state_dict(state["state_dict"])
    save_checkpoint(
        net,
        out,
        meta={"step": int(state["step"]), "seconds": float(state["seconds"]), "config": state["config"], **meta},
    )
    return Path(out)
