"""Position priors of the images: where a GNSS receiver (or a flight log) put each camera.

A positions file has one line per image, ``NAME X Y Z``: the image's name as the scene names
it (a burst folder, a keyframe), then its camera centre in metres in a local Cartesian frame
(east, north, up, or any right-handed metric frame), as COLMAP's ``model_aligner``
reads its reference images.  Blank lines and lines starting with ``#`` are skipped; images
the file does not name have no prior.  ``lburst simulate flight`` writes one
(``positions.txt``: the true centres plus seeded Gaussian noise, a consumer receiver's few
metres), and ``lburst reconstruct --positions FILE`` gives them to COLMAP's incremental
mapper, which then holds each camera near its prior in bundle adjustment
(:func:`lburst.sfm.colmap.map_database`) and returns the model in the file's frame.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from lburst.errors import LBurstValueError
from lburst.numbers import check_real

#: the positions file ``lburst simulate flight`` writes into a scene
POSITIONS_FILE = "positions.txt"

#: the default standard deviation of each coordinate of a prior (m): a consumer GNSS receiver's
DEFAULT_STD_M = 2.0


class PositionsError(LBurstValueError):
    """A positions file that cannot be used; the message names the file, the line and the problem."""


def parse_positions(path: str | Path) -> dict[str, np.ndarray]:
    """The positions file ``path`` as name -> (3,) centre.  Raises :class:`PositionsError` for
    a missing file, a line that is not ``NAME X Y Z`` with finite numbers, a name given twice,
    or a file with no position at all."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise PositionsError(f"{path}: cannot read the positions file ({exc})") from None
    found: dict[str, np.ndarray] = {}
    for number, line in enumerate(text.splitlines(), 1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        where = f"{path}:{number}"
        if len(fields) != 4:
            raise PositionsError(f"{where}: expected 'NAME X Y Z', got {len(fields)} fields")
        name = fields[0]
        try:
            xyz = [float(v) for v in fields[1:]]
        except ValueError:
            raise PositionsError(f"{where}: {name}: X Y Z must be numbers, got {' '.join(fields[1:])!r}") from None
        if not all(math.isfinite(v) for v in xyz):
            raise PositionsError(f"{where}: {name}: X Y Z must be finite, got {' '.join(fields[1:])}")
        if name in found:
            raise PositionsError(f"{where}: {name} is given twice")
        found[name] = np.array(xyz)
    if not found:
        raise PositionsError(f"{path}: no position in the file")
    return found


def read_positions(path: str | Path, names: list[str]) -> np.ndarray:
    """The (N, 3) prior centre of each of ``names`` from the positions file ``path``
    (:func:`parse_positions`), NaN rows for names the file does not give; also refused: a
    name that is not an image of the scene."""
    found = parse_positions(path)
    index = {name: i for i, name in enumerate(names)}
    out = np.full((len(names), 3), np.nan)
    for name, xyz in found.items():
        if name not in index:
            raise PositionsError(f"{path}: {name} is not an image of the scene (its first: {names[0]!r})")
        out[index[name]] = xyz
    return out


def write_positions(path: str | Path, centres: dict[str, np.ndarray]) -> None:
    """Write ``centres`` (name -> (3,) metres) as a positions file."""
    lines = ["# NAME X Y Z (m): camera centres, a local Cartesian frame"]
    lines += [f"{name} {c[0]:.4f} {c[1]:.4f} {c[2]:.4f}" for name, c in centres.items()]
    Path(path).write_text("\n".join(lines) + "\n")


def check_std(std: float) -> float:
    """A prior's standard deviation (m): finite and positive."""
    return check_real(std, "the position prior's standard deviation (m)", 0, low_open=True)
