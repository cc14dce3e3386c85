"""``lburst extract``: features of many bursts, one ``.npz`` each (and an hloc ``features.h5``).

Each BURST is a folder of frames, an image or a video (see :func:`lburst.io.load_burst`).
Finished bursts are skipped on a re-run, every file is written atomically, and a
burst that fails is reported and skipped: the exit code is 1 if any failed.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from tqdm import tqdm

from lburst.io import BurstError, load_burst, write_features_h5, write_features_npz
from lburst.methods import create
from lburst.model import AUTOCAST_DTYPES, CheckpointError
from lburst.sources import add_recording_arguments, is_recording, open_recording, recording_options


def burst_name(path: Path) -> str:
    """A burst's name in outputs: the folder or file name without suffix."""
    return path.stem if path.is_file() else path.name


def method_spec(method: str | None, weights: str | None, frame_order: str | None = None) -> str:
    """The method spec for ``--method``/``--weights``: ``lburst`` (shipped weights) by default."""
    weights = weights or os.environ.get("LBURST_WEIGHTS")
    if method is None:
        spec = f"lburst:{weights}" if weights else "lburst"
    elif weights and ":" not in method.split(",")[0]:
        spec = f"{method}:{weights}"
    else:
        spec = method
    if frame_order:
        spec += f",frame_order={frame_order}"
    return spec


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("bursts", nargs="+", type=Path,
                   help="burst folders, images or videos (a whole video is one burst unless --every is given), "
                        "or recordings: features of each keyframe burst go to OUT/<recording>/<keyframe>.npz")
    p.add_argument("--out", type=Path, required=True, help="output folder for <burst>.npz")
    p.add_argument("--weights", help="checkpoint (default: $LBURST_WEIGHTS, else the shipped lburst-b5)")
    p.add_argument("--method", help="any method spec, e.g. sift, orb, merge+sift, buff (default: lburst)")
    p.add_argument("--frame-order", choices=["temporal", "published"],
                   help="frame order for burst networks ('published' for the published LBurst weights)")
    p.add_argument("--top-k", type=int, default=4000, help="keypoints per burst (learned methods)")
    p.add_argument("--h5", action="store_true", help="also write an hloc-style features.h5 in --out")
    p.add_argument("--overwrite", action="store_true", help="recompute bursts that are already done")
    p.add_argument("--device", help="cpu or cuda (default: cuda if available)")
    p.add_argument("--precision", choices=list(AUTOCAST_DTYPES), default="fp32",
                   help="backbone precision of learned methods: bf16 is faster on CPUs with AVX512-BF16 or AMX "
                        "(heads stay fp32; about 99%% of keypoints within 1 px of fp32), fp16 on a GPU")
    add_recording_arguments(p)


def extract_recording(path: Path, extractor, args: argparse.Namespace) -> tuple[int, int, str | None]:
    """Features of every keyframe burst of a recording, one ``.npz`` each in ``OUT/<recording>/``;
    returns (extracted, already done, why reading stopped or ``None``).  Keyframes finished
    before a bad frame are kept."""
    folder = args.out / burst_name(path)
    done = skipped = 0
    try:
        for keyframe, burst in open_recording(path, recording_options(args)).bursts():
            target = folder / f"{keyframe.name}.npz"
            if target.exists() and not args.overwrite:
                skipped += 1
                continue
            features = extractor(burst)
            size = (burst.shape[2], burst.shape[1])
            if args.h5:
                write_features_h5(args.out / "features.h5", f"{burst_name(path)}/{keyframe.name}", features, size)
            folder.mkdir(parents=True, exist_ok=True)
            write_features_npz(target, features, size)
            done += 1
    except BurstError as exc:
        return done, skipped, str(exc)
    return done, skipped, None


def main(args: argparse.Namespace) -> int:
    spec = method_spec(args.method, args.weights, args.frame_order)
    options = {}
    if spec.startswith("lburst") or spec.startswith("r2d2"):
        options["top_k"] = str(args.top_k)
        if args.device:
            options["device"] = args.device
        if args.precision != "fp32":
            options["precision"] = args.precision
    try:
        extractor = create(spec, **options)
    except (CheckpointError, FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    failed: list[tuple[Path, str]] = []
    done = 0
    try:
        recording_options(args)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path in tqdm(args.bursts, desc=f"extract {spec}", unit="burst"):
        if is_recording(path) and (path.is_dir() or args.every is not None):
            new, old, problem = extract_recording(path, extractor, args)
            tqdm.write(f"{path}: {new} keyframes extracted, {old} already done")
            done += 1
            if problem:
                failed.append((path, problem))
                tqdm.write(f"stopped {path}: {problem}", file=sys.stderr)
                done -= 1
            continue
        name = burst_name(path)
        target = args.out / f"{name}.npz"
        if target.exists() and not args.overwrite:
            continue
        try:
            burst = load_burst(path)
            features = extractor(burst)
        except (BurstError, ValueError, OSError) as exc:
            failed.append((path, str(exc)))
            tqdm.write(f"skipped {path}: {exc}", file=sys.stderr)
            continue
        size = (burst.shape[2], burst.shape[1])
        if args.h5:
            write_features_h5(args.out / "features.h5", name, features, size)
        write_features_npz(target, features, size)  # last: its presence marks the burst done
        done += 1
    print(f"{done} bursts extracted to {args.out}, {len(args.bursts) - done - len(failed)} already done, "
          f"{len(failed)} failed")
    for path, why in failed:
        print(f"  failed: {path}: {why}", file=sys.stderr)
    return 1 if failed else 0
