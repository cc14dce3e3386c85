"""Where a burst network's matching loses to noise: its detector or its descriptors.

Every image of the homography benchmark becomes its protocol burst at noise σ
(:func:`lburst.bench.homography.protocol_burst`) and the same burst without noise (the same
in-burst motion).  The network runs on both, and the keypoints of one are described with the
descriptor map of the other, so each pair of sequences is matched four ways:

    detector  descriptors
    clean     clean          the noise-free burst
    clean     noisy          noise in the descriptors only
    noisy     clean          noise in the keypoints (and their scores) only
    noisy     noisy          the benchmark at σ (equal to `lburst bench homography --sigma σ`)

MMA, repeatability at 3 px and keypoints / matches per image as `lburst bench homography`
reports them (mutual nearest neighbours, pairs (1, k), mean over a sequence's pairs, then over
sequences; in the JSON as the benchmark's ``summary``, each sequence's ``seconds`` the four-way
extraction of one image):

    python scripts/drop_sources.py data/validation --every 4 --sigma 100 \
        --methods lburst "lburst:$LBURST_SHARED/anchors/RoBLo_N16_B5.pt,frame_order=published" \
        --out outputs/drop_sources_val100.json

Only networks on the fast path in torch (lburst-b5, the published checkpoints, and the light
network as ``lburst-lite,runtime=torch``: its default ONNX runtime takes one burst at a time),
at one rotation, without ``spread``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch
from tqdm import tqdm

from lburst.bench.homography import noise_levels, pair_metrics, protocol_burst, summarize
from lburst.bench.sequences import list_sequences, read_sequence
from lburst.burst.io import atomic_path
from lburst.errors import LBurstError, LBurstValueError
from lburst.methods import create
from lburst.model.extractor import LBurst
from lburst.simulate import simulate_burst

#: (detector, descriptors) of each batch entry: which burst the keypoints and the descriptors come from.
COMBOS = (("clean", "clean"), ("clean", "noisy"), ("noisy", "clean"), ("noisy", "noisy"))

_network_level = LBurst._fast_level


def _swapped_level(self: LBurst, x: torch.Tensor, precision: str):
    """For the batch (clean, clean, noisy, noisy): the network once on the clean and once on the
    noisy level, the maps of each entry's detector and the descriptor map of its descriptors."""
    rep, rel, desc = _network_level(self, x[[0, 2]], precision)
    detector, descriptors = [0, 0, 1, 1], [0, 1, 0, 1]
    return rep[detector], rel[detector], desc[descriptors]


def run(data: Path, every: int, sigma: float, spec: str, top_k: int) -> dict:
    extractor = create(spec, top_k=top_k)
    model = getattr(extractor, "model", None)
    if not isinstance(model, LBurst) or extractor.rotations != 1 or extractor.spread:
        raise LBurstValueError(f"{spec!r} is not a burst network at one rotation without spread")
    level = noise_levels([sigma], [])[0]
    per_pair: dict[tuple[str, str], dict[str, list[dict]]] = {combo: {} for combo in COMBOS}
    seconds: dict[str, float] = {}
    kinds: dict[str, str] = {}
    folders = list_sequences(data)[::every]
    bar = tqdm(total=6 * len(folders), desc=spec)
    for folder in folders:
        seq = read_sequence(folder)
        feats: dict[tuple[str, str], list] = {combo: [] for combo in COMBOS}
        start = time.perf_counter()
        for i, image in enumerate(seq.images):
            noisy, motion = protocol_burst(image, folder.name, i, level)
            clean = simulate_burst(image, len(noisy), motion)
            found = model.extract_batch([clean, clean, noisy, noisy], top_k=top_k, **extractor.options)
            for combo, f in zip(COMBOS, found):
                feats[combo].append(f)
            bar.update(1)
        seconds[folder.name] = (time.perf_counter() - start) / len(seq.images)
        kinds[folder.name] = seq.kind
        for combo in COMBOS:
            per_pair[combo][folder.name] = [pair_metrics(seq, feats[combo], k) for k in range(len(seq.images) - 1)]
    bar.close()
    return {
        f"{det} detector, {desc} descriptors": summarize(pairs, seconds, kinds)
        for (det, desc), pairs in per_pair.items()
    }


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("data", type=Path, help="sequences in Oxford or HPatches layout")
    parser.add_argument("--every", type=_positive, default=1, help="keep every n-th sequence (as the benchmark)")
    parser.add_argument("--sigma", type=float, default=100.0, help="Gaussian noise std on 0..255")
    parser.add_argument("--methods", nargs="+", default=["lburst"], help="method specs (burst networks)")
    parser.add_argument("--top-k", type=_positive, default=5000)
    parser.add_argument("--out", type=Path, required=True, help="JSON file to write")
    args = parser.parse_args()
    LBurst._fast_level = _swapped_level
    results = {"data": str(args.data), "every": args.every, "sigma": args.sigma, "top_k": args.top_k, "methods": {}}
    for spec in args.methods:
        try:
            results["methods"][spec] = run(args.data, args.every, args.sigma, spec, args.top_k)
        except LBurstError as exc:
            parser.exit(2, f"drop_sources.py: {exc}\n")
        print(f"\n{spec} (σ {args.sigma:g}): MMA@3 / MMA@1, repeatability@3, keypoints / matches per image")
        for name, summary in results["methods"][spec].items():
            r = summary["all"]
            print(
                f"  {name:36s} {r['mma'][2]:.3f} / {r['mma'][0]:.3f}   {r['rep3']:.3f}   {r['keypoints']:.0f} / {r['matches']:.0f}"
            )
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(args.out) as tmp:  # after every method, so a failure keeps the ones done
            tmp.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
