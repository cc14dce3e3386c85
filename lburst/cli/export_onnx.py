"""``lburst export onnx``: a checkpoint's fast network to ONNX (:mod:`lburst.model.onnx`)."""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from lburst.cli.numbers import integer
from lburst.model.network import load_checkpoint
from lburst.model.onnx import OnnxRunner, export_onnx
from lburst.model.runtimes import inference_form
from lburst.weights import resolve_weights


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "checkpoint", help="checkpoint to export (lburst or published layout), or a shipped name such as lburst-b5"
    )
    p.add_argument("--out", type=Path, required=True, help="ONNX file to write")
    p.add_argument("--opset", type=integer(11, 30), default=18)
    p.add_argument("--check", action="store_true", help="compare ONNX Runtime with torch on a random burst")


def main(args: argparse.Namespace) -> int:
    args.checkpoint = resolve_weights(args.checkpoint)
    out = export_onnx(args.checkpoint, args.out, args.opset)
    print(f"wrote {out}")
    if args.check:
        net, _ = load_checkpoint(args.checkpoint, "cpu")
        x = torch.randn(1, net.config.in_channels, 123, 166)
        with torch.inference_mode():
            ref = inference_form(net)(x)
        got = OnnxRunner(out)(x)
        err = max(float((a - b).abs().max()) for a, b in zip(got, ref))
        print(f"max abs difference to torch on a 166x123 input: {err:.2e}")
    return 0
