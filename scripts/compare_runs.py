"""Compare two lburst output folders file by file: what a change of code left unchanged.

Run the same commands (``lburst reconstruct``, ``lburst extract``, ...) with two versions of
the code into folders A and B, then::

    python scripts/compare_runs.py A B [--out diff.json]

Every file of A must be in B and the other way round.  ``.npz`` files are compared array by
array (``_meta``, which records file paths and times, is left out), ``.h5`` files dataset by
dataset, ``.json`` files as data without the keys in :data:`VOLATILE` (timings, paths, versions),
and every other file byte for byte, except logs.  Prints one line per difference and the
count of items compared; exits 1 when anything differs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import h5py
import numpy as np

#: JSON keys whose values depend on the run, not on what it computed.
VOLATILE = {"seconds", "elapsed_s", "wall_s", "read_fps", "started", "finished", "created", "version", "command"}
#: Files that record the run (its timings, its log), not its results.
SKIPPED_SUFFIXES = {".log", ".lock"}
SKIPPED_NAMES = {"stages.txt"}


def _without_volatile(value, root: Path):
    """``value`` without the :data:`VOLATILE` keys (and ``*_seconds``), the folder's own path, absolute
    or as given (relative to the working directory), as ``<ROOT>``."""
    if isinstance(value, dict):
        return {
            k: _without_volatile(v, root) for k, v in value.items() if k not in VOLATILE and not k.endswith("_seconds")
        }
    if isinstance(value, list):
        return [_without_volatile(v, root) for v in value]
    if not isinstance(value, str):
        return value
    for form in dict.fromkeys((str(root.resolve()), str(root))):  # the absolute form first
        if form not in (".", ""):
            value = value.replace(form, "<ROOT>")
    return value


def _same_array(x: np.ndarray, y: np.ndarray) -> bool:
    return x.shape == y.shape and x.dtype == y.dtype and x.tobytes() == y.tobytes()


def _h5_items(path: Path) -> dict[str, np.ndarray]:
    items: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: items.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return items


def compare_files(a: Path, b: Path, roots: tuple[Path, Path]) -> tuple[int, list[str]]:
    """(items compared, differences) of two files of the same name under ``roots``."""
    if a.suffix == ".npz":
        with np.load(a) as x, np.load(b) as y:
            keys = sorted((set(x.files) | set(y.files)) - {"_meta"})
            return len(keys), [
                f"{k}" for k in keys if k not in x.files or k not in y.files or not _same_array(x[k], y[k])
            ]
    if a.suffix == ".h5":
        x, y = _h5_items(a), _h5_items(b)
        keys = sorted(set(x) | set(y))
        return len(keys), [
            k for k in keys if k not in x or k not in y or not _same_array(np.asarray(x[k]), np.asarray(y[k]))
        ]
    if a.suffix == ".json":
        x, y = (_without_volatile(json.loads(p.read_text()), r) for p, r in zip((a, b), roots))
        same = x == y
        return 1, [] if same else ["content"]
    return 1, [] if a.read_bytes() == b.read_bytes() else ["bytes"]


def compare_folders(a: Path, b: Path) -> tuple[int, list[str]]:
    """(items compared, differences) of two output folders."""

    def files(root: Path) -> set[Path]:
        return {
            p.relative_to(root)
            for p in root.rglob("*")
            if p.is_file() and p.suffix not in SKIPPED_SUFFIXES and p.name not in SKIPPED_NAMES
        }

    fa, fb = files(a), files(b)
    differences = [f"{p}: only in {a}" for p in sorted(fa - fb)] + [f"{p}: only in {b}" for p in sorted(fb - fa)]
    count = 0
    for rel in sorted(fa & fb):
        n, diff = compare_files(a / rel, b / rel, (a, b))
        count += n
        differences += [f"{rel}: {d} differs" for d in diff]
    return count, differences


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("a", type=Path)
    parser.add_argument("b", type=Path)
    parser.add_argument("--out", type=Path, help="write the comparison as JSON")
    args = parser.parse_args()
    count, differences = compare_folders(args.a, args.b)
    for line in differences:
        print(line)
    print(f"{count} items compared, {len(differences)} differ")
    if args.out:
        args.out.write_text(
            json.dumps({"a": str(args.a), "b": str(args.b), "items": count, "differences": differences}, indent=1)
        )
    return 1 if differences else 0


if __name__ == "__main__":
    sys.exit(main())
