"""Features of many bursts, one ``.npz`` each (and an hloc ``features.h5``): the work of
``lburst extract`` (:func:`extract`).

Each burst is a folder of frames, an image or a video (see :func:`lburst.burst.io.load_burst`).
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
written atomically, and a burst that fails is reported and skipped (:attr:`ExtractReport.failed`).
With ``cluster`` the bursts to compute are tasks on a Dask cluster (:mod:`lburst.cluster`),
through the same loop (:func:`lburst.sfm.feature_stage.keyframe_features`), so they write the
same files, equal to a run in one process at the same ``threads``.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
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
from lburst.burst.sources import RecordingOptions
from lburst.cluster.runner import Runner, open_runner
from lburst.cluster.spec import ClusterSpec, parse_cluster
from lburst.errors import LBurstFileNotFoundError
from lburst.methods import Method
from lburst.sfm.feature_stage import KeyframeBurst, Layout, compute_for, keyframe_features
from lburst.sfm.inputs import InputSource, burst_name, open_bursts
from lburst.sfm.outputs import IMAGES

CUT_FILE = "cut.json"
#: keypoints per burst of a learned method whose spec sets no top_k and no --top-k is given
DEFAULT_TOP_K = 4000


@dataclass
class ExtractReport:
    """What :func:`extract` did with its ``inputs``: ``done`` of them computed (a recording counts
    once), each burst ``finished`` as (``features.h5`` group, ``.npz``), the ``failed`` inputs as
    (path, why)."""

    out: Path
    inputs: int
    done: int = 0
    finished: list[tuple[str, Path]] = field(default_factory=list)
    failed: list[tuple[Path, str]] = field(default_factory=list)

    @property
    def already(self) -> int:
        """Inputs whose features were all stored already."""
        return self.inputs - self.done - len(self.failed)


@dataclass
class _Run:
    """One extraction: where it writes, whether it recomputes, what computes a burst and where."""

    out: Path
    overwrite: bool
    compute: Callable
    runner: Runner
    recording: RecordingOptions
    report: ExtractReport


def extract_method(method: str | Method | None = None, top_k: int | None = None) -> Method:
    """``method`` (``None``: ``lburst``) with its keypoints: the spec's own ``top_k=N`` wins over
    :data:`DEFAULT_TOP_K`; a ``top_k`` that disagrees with the spec's is refused."""
    chosen = Method.of(method) if method is not None else Method("lburst")
    return chosen.with_given("top_k", top_k, "--top-k").with_default("top_k", DEFAULT_TOP_K)


def extract(
    bursts: Sequence[str | Path],
    out: str | Path,
    method: str | Method | None = None,
    *,
    top_k: int | None = None,
    overwrite: bool = False,
    h5: bool = False,
    device: str | None = None,
    precision: str = "fp32",
    runtime: str | None = None,
    threads: int | None = None,
    recording: RecordingOptions | None = None,
    cluster: ClusterSpec | str | None = None,
) -> ExtractReport:
    """The features of ``bursts`` (bursts or recordings) by ``method`` (its keypoints by
    :func:`extract_method`) into ``out`` (module docstring), in this process or, with ``cluster``,
    on a Dask cluster; ``device``, ``precision`` and ``runtime`` for a learned method, torch at
    ``threads``; ``h5``: also ``OUT/features.h5``.  A bad method, a missing input or an output
    inside an input raises before any work; a burst that fails is reported in
    :attr:`ExtractReport.failed` and the others go on."""
    chosen = extract_method(method, top_k)
    cluster = parse_cluster(cluster) if isinstance(cluster, str) else cluster
    paths, out = [Path(p) for p in bursts], Path(out)
    missing = [path for path in paths if not path.exists()]
    if missing:  # nothing done, no --out made: a typo is not a burst that failed
        more = f" (and {len(missing) - 1} more inputs)" if len(missing) > 1 else ""
        raise LBurstFileNotFoundError(f"{missing[0]}: no such file or folder{more}")
    check_output_outside(out, paths)
    wanted = {"device": device, "precision": precision if precision != "fp32" else None, "runtime": runtime}
    options = {k: v for k, v in wanted.items() if v is not None and chosen.accepts(k)}  # learned methods have them
    chosen.check(**options)  # a bad spec or option is one line (exit 2) before any work, with --cluster too
    extractor = chosen.create(**options) if cluster is None else None  # on a cluster: one per worker
    method_key = store.method_key(chosen, **{k: v for k, v in options.items() if k != "device"})
    report = ExtractReport(out, len(paths))
    with open_runner(cluster) as runner:  # a cluster that cannot be reached leaves no --out
        out.mkdir(parents=True, exist_ok=True)
        compute = compute_for(chosen, runner, extractor, options, threads)
        run = _Run(out, overwrite, compute, runner, recording or RecordingOptions(), report)
        _extract_inputs(paths, run, method_key)
    if h5:
        write_h5(out / "features.h5", sorted({**features_in_folder(out), **dict(report.finished)}.items()))
    return report


def _extract_inputs(paths: list[Path], run: _Run, method: dict) -> None:
    """Each input in turn: single bursts mapped together (on a cluster, in parallel), each
    recording's keyframes after the single bursts before it; counted in ``run.report``."""
    names: dict[str, Path] = {}
    report = run.report
    pending: list[tuple[Path, KeyframeBurst]] = []  # single bursts, mapped together
    for path in paths:
        source = open_bursts(path, run.recording)  # a burst, or a recording cut into keyframe bursts
        if source.folder:  # the single bursts before it first
            report.done += extract_bursts(pending, run)
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
            new, old = extract_recording(source, run, method)
        except (BurstError, ValueError, OSError, RuntimeError) as exc:  # a missing extra (ImportError) ends the run
            skip(path, str(exc), report.failed)
            continue
        tqdm.write(f"{path}: {new} keyframes extracted, {old} already done")
        if source.error:
            report.failed.append((path, source.error))
            tqdm.write(f"stopped {path}: {source.error}", file=sys.stderr)
            continue
        report.done += new > 0
    report.done += extract_bursts(pending, run)


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
    run: _Run,
    failed: Callable[[KeyframeBurst, Exception], None] | None = None,
    names: list[str] | None = None,
) -> tuple[int, int]:
    """Features of ``bursts`` (:func:`lburst.sfm.feature_stage.keyframe_features`), one ``.npz``
    each in ``OUT/<folder>/`` with its common frame in ``OUT/images/<folder>/`` (``folder``:
    :attr:`lburst.sfm.inputs.InputSource.folder`, a recording's name, else none), computed in
    this process or as tasks of ``run.runner`` on a cluster; returns (computed, already done) and
    appends each finished burst to the report's ``finished`` as (features.h5 group, ``.npz``) and its name
    to ``names`` (sorted at the end, even on failure), so that those done before a failure are
    kept.  ``failed``: a burst that fails is reported there and the others go on (by default
    its error ends the call)."""
    layout = Layout(run.out / folder, run.out / IMAGES / folder)
    done = skipped = 0
    names = [] if names is None else names
    try:
        for burst in keyframe_features(
            bursts,
            run.compute,
            layout,
            reuse=not run.overwrite,
            protect=True,
            runner=run.runner,
            failed=failed,
            progress=True,
            desc=f"extract {folder or 'bursts'}",
        ):
            done, skipped = done + burst.computed, skipped + (not burst.computed)
            group = layout.image_path(burst.burst.name).relative_to(run.out / IMAGES).as_posix()
            run.report.finished.append((group, layout.features_path(burst.burst.name)))
            names.append(burst.burst.name)
    finally:
        names.sort()  # on a cluster they finish in any order; keyframe names sort in frame order
    return done, skipped


def extract_recording(source: InputSource, run: _Run, method: dict) -> tuple[int, int]:
    """Features of every keyframe burst of a recording (:func:`extract_input`); returns (computed,
    already done).  The names it finished go to ``OUT/<folder>/cut.json`` (:func:`write_cut`),
    even when it fails."""
    names: list[str] = []
    try:
        return extract_input(source.keyframe_bursts(method), source.folder, run, None, names)
    finally:
        write_cut(run.out / source.folder, source.path, run.recording, names)


def skip(path: Path, why: str, failed: list[tuple[Path, str]]) -> None:
    """Report a burst that failed on stderr and keep it for the summary."""
    failed.append((path, why))
    tqdm.write(f"skipped {why if why.startswith(str(path)) else f'{path}: {why}'}", file=sys.stderr)


def extract_bursts(pending: list[tuple[Path, KeyframeBurst]], run: _Run) -> int:
    """Features of single bursts, one ``OUT/<name>.npz`` each, in one map (on a cluster, in
    parallel); a burst that fails is skipped and reported.  Returns how many were computed."""
    paths = {burst.name: path for path, burst in pending}

    def report(burst: KeyframeBurst, exc: Exception) -> None:
        skip(paths[burst.name], str(exc), run.report.failed)

    new, _ = extract_input([b for _, b in pending], "", run, report)
    pending.clear()
    return new
