"""Extraction speed: seconds per 5-frame burst at a 1024 px long side, per path.

Two paths time what a user gets from ``LBurst.pretrained(NAME).extract(burst)`` with every
default, alignment included: ``default`` (``lburst-b5``, or ``--weights``) and ``lite``
(``lburst-b5-lite``, or ``--lite-weights``: the light network on its fastest runtime);
the table gives the light model's speed-up over ``default`` measured in the same run.

The other paths: ``plain`` (the network run as the published code runs it: NCHW, full-resolution
128-D maps at every level), ``fast`` (lburst's default, same features), ``bf16``
(bfloat16 autocast of the backbone, heads in fp32) and ``onnx`` (the fast network
exported by ``lburst export onnx``, run by ONNX Runtime), and ``align`` (only the burst
alignment, :func:`lburst.burst.align.align_burst`, which ``LBurst`` runs before the network for
weights that ask for it, as the shipped ``lburst-b5``: add it to a network path's time).
The network paths run without alignment.  Each path runs in its own
process so its peak memory can be read; times are medians of ``--repeats`` runs after
one warm-up, on random weights unless ``--weights`` is given (the time does not depend
on the weights, the keypoint count does).  ``--batch B`` runs ``B`` bursts at once through
:meth:`lburst.LBurst.extract_batch` (what pays on a GPU) and reports seconds per burst.  ``bf16`` and ``onnx`` also report the share
of their keypoints within 1 px of a fast fp32 keypoint.

    python scripts/extract_speed.py --out outputs/extract_speed.json
    python scripts/extract_speed.py --device cuda --paths fast default lite --batch 8
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from lburst.model.precision import cpu_name

PATHS = ("plain", "fast", "bf16", "onnx", "align", "default", "lite")
#: what a user runs: shipped weights, every default, alignment included
USER_PATHS = ("default", "lite")


def _make_burst(size: tuple[int, int], frames: int) -> np.ndarray:
    import cv2
    import skimage.data

    photo = cv2.resize(skimage.data.astronaut(), (size[1], size[0]), interpolation=cv2.INTER_LINEAR)
    from lburst.noise import GaussianNoise
    from lburst.simulate import simulate_burst

    return simulate_burst(photo, frames, (1.5, 0.5), GaussianNoise(50.0), rng=0)


def run_child(path: str, args: argparse.Namespace) -> dict:
    from lburst.burst.align import align_burst
    from lburst.model.extractor import LBurst
    from lburst.model.network import LBurstNet, NetConfig

    torch.set_num_threads(args.threads)
    device = args.device
    if path in USER_PATHS:
        from lburst.weights import resolve_weights

        name = (args.lite_weights or "lburst-b5-lite") if path == "lite" else (args.weights or "lburst-b5")
        model = LBurst.from_checkpoint(resolve_weights(name), device=device)
    elif args.weights:
        model = LBurst.from_checkpoint(args.weights, device=device, align=False)
    else:
        torch.manual_seed(0)
        model = LBurst(LBurstNet(NetConfig(frames=5)), device=device)
    burst = np.load(args.burst_file, mmap_mode="r") if args.burst_file else _make_burst((args.height, args.width), 5)
    burst = np.ascontiguousarray(burst[: model.frames] if model.frames < 5 else burst)
    options = (
        {"rotations": args.rotations}
        if path in USER_PATHS
        else {"fast": path != "plain", "precision": "bf16" if path == "bf16" else "fp32"}
    )
    if path == "plain":
        model.net.to(memory_format=torch.contiguous_format)
    reference_model = model
    if path == "onnx":
        model = LBurst.from_onnx(args.onnx_model, threads=args.threads)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    times, count = [], 0
    for i in range(args.repeats + 1):
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        start = time.perf_counter()
        if path == "align":
            feats = align_burst(burst)
        elif args.batch > 1:
            feats = model.extract_batch([burst] * args.batch, top_k=args.top_k, **options)[0]
        else:
            feats = model.extract(burst, top_k=args.top_k, **options)
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        if i:
            times.append((time.perf_counter() - start) / (1 if path == "align" else args.batch))
        count = len(feats["scores"]) if path != "align" else 0
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    if path in ("bf16", "onnx"):  # agreement with fp32: share of keypoints within 1 px of an fp32 keypoint
        from scipy.spatial import cKDTree

        ref = reference_model.extract(burst, top_k=args.top_k)
        dist, _ = cKDTree(ref["keypoints"]).query(feats["keypoints"])
        agreement = float((dist <= 1).mean()) if len(dist) else None
    else:
        agreement = None
    result = {
        "path": path,
        "runtime": None if path == "align" else "onnxruntime" if path == "onnx" else getattr(model, "runtime", None),
        "median_s": statistics.median(times),
        "times_s": times,
        "keypoints": count,
        "peak_rss_mb": rss1 / 1024,
        "extra_rss_mb": (rss1 - rss0) / 1024,
        "agreement_1px": agreement,
    }
    if device.startswith("cuda"):
        result["peak_cuda_mb"] = torch.cuda.max_memory_allocated() / 2**20
    return result


def _cpu_flags() -> str:
    """The CPU's bf16 instructions (AMX or AVX512-BF16), which decide whether bf16 pays."""
    try:
        flags = next(
            line for line in Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("flags")
        ).split()
    except (OSError, StopIteration):
        return "unknown"
    found = [f for f in ("amx_bf16", "avx512_bf16") if f in flags]
    return ", ".join(found) or "none"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--paths", nargs="+", default=list(PATHS), choices=PATHS)
    p.add_argument("--weights", help="checkpoint (default: random weights; the default path: lburst-b5)")
    p.add_argument("--lite-weights", help="light checkpoint of the lite path (default: lburst-b5-lite)")
    p.add_argument("--height", type=int, default=768)
    p.add_argument("--width", type=int, default=1024)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--batch", type=int, default=1, help="bursts per call (extract_batch); times are per burst")
    p.add_argument("--top-k", type=int, default=4000)
    p.add_argument(
        "--rotations",
        type=int,
        default=1,
        choices=(1, 2, 4),
        help="the user paths also extract at 180 (2) or every 90 (4) degrees",
    )
    p.add_argument("--threads", type=int, default=torch.get_num_threads())
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--out", type=Path, help="JSON results")
    p.add_argument("--child", help=argparse.SUPPRESS)
    p.add_argument("--burst-file", help=argparse.SUPPRESS)
    p.add_argument("--onnx-model", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        print(json.dumps(run_child(args.child, args)))
        return 0
    import shutil
    import tempfile

    extra = []
    if "onnx" in args.paths:  # export here, so the onnx child's peak memory is that of running it
        from lburst.model.network import LBurstNet, NetConfig, save_checkpoint
        from lburst.model.onnx import export_onnx

        folder = Path(tempfile.mkdtemp(prefix="lburst-speed-"))
        checkpoint = args.weights
        if not checkpoint:
            torch.manual_seed(0)
            checkpoint = folder / "random.pt"
            save_checkpoint(LBurstNet(NetConfig(frames=5)), checkpoint)
        extra = ["--onnx-model", str(export_onnx(checkpoint, folder / "model.onnx"))]
    # the burst is made once here, so that a child's peak memory is that of reading and extracting it
    burst_file = Path(tempfile.mkdtemp(prefix="lburst-speed-burst-")) / "burst.npy"
    np.save(burst_file, _make_burst((args.height, args.width), 5))
    extra += ["--burst-file", str(burst_file)]
    results = []
    for path in args.paths:
        cmd = [sys.executable, __file__, "--child", path] + sys.argv[1:] + extra
        out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
        results.append(json.loads(out.strip().splitlines()[-1]))
    shutil.rmtree(burst_file.parent, ignore_errors=True)
    if "onnx" in args.paths:
        shutil.rmtree(Path(extra[1]).parent, ignore_errors=True)
    base = next((r["median_s"] for r in results if r["path"] == "plain"), None)
    default = next((r["median_s"] for r in results if r["path"] == "default"), None)
    device = torch.cuda.get_device_name() if args.device.startswith("cuda") else cpu_name()
    flags = _cpu_flags()
    print(
        f"\n5-frame burst {args.width}x{args.height}, {args.device} ({device}; native bf16: {flags}), "
        f"{args.threads} threads, median of {args.repeats}, batches of {args.batch}\n"
    )
    print(
        "| path | runtime | s / burst | speed-up vs plain | speed-up vs default | keypoints | within 1 px of fp32 | peak RSS MB |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for r in results:
        network = r["path"] not in ("align",) + USER_PATHS  # align and the user paths are no network path
        ratio = f"{base / r['median_s']:.2f}x" if base and network else "-"
        versus = f"{default / r['median_s']:.2f}x" if default and not network and r["path"] != "align" else "-"
        r["speedup_vs_default"] = default / r["median_s"] if versus != "-" else None
        agree = "-" if r["agreement_1px"] is None else f"{r['agreement_1px']:.3f}"
        print(
            f"| {r['path']} | {r['runtime'] or '-'} | {r['median_s']:.2f} | {ratio} | {versus} | {r['keypoints']} | {agree} | "
            f"{r['peak_rss_mb']:.0f} |"
        )
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(
            json.dumps(
                {
                    "device": device,
                    "bf16_hardware": flags,
                    "threads": args.threads,
                    "batch": args.batch,
                    "size": [args.width, args.height],
                    "results": results,
                },
                indent=2,
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
