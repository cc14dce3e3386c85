"""Which pyramid levels and how many keypoints buy matches: the homography benchmark of one
method under several extraction settings, with their seconds per image.

Each variant is ``NAME=OPTIONS``: the method spec's ``KEY=VALUE`` options (fields of
:class:`lburst.model.extractor.MultiScaleConfig`), e.g. ``no1024=max_size=768``.  The
benchmark runs once per variant (``lburst bench homography``, cached by method spec, so a
rerun only adds new variants); the table gives MMA@3, MMA@1, keypoints, mutual matches and
correct matches (matches x MMA@3) per image pair, and the benchmark's seconds per image
(extraction only, on whatever else the machine runs: compare within one table).

    python scripts/scales_topk.py data/validation --every 4 --sigma 100 \\
        --method lburst-lite --out outputs/scales_topk
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

#: the paper's pyramid (1024 down to 256 px in steps of 2^(1/4)), and the variants measured
DEFAULT_VARIANTS = (
    "paper=",
    "no1024=max_size=768",
    "from362=min_size=362",
    "from512=min_size=512",
    "steps2^0.5=scale_factor=1.41421356",
    "top2000=top_k=2000",
    "top8000=top_k=8000",
)


def parse_variant(text: str) -> tuple[str, str]:
    """``NAME=K=V,K=V`` -> (name, ``,K=V,K=V``); ``NAME=`` is the method's defaults."""
    name, _, options = text.partition("=")
    if not name:
        raise argparse.ArgumentTypeError(f"variant {text!r}: expected NAME=OPTIONS")
    return name, f",{options}" if options else ""


def summary(results: dict, spec: str, sigma: float) -> dict:
    block = results["methods"][spec][f"sigma{sigma:g}"]["summary"]["all"]
    return {
        "mma3": block["mma"][2],
        "mma1": block["mma"][0],
        "keypoints": block["keypoints"],
        "matches": block["matches"],
        "correct": block["matches"] * block["mma"][2],
        "seconds": block.get("seconds"),
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", type=Path)
    p.add_argument("--method", default="lburst-lite", help="method spec without options (default lburst-lite)")
    p.add_argument("--variants", nargs="+", type=parse_variant, default=[parse_variant(v) for v in DEFAULT_VARIANTS])
    p.add_argument("--sigma", type=float, nargs="+", default=[100.0])
    p.add_argument("--every", type=int, default=1)
    p.add_argument("--out", type=Path, default=Path("outputs/scales_topk"))
    args = p.parse_args()
    rows = []
    for name, options in args.variants:
        pairs = [o for o in options.split(",") if o]
        top_k = next((o.split("=", 1)[1] for o in pairs if o.startswith("top_k=")), "4000")  # LBurst.extract's
        spec = args.method + "".join(f",{o}" for o in pairs if not o.startswith("top_k="))
        bench_out = args.out / name
        cmd = ["bench", "homography", str(args.data), "--every", str(args.every), "--top-k", top_k, "--sigma"]
        cmd += [f"{s:g}" for s in args.sigma] + ["--methods", spec, "--out", str(bench_out)]
        subprocess.run([sys.executable, "-m", "lburst.cli", *cmd], check=True, stdout=subprocess.DEVNULL)
        results = json.loads((bench_out / "results.json").read_text())
        for sigma in args.sigma:
            rows.append(
                {"variant": name, "spec": spec, "top_k": int(top_k), "sigma": sigma, **summary(results, spec, sigma)}
            )
    print(f"\n{args.method} on {args.data} (every {args.every}), per image pair\n")
    print("| variant | σ | MMA@3 | MMA@1 | keypoints | matches | correct | s / image |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        seconds = "-" if r["seconds"] is None else f"{r['seconds']:.2f}"
        print(
            f"| {r['variant']} | {r['sigma']:g} | {r['mma3']:.3f} | {r['mma1']:.3f} | {r['keypoints']:.0f} | "
            f"{r['matches']:.0f} | {r['correct']:.0f} | {seconds} |"
        )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "scales_topk.json").write_text(json.dumps({"data": str(args.data), "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
