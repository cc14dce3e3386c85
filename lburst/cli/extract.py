"""``lburst extract``: features of many bursts, one ``.npz`` each (and an hloc ``features.h5``).

Each BURST is a folder of frames, an image or a video (see :func:`lburst.burst.io.load_burst`).
Each ``.npz`` records what made it (:mod:`lburst.store`: the method spec, its weights'
SHA-1 and options, the burst's path and content SHA-1); a re-run skips a burst only when
its file holds the same burst by the same method, and recomputes it otherwise.  A name
that two different bursts map to (``a/b0`` and ``c/b0``) is refused for the second.
The common frame of each burst (the frame its features describe) is written as
``OUT/images/<name>.png`` (a recording's keyframe: ``OUT/images/<recording>/<keyframe>.png``).
``features.h5`` is written at the end from every lburst ``.npz`` in the output folder
(this run's and earlier runs'; of a recording, its last cut's keyframes, listed in
``OUT/<recording>/cut.json``), as hloc expects one features file per folder, with groups
named after those images (``<name>.png``, ``<recording>/<keyframe>.png``), so that hloc reads
an image from ``OUT/images`` and its keypoints from ``features.h5`` by one name.  Features are
keyed as ``lburst reconstruct`` keys them (:func:`lburst.store.key`).  Every file is
written atomically, and a burst that fails is reported and skipped: the exit code is 1 if any failed.
With ``--cluster`` the bursts to compute are tasks on a Dask cluster (:mod:`lburst.cluster`),
through the same loop (:func:`lburst.sfm.feature_stage.keyframe_features`), so they write the
same files, equal to a run in one process at the same ``--threads``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable, Iterable
from pathlib import Path

from tqdm import tqdm

from lburst import store
from lburst.burst.io import (
    BurstError,
    atomic_path,
    check_output_outside,
    h5_file,
    read_features_npz,
    write_features_h5,
)
from lburst.cli.numbers import integer
from lburst.cli.options import add_cluster_argument, add_recording_arguments, parse_method, recording_options
from lburst.cluster.runner import Runner, open_runner
from lburst.cluster.spec import parse_cluster
from lburst.errors import LBurstFileNotFoundError
from lburst.methods import Method
from lburst.model.network import AUTOCAST_DTYPES
from lburst.model.runtimes import RUNTIMES
from lburst.sfm.feature_stage import KeyframeBurst, Layout, compute_for, keyframe_features
from lburst.sfm.inputs import InputSource, burst_name, open_bursts
from lburst.sfm.outputs import IMAGES

CUT_FILE = "cut.json"
#: keypoints per burst of a learned method whose spec sets no top_k and no --top-k is given
DEFAULT_TOP_K = 4000


def chosen_method(method: Method | None, weights: str | None, frame_order: str | None = None) -> Method:
    """The method of ``--method``/``--weights``/``--frame-order``: ``lburst`` (shipped weights) by
    default; ``--weights`` (else ``$LBURST_WEIGHTS``) is the checkpoint of a method that names none."""
    method = (method or Method("lburst")).with_weights(weights or os.environ.get("LBURST_WEIGHTS"))
    return method.with_option("frame_order", frame_order) if frame_order else method


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "bursts",
        nargs="+",
        type=Path,
        help="burst folders, images or videos (a whole video, or a folder of frames without meta.json, is one "
        "burst unless --every or --motion is given), or recordings: features of each keyframe burst go to "
        "OUT/<recording>/<keyframe>.npz",
    )
    p.add_argument("--out", type=Path, required=True, help="output folder for <burst>.npz")
    p.add_argument("--weights", help="checkpoint (default: $LBURST_WEIGHTS, else the shipped lburst-b5)")
    p.add_argument(
        "--method", type=parse_method, help="any method spec, e.g. sift, orb, merge+sift, buff (default: lburst)"
    )
    p.add_argument(
        "--frame-order",
        choices=["temporal", "published"],
        help="frame order for burst networks ('published' for the published LBurst weights)",
    )
    p.add_argument(
        "--top-k",
        type=integer(1),
        help=f"keypoints per burst of a learned method (default: the spec's top_k=N, else {DEFAULT_TOP_K}); "
        "an explicit --top-k that disagrees with the spec's top_k is refused",
    )
    p.add_argument("--h5", action="store_true", help="also write an hloc-style features.h5 in --out")
    p.add_argument("--overwrite", action="store_true", help="recompute bursts that are already done")
    p.add_argument("--device", help="cpu or cuda (default: cuda if available)")
    p.add_argument(
        "--precision",
        choices=list(AUTOCAST_DTYPES),
        default="fp32",
        help="backbone precision of learned methods: bf16 is faster on CPUs with AVX512-BF16 or AMX "
        "(heads stay fp32; about 99%% of keypoints within 1 px of fp32), fp16 on a GPU",
    )
    p.add_argument(
        "--runtime",
        choices=["auto", *RUNTIMES],
        help="what runs a learned network on the CPU (default: auto, the fastest this CPU has, for the light "
        "network lburst-lite; torch for the others); the bf16 and int8 runtimes move some keypoints",
    )
    p.add_argument(
        "--threads",
        type=integer(1, 1024),
        help="torch threads per burst (default: torch's own in one process, 1 per worker with --cluster); "
        "the features of lburst-b5 equal byte for byte only at equal thread counts",
    )
    add_cluster_argument(p, "the bursts")
    add_recording_arguments(p)


def write_cut(folder: Path, path: Path, options, names: list[str]) -> None:
    """``folder/cut.json``: the recording, how it was cut and its keyframes' names, in order
    (what ``features.h5`` holds of this folder); says how many ``.npz`` of an earlier cut stay."""
    if not folder.is_dir():
        return
    cut = {"recording": str(path), "options": options.signature(), "keyframes": names}
    with atomic_path(folder / CUT_FILE) as tmp:
        tmp.write_text(json.dumps(cut, indent=1))
    listed = set(names)
    stale = [p for p in folder.glob("*.npz") if p.stem not in listed and store.read_meta(p) is not None]
    if stale:
        tqdm.write(
            f"{path}: {len(stale)} keyframes of an earlier cut stay in {folder}; {CUT_FILE} and features.h5 "
            f"list this cut's {len(names)} ({options.signature().split(',gain=')[0]})"
        )


def features_in_folder(out: Path) -> dict[str, Path]:
    """features.h5 group -> ``.npz`` of every lburst features file in ``out`` (a burst's
    ``NAME.npz``: group ``NAME.png``, a recording's ``REC/KEYFRAME.npz``: ``REC/KEYFRAME.png``, the
    names of their images in ``out/images``); files without lburst's metadata are left out, and so is
    the features cache of a ``lburst reconstruct --out`` into the same folder (``out/features``)."""
    found, cuts = {}, {}
    for npz in sorted(list(out.glob("*.npz")) + list(out.glob("*/*.npz"))):
        if npz.parent not in cuts:
            cuts[npz.parent] = this_cut(npz.parent)  # one read of cut.json per folder
        cut = cuts[npz.parent]
        if npz.parent == out / "features" and cut is None:
            continue
        if (cut is None or npz.stem in cut) and store.read_meta(npz) is not None:
            found[npz.relative_to(out).with_suffix(".png").as_posix()] = npz
    return found


def this_cut(folder: Path) -> set[str] | None:
    """The keyframe names of ``folder``'s last cut (its ``cut.json``), or ``None`` when it has none."""
    try:
        return set(json.loads((folder / CUT_FILE).read_text())["keyframes"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def write_h5(path: Path, finished: list[tuple[str, Path]]) -> None:
    """hloc's ``features.h5`` from finished ``.npz`` files (group name, file), atomically."""
    with atomic_path(path) as tmp:
        with h5_file(tmp, "w"):
            pass  # a new, empty file (h5py appends to an existing one), even when none finished
        for group, npz in finished:
            features = read_features_npz(npz)
            write_features_h5(tmp, group, features, tuple(int(v) for v in features["imsize"]))


def extract_input(
    bursts: Iterable[KeyframeBurst],
    folder: str,
    compute,
    args: argparse.Namespace,
    finished: list[tuple[str, Path]],
    runner: Runner,
    failed: Callable[[KeyframeBurst, Exception], None] | None = None,
    names: list[str] | None = None,
) -> tuple[int, int]:
    """Features of ``bursts`` (:func:`lburst.sfm.feature_stage.keyframe_features`), one ``.npz``
    each in ``OUT/<folder>/`` with its common frame in ``OUT/images/<folder>/`` (``folder``:
    :attr:`lburst.sfm.inputs.InputSource.folder`, a recording's name, else none), computed in
    this process or as tasks of ``runner`` on a cluster; returns (computed, already done) and
    appends each finished burst to ``finished`` as (features.h5 group, ``.npz``) and its name
    to ``names`` (sorted at the end, even on failure), so that those done before a failure are
    kept.  ``failed``: a burst that fails is reported there and the others go on (by default
    its error ends the call)."""
    layout = Layout(args.out / folder, args.out / IMAGES / folder)
    done = skipped = 0
    names = [] if names is None else names
    try:
        for burst in keyframe_features(
            bursts,
            compute,
            layout,
            reuse=not args.overwrite,
            protect=True,
            runner=runner,
            failed=failed,
            progress=True,
            desc=f"extract {folder or 'bursts'}",
        ):
            done, skipped = done + burst.computed, skipped + (not burst.computed)
            group = layout.image_path(burst.burst.name).relative_to(args.out / IMAGES).as_posix()
            finished.append((group, layout.features_path(burst.burst.name)))
            names.append(burst.burst.name)
    finally:
        names.sort()  # on a cluster they finish in any order; keyframe names sort in frame order
    return done, skipped


def extract_recording(
    source: InputSource, compute, args: argparse.Namespace, method: dict, finished: list[tuple[str, Path]], runner
) -> tuple[int, int]:
    """Features of every keyframe burst of a recording (:func:`extract_input`); returns (computed,
    already done).  The names it finished go to ``OUT/<folder>/cut.json`` (:func:`write_cut`),
    even when it fails."""
    names: list[str] = []
    try:
        return extract_input(
            source.keyframe_bursts(method), source.folder, compute, args, finished, runner, None, names
        )
    finally:
        write_cut(args.out / source.folder, source.path, recording_options(args), names)


def skip(path: Path, why: str, failed: list[tuple[Path, str]]) -> None:
    """Report a burst that failed on stderr and keep it for the summary."""
    failed.append((path, why))
    tqdm.write(f"skipped {why if why.startswith(str(path)) else f'{path}: {why}'}", file=sys.stderr)


def extract_bursts(
    pending: list[tuple[Path, KeyframeBurst]],
    compute,
    args: argparse.Namespace,
    finished: list[tuple[str, Path]],
    runner: Runner,
    failed: list[tuple[Path, str]],
) -> int:
    """Features of single bursts, one ``OUT/<name>.npz`` each, in one map (on a cluster, in
    parallel); a burst that fails is skipped and reported.  Returns how many were computed."""
    paths = {burst.name: path for path, burst in pending}

    def report(burst: KeyframeBurst, exc: Exception) -> None:
        skip(paths[burst.name], str(exc), failed)

    new, _ = extract_input([b for _, b in pending], "", compute, args, finished, runner, report)
    pending.clear()
    return new


def main(args: argparse.Namespace) -> int:
    chosen = chosen_method(args.method, args.weights, args.frame_order)
    # the spec's own top_k=N wins over the default; an explicit --top-k that disagrees is refused
    chosen = chosen.with_given("top_k", args.top_k, "--top-k").with_default("top_k", DEFAULT_TOP_K)
    cluster = parse_cluster(args.cluster) if args.cluster is not None else None
    missing = [path for path in args.bursts if not path.exists()]
    if missing:  # nothing done, no --out made: a typo is not a burst that failed
        more = f" (and {len(missing) - 1} more inputs)" if len(missing) > 1 else ""
        raise LBurstFileNotFoundError(f"{missing[0]}: no such file or folder{more}")
    check_output_outside(args.out, args.bursts)
    wanted = {
        "device": args.device,
        "precision": args.precision if args.precision != "fp32" else None,
        "runtime": args.runtime,
    }
    options = {k: v for k, v in wanted.items() if v is not None and chosen.accepts(k)}  # learned methods have them
    chosen.check(**options)  # a bad spec or option is one line (exit 2) before any work, with --cluster too
    extractor = chosen.create(**options) if cluster is None else None  # on a cluster: one per worker
    cut = recording_options(args)
    method = store.method_key(chosen, **{k: v for k, v in options.items() if k != "device"})
    failed: list[tuple[Path, str]] = []
    finished: list[tuple[str, Path]] = []  # (features.h5 group, .npz) of every finished burst
    names: dict[str, Path] = {}
    done = 0
    with open_runner(cluster) as runner:  # a cluster that cannot be reached leaves no --out
        args.out.mkdir(parents=True, exist_ok=True)
        compute = compute_for(chosen, runner, extractor, options, args.threads)
        pending: list[tuple[Path, KeyframeBurst]] = []  # single bursts, mapped together
        for path in args.bursts:
            source = open_bursts(path, cut)  # a burst, or a recording cut into keyframe bursts
            if source.folder:  # the single bursts before it first
                done += extract_bursts(pending, compute, args, finished, runner, failed)
            try:
                here = Path(os.path.abspath(path))
                if names.setdefault(burst_name(path), here) != here:
                    raise BurstError(
                        f"{path}: same output name {burst_name(path)!r} as {names[burst_name(path)]} in this run; "
                        "extract one of them into another --out"
                    )
                if not source.folder:
                    pending.extend((path, burst) for burst in source.keyframe_bursts(method))
                    continue
                new, old = extract_recording(source, compute, args, method, finished, runner)
            except (BurstError, ValueError, OSError, RuntimeError) as exc:  # a missing extra (ImportError) ends the run
                skip(path, str(exc), failed)
                continue
            tqdm.write(f"{path}: {new} keyframes extracted, {old} already done")
            if source.error:
                failed.append((path, source.error))
                tqdm.write(f"stopped {path}: {source.error}", file=sys.stderr)
                continue
            done += new > 0
        done += extract_bursts(pending, compute, args, finished, runner, failed)
    if args.h5:
        write_h5(args.out / "features.h5", sorted({**features_in_folder(args.out), **dict(finished)}.items()))
    print(
        f"{done} bursts extracted to {args.out}, {len(args.bursts) - done - len(failed)} already done, "
        f"{len(failed)} failed"
    )
    for path, why in failed:
        print(f"  failed: {why if why.startswith(str(path)) else f'{path}: {why}'}", file=sys.stderr)
    return 1 if failed else 0
