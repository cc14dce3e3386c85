"""Runtime speed of the light network: seconds per multi-scale extraction, per CPU runtime.

Times the full ``LBurst.extract(burst, top_k=4000)`` (9 pyramid levels, 1024 down to 256 px)
of a 1024x768 5-frame burst (the astronaut, simulated as in ``scripts/extract_speed.py``) with
the light network (random weights, or ``--weights``) on each runtime of
:mod:`lburst.model.runtimes`: ``torch`` (``LBurst(net)``, fp32), ``torch-bf16`` (its
``precision='bf16'``), ``onnxruntime``, ``onnxruntime-int8``, ``openvino``, ``openvino-bf16``
(only on CPUs with native bf16) and ``openvino-int8``; plus the Fast-Quad-L2-Net
(``LBurst(LBurstNet(NetConfig(frames=5)))``, torch fp32 fast path) as the reference row.

All runtimes run in one process, interleaved: after a warm-up round (which pays OpenVINO's
per-shape compiles; ``first s``), each of ``--repeats`` rounds runs every runtime once, so a
load that comes and goes (another job on the machine) hits them alike.  The table gives the
median wall time and the median CPU time of the process (``time.process_time``: with one
thread the time the extraction actually ran, the steadier number on a shared machine).  The
burst alignment is not timed (the burst is aligned once before, when the weights read aligned
bursts).  Against torch fp32 the table reports the max abs difference of the raw maps
(repeatability, reliability, raw descriptor map) at the full-size level, and with ``--weights``
the share of keypoints within 1 px of a torch fp32 keypoint.

    taskset -c 0 python scripts/runtime_speed.py --threads 1 --out outputs/runtime_speed_1.json
    taskset -c 0,1 python scripts/runtime_speed.py --threads 2 --out outputs/runtime_speed_2.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from lburst.model.precision import cpu_name

RUNTIMES = ("torch", "torch-bf16", "onnxruntime", "onnxruntime-int8", "openvino", "openvino-bf16", "openvino-int8")
REFERENCE = "fast-quad-l2 (torch)"


def _make_burst(size: tuple[int, int], frames: int) -> np.ndarray:
    """The burst of ``scripts/extract_speed.py``: the astronaut, 1.5 x 0.5 px per frame, Gaussian noise 50."""
    import cv2
    import skimage.data

    from lburst.noise import GaussianNoise
    from lburst.simulate import simulate_burst

    photo = cv2.resize(skimage.data.astronaut(), (size[1], size[0]), interpolation=cv2.INTER_LINEAR)
    return simulate_burst(photo, frames, (1.5, 0.5), GaussianNoise(50.0), rng=0)


def _cpu_features() -> str:
    from lburst.model.precision import cpu_flags

    flags = cpu_flags() or set()
    found = [f for f in ("amx_bf16", "amx_int8", "avx512_bf16", "avx512_vnni", "avx_vnni", "avx512f") if f in flags]
    return ", ".join(found) or "none"


def _agreement(ref: dict, got: dict) -> float | None:
    """Share of ``got``'s keypoints within 1 px of one of ``ref``'s."""
    from scipy.spatial import cKDTree

    if not len(got["keypoints"]) or not len(ref["keypoints"]):
        return None
    dist, _ = cKDTree(ref["keypoints"]).query(got["keypoints"])
    return float((dist <= 1).mean())


def _load_net(args: argparse.Namespace):
    from lburst.model.lite import LiteConfig, LiteNet
    from lburst.model.network import load_checkpoint

    if args.weights:
        net, extra = load_checkpoint(args.weights, "cpu")
        meta = extra.get("meta") if isinstance(extra.get("meta"), dict) else {}
        return net, meta
    torch.manual_seed(0)
    return LiteNet(LiteConfig(frames=5)).eval(), {}


def build(args: argparse.Namespace, net, meta: dict, threads: int, workdir: Path, shared: dict) -> dict:
    """``{name: (LBurst, extract options, setup seconds)}`` for the runtimes asked for, at ``threads``."""
    from lburst import calibration
    from lburst.model import openvino as ov
    from lburst.model import runtimes as rt
    from lburst.model.extractor import LBurst
    from lburst.model.network import LBurstNet, NetConfig
    from lburst.model.onnx import OnnxRunner, export_network_onnx, quantize_onnx

    models: dict[str, tuple] = {}
    torch.manual_seed(0)
    models[REFERENCE] = (LBurst(LBurstNet(NetConfig(frames=5))), {}, 0.0)
    frames = net.config.frames
    for name in args.runtimes:
        if not rt.available(name):
            print(f"skipping {name}: not available here", file=sys.stderr)
            continue
        start = time.perf_counter()
        if name in ("torch", "torch-bf16"):
            model, options = LBurst(net), {"precision": "bf16" if name == "torch-bf16" else "fp32"}
        else:
            if name.endswith("int8") and "calibration" not in shared:
                t0 = time.perf_counter()
                shared["calibration"] = calibration.calibration_bursts(
                    args.photos, count=args.calibration, frames=frames, seed=args.seed
                )
                shared["calibration_s"] = time.perf_counter() - t0
            if name.startswith("onnxruntime"):
                if "onnx" not in shared:
                    t0 = time.perf_counter()
                    shared["onnx"] = export_network_onnx(net, workdir / "model.onnx", meta)
                    shared["export_s"] = time.perf_counter() - t0
                path = shared["onnx"]
                if name == "onnxruntime-int8":
                    if "onnx_int8" not in shared:
                        t0 = time.perf_counter()
                        shared["onnx_int8"] = quantize_onnx(path, workdir / "model-int8.onnx", shared["calibration"])
                        shared["quantize_onnx_s"] = time.perf_counter() - t0
                    path = shared["onnx_int8"]
                runner = OnnxRunner(path, threads=threads)
            else:
                if "ov" not in shared:
                    t0 = time.perf_counter()
                    shared["ov"] = ov.openvino_model(net, meta)
                    shared["convert_openvino_s"] = time.perf_counter() - t0
                model = shared["ov"]
                if name == "openvino-int8":
                    if "ov_int8" not in shared:
                        t0 = time.perf_counter()
                        shared["ov_int8"] = ov.quantize_openvino(model, shared["calibration"])
                        shared["quantize_openvino_s"] = time.perf_counter() - t0
                    model = shared["ov_int8"]
                runner = ov.OpenVinoRunner(
                    model, threads=threads, precision="bf16" if name == "openvino-bf16" else "fp32"
                )
            model, options = LBurst(None, runner=runner, frames=frames), {}
        models[name] = (model, options, time.perf_counter() - start)
    return models


def raw_maps(name: str, model, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """The raw maps of one level (``x``) as ``model`` computes them for runtime ``name``."""
    from lburst.model.runtimes import inference_form

    with torch.inference_mode():
        if name in ("torch", "torch-bf16"):
            return inference_form(model.net, "bf16" if name == "torch-bf16" else "fp32")(x)
        return model.fast_net(x)


def run(args: argparse.Namespace, threads: int) -> list[dict]:
    from lburst.burst.align import align_burst
    from lburst.model.network import normalize_burst

    torch.set_num_threads(threads)
    net, meta = _load_net(args)
    burst = _make_burst((args.height, args.width), net.config.frames)
    if meta.get("input") == "aligned" or args.aligned:
        burst = align_burst(burst)
    workdir = Path(tempfile.mkdtemp(prefix="lburst-runtime-speed-"))
    shared = args.shared
    models = build(args, net, meta, threads, workdir, shared)
    names = list(models)
    wall: dict[str, list[float]] = {n: [] for n in names}
    cpu: dict[str, list[float]] = {n: [] for n in names}
    feats: dict[str, dict] = {}
    first: dict[str, float] = {}
    for round_ in range(args.repeats + 1):
        for name in names:
            model, options, _ = models[name]
            t0, c0 = time.perf_counter(), time.process_time()
            out = model.extract(burst, top_k=args.top_k, **options)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            if round_ == 0:
                first[name], feats[name] = dt, out
            else:
                wall[name].append(dt)
                cpu[name].append(dc)
    x = normalize_burst(burst)
    reference_maps = raw_maps("torch", models["torch"][0], x) if "torch" in models else None
    results = []
    for name in names:
        model, _, setup = models[name]
        diff = agreement = None
        if name != REFERENCE and reference_maps is not None:
            maps = raw_maps(name, model, x)
            diff = {
                key: float((a.float() - b.float()).abs().max())
                for key, a, b in zip(("repeatability", "reliability", "descriptor_map"), maps, reference_maps)
            }
            if args.weights and "torch" in feats:
                agreement = _agreement(feats["torch"], feats[name])
        results.append(
            {
                "runtime": name,
                "threads": threads,
                "median_s": statistics.median(wall[name]),
                "cpu_median_s": statistics.median(cpu[name]),
                "times_s": wall[name],
                "cpu_times_s": cpu[name],
                "first_s": first[name],
                "setup_s": setup,
                "compile_s": getattr(getattr(model, "_runner", None), "compile_seconds", None),
                "keypoints": len(feats[name]["scores"]),
                "max_abs_diff": diff,
                "agreement_1px": agreement,
            }
        )
    return results


def _table(results: list[dict], threads: int, args: argparse.Namespace) -> str:
    rows = [r for r in results if r["threads"] == threads]
    base = next((r for r in rows if r["runtime"] == "torch"), None)
    ref = next((r for r in rows if r["runtime"] == REFERENCE), None)
    lines = [
        f"\n{threads} thread(s), {args.width}x{args.height} 5-frame burst, median of {args.repeats} "
        f"(indicative: shared machine)\n",
        "| runtime | s / burst | CPU s / burst | vs torch fp32 | vs Fast-Quad-L2-Net | first s | keypoints "
        "| max abs diff rep / rel / desc | within 1 px of torch fp32 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    key = "cpu_median_s" if threads == 1 else "median_s"  # CPU time of several threads counts their waits
    for r in rows:
        vs_torch = f"{base[key] / r[key]:.2f}x" if base else "-"
        vs_ref = f"{ref[key] / r[key]:.1f}x" if ref else "-"
        d = r["max_abs_diff"]
        diff = "-" if d is None else " / ".join(f"{v:.1e}" for v in d.values())
        agree = "-" if r["agreement_1px"] is None else f"{r['agreement_1px']:.3f}"
        lines.append(
            f"| {r['runtime']} | {r['median_s']:.3f} | {r['cpu_median_s']:.3f} | {vs_torch} | {vs_ref} | "
            f"{r['first_s']:.2f} | {r['keypoints']} | {diff} | {agree} |"
        )
    lines.append(f"\n(speed-ups are ratios of {'CPU' if threads == 1 else 'wall'} time)")
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runtimes", nargs="+", default=list(RUNTIMES), choices=RUNTIMES)
    p.add_argument("--weights", help="checkpoint of the light network (default: random weights)")
    p.add_argument("--aligned", action="store_true", help="align the burst first (the weights' meta may say so too)")
    p.add_argument("--height", type=int, default=768)
    p.add_argument("--width", type=int, default=1024)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--top-k", type=int, default=4000)
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    p.add_argument("--calibration", type=int, default=24, help="calibration bursts for the int8 runtimes")
    p.add_argument("--photos", type=Path, help="calibration photo folder (default $LBURST_SHARED/data/train)")
    p.add_argument("--seed", type=int, default=0, help="seed of the calibration bursts")
    p.add_argument("--out", type=Path, help="JSON results")
    args = p.parse_args()
    args.shared = {}  # exports, quantised models and calibration data, shared by the thread counts
    results = []
    for threads in args.threads:
        results += run(args, threads)
    print(f"\nCPU: {cpu_name()} ({_cpu_features()}); torch {torch.__version__}")
    for key in ("calibration_s", "export_s", "quantize_onnx_s", "convert_openvino_s", "quantize_openvino_s"):
        if key in args.shared:
            print(f"{key}: {args.shared[key]:.1f}")
    for threads in args.threads:
        print(_table(results, threads, args))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        versions = {}
        for module in ("onnxruntime", "openvino", "nncf"):
            try:
                versions[module] = __import__(module).__version__
            except ImportError:
                pass
        args.out.write_text(
            json.dumps(
                {
                    "cpu": cpu_name(),
                    "cpu_features": _cpu_features(),
                    "torch": torch.__version__,
                    "versions": versions,
                    "weights": args.weights,
                    "size": [args.width, args.height],
                    "repeats": args.repeats,
                    "setup_s": {k: v for k, v in args.shared.items() if k.endswith("_s")},
                    "results": results,
                },
                indent=2,
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
