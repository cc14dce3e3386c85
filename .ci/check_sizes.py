"""Refuse large files in git: any tracked file above 10 MB, or tracked training runs above 15 MB in all.

Checks what the index holds (``git ls-files``), so a file that was added and is about
to be committed counts.  Usage: ``python .ci/check_sizes.py`` from anywhere in the repository.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

MAX_FILE = 10 * 1000 * 1000
MAX_TRAINING = 15 * 1000 * 1000


def tracked_sizes(root: Path) -> dict[str, int]:
    names = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True, check=True).stdout
    sizes = {}
    for name in names.decode().split("\0"):
        path = root / name
        if name and path.is_file() and not path.is_symlink():
            sizes[name] = path.stat().st_size
    return sizes


def main() -> int:
    root = Path(
        subprocess.run(
            ["git", "rev-parse", "--show-toplevel"], capture_output=True, text=True, check=True
        ).stdout.strip()
    )
    sizes = tracked_sizes(root)
    errors = [
        f"{name}: {size / 1e6:.1f} MB (limit {MAX_FILE / 1e6:.0f} MB per file)"
        for name, size in sorted(sizes.items())
        if size > MAX_FILE
    ]
    training = sum(size for name, size in sizes.items() if name.startswith("training/"))
    if training > MAX_TRAINING:
        errors.append(f"training/: {training / 1e6:.1f} MB tracked (limit {MAX_TRAINING / 1e6:.0f} MB)")
    for error in errors:
        print(f"check_sizes: {error}", file=sys.stderr)
    if not errors:
        print(
            f"check_sizes: {len(sizes)} tracked files, none above {MAX_FILE / 1e6:.0f} MB; "
            f"training/ {training / 1e6:.1f} MB"
        )
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
