"""Turn a training run's checkpoint into shippable weights (published layout)."""

from __future__ import annotations

import json
from pathlib import Path

import torch

from lburst.model.network import network_from_net_string, save_checkpoint


def export_weights(run_checkpoint: str | Path, out: str | Path, **meta) -> Path:
    """Write the weights of ``run_checkpoint`` to ``out`` as ``{'net', 'state_dict', 'meta'}``.

    ``run_checkpoint``: a run's resumable ``last.pt`` or one of its ``snapshots/step_*.pt``
    (either architecture).  ``meta``: the checkpoint's step, seconds and ``meta`` (``input``),
    the run's configuration (from ``last.pt``, or the run folder's ``config.json`` for a
    snapshot), then the keyword ``meta`` given here."""
    run_checkpoint = Path(run_checkpoint)
    state = torch.load(run_checkpoint, map_location="cpu", weights_only=True)
    net = network_from_net_string(state["net"])
    net.load_state_dict(state["state_dict"])
    saved = dict(state.get("meta") or {})
    if "step" in state:
        saved["step"] = int(state["step"])
    if "seconds" in state:
        saved["seconds"] = float(state["seconds"])
    config = state.get("config")
    if config is None:
        for folder in (run_checkpoint.parent, run_checkpoint.parent.parent):
            if (folder / "config.json").is_file():
                config = json.loads((folder / "config.json").read_text())
                break
    if config is not None:
        saved["config"] = config
    save_checkpoint(net, out, meta={**saved, **meta})
    return Path(out)
