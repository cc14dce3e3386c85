"""Position priors of the images: where a GNSS receiver (or a flight log) put each camera.

A positions file has one line per image, ``NAME X Y Z``: the image's name as the scene names
it (a burst folder, a keyframe), or as the outputs name it (``0000.png`` in ``images/``,
``features.h5`` and ``pairs.txt``: an image suffix is dropped), then its camera centre in
metres in a local Cartesian frame (east, north, up, or any right-handed metric frame), as
COLMAP's ``model_aligner`` reads its reference images.  Blank lines and lines starting with
``#`` are skipped; images the file does not name have no prior.  ``lburst simulate flight``
writes one (``positions.txt``: the true centres plus seeded Gaussian noise, a consumer
receiver's few metres), and ``lburst reconstruct --positions FILE`` gives them to COLMAP's
incremental mapper, which then holds each camera near its prior in bundle adjustment
(:func:`lburst.sfm.colmap.map_database`) and returns the model in the file's frame.

Without ``--positions`` a reconstruction takes the positions its input carries
(:func:`track_priors`: the EXIF GPS of its frames, a DJI ``.SRT``, a bag's ``NavSatFix``,
:mod:`lburst.geo`), in metres east, north and up of the first fix.  Either way a
:class:`Priors` says where they came from and what was left out, and positions spread over
less than their own standard deviation are refused (a file: degrees or kilometres taken for
metres) or not used (an input's: a platform that hardly moved).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lburst.burst.io import IMAGE_SUFFIXES
from lburst.errors import LBurstValueError
from lburst.geo.fixes import GnssTrack, drop_jumps, positions_at
from lburst.geo.frame import GeoOrigin
from lburst.numbers import check_real
from lburst.sfm.turns import describe_turns

#: the positions file ``lburst simulate flight`` writes into a scene
POSITIONS_FILE = "positions.txt"

#: the default standard deviation of each coordinate of a prior (m): a consumer GNSS receiver's
DEFAULT_STD_M = 2.0
#: bounds of a prior's standard deviation (m): an RTK receiver's centimetre to a kilometre; below
#: a centimetre COLMAP's bundle adjustment weighs the priors so far above the images that it
#: stops fitting them (1e-9 m left a model 62 m from its priors)
MIN_STD_M = 0.01
MAX_STD_M = 1000.0
#: the largest positions file read (bytes): 40 bytes a line, over a million images
MAX_FILE_BYTES = 64 * 2**20
#: fewest registered images with a prior that place a model in the priors' frame (a similarity
#: needs three points not on one line)
MIN_PLACED = 3
#: a model whose cameras lie farther than this many standard deviations (RMS) from their priors is
#: flagged (a camera 3 sigma off on each axis lies 5.2 sigma away)
FAR_FROM_PRIORS = 5.0


class PositionsError(LBurstValueError):
    """A positions file that cannot be used; the message names the file, the line and the problem."""


def _read_text(path: Path) -> str:
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise PositionsError(f"{path}: cannot read the positions file ({exc})") from None
    if len(data) > MAX_FILE_BYTES:
        raise PositionsError(f"{path}: over {MAX_FILE_BYTES // 2**20} MiB, not a positions file (NAME X Y Z a line)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PositionsError(f"{path}: cannot read the positions file ({exc})") from None


def parse_positions(path: str | Path) -> dict[str, np.ndarray]:
    """The positions file ``path`` as name -> (3,) centre.  Raises :class:`PositionsError` for
    a missing file, a line that is not ``NAME X Y Z`` with finite numbers, a name given twice,
    or a file with no position at all."""
    path = Path(path)
    text = _read_text(path)
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


def image_name(name: str, names: set[str] | dict[str, int]) -> str | None:
    """The image of ``names`` that ``name`` means: itself, or without an image suffix
    (``0000.png``, as ``images/``, ``features.h5`` and ``pairs.txt`` name it); else ``None``."""
    if name in names:
        return name
    stem, dot, suffix = name.rpartition(".")
    if dot and f".{suffix.lower()}" in IMAGE_SUFFIXES and stem in names:
        return stem
    return None


def read_positions(path: str | Path, names: list[str]) -> np.ndarray:
    """The (N, 3) prior centre of each of ``names`` from the positions file ``path``
    (:func:`parse_positions`), NaN rows for names the file does not give; also refused: a
    name that is not an image of the scene (:func:`image_name`), a scene without images,
    two lines for one image."""
    if not names:
        raise PositionsError(f"{path}: the scene has no images to give positions to")
    found = parse_positions(path)
    index = {name: i for i, name in enumerate(names)}
    out = np.full((len(names), 3), np.nan)
    given: dict[str, str] = {}
    for name, xyz in found.items():
        image = image_name(name, index)
        if image is None:
            raise PositionsError(f"{path}: {name} is not an image of the scene (its first: {names[0]!r})")
        if image in given:
            raise PositionsError(f"{path}: {given[image]} and {name} are the same image")
        given[image] = name
        out[index[image]] = xyz
    return out


def write_positions(path: str | Path, centres: dict[str, np.ndarray]) -> None:
    """Write ``centres`` (name -> (3,) metres) as a positions file."""
    lines = ["# NAME X Y Z (m): camera centres, a local Cartesian frame"]
    lines += [f"{name} {c[0]:.4f} {c[1]:.4f} {c[2]:.4f}" for name, c in centres.items()]
    Path(path).write_text("\n".join(lines) + "\n")


def check_std(std: float) -> float:
    """A prior's standard deviation (m): a finite number from :data:`MIN_STD_M` to :data:`MAX_STD_M`."""
    return check_real(std, "the position prior's standard deviation (m)", MIN_STD_M, MAX_STD_M)


def spread_problem(centres: np.ndarray, std: float) -> str | None:
    """Why positions ``centres`` (N, 3), NaN rows ignored, cannot be metres with priors of
    ``std`` m, or ``None``: X and Y that look like longitude and latitude (within their
    ranges, not near 0, spread over less than ``std`` while Z may be metres), or positions
    that span less than ``std`` (kilometres taken for metres, or a platform that did not move)."""
    given = centres[~np.isnan(centres).any(axis=1)]
    if len(given) < 2:
        return None
    span = float(np.linalg.norm(np.ptp(given, axis=0)))
    across = float(np.linalg.norm(np.ptp(given[:, :2], axis=0)))
    x, y = np.abs(given[:, 0]), np.abs(given[:, 1])
    in_range = bool(((x <= 180) & (y <= 90)).all() or ((x <= 90) & (y <= 180)).all())
    if in_range and across < std and max(x.max(), y.max()) > 1:
        looks = f"X and Y span {across:.3g} m and look like longitude and latitude in degrees"
    elif span < std:
        looks = f"they span {span:.3g} m: kilometres taken for metres, or a platform that did not move"
    else:
        return None
    return (
        f"the {len(given)} positions cannot place the model with priors of {std:g} m ({looks}); "
        "give metres in a local frame, or a smaller --position-std if they are metres"
    )


@dataclass
class Priors:
    """Position priors of a scene's images and where they came from.

    Attributes:
        centres: (N, 3) prior camera centre of each image of the scene in its order (metres),
            NaN rows for images without one.
        source: what gave them, as the report says it (a positions file, the EXIF of frames).
        origin: the geodetic origin of their east-north-up frame (:mod:`lburst.geo.frame`), or
            ``None`` for a positions file's own frame.
        notes: what was left out and why, one line each.
    """

    centres: np.ndarray
    source: str
    origin: GeoOrigin | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def count(self) -> int:
        return int((~np.isnan(self.centres).any(axis=1)).sum())

    def job_positions(self) -> list[list[float] | None]:
        """Each image's prior as :class:`lburst.sfm.colmap.ColmapJob` takes them."""
        return [None if np.isnan(c).any() else [float(v) for v in c] for c in self.centres]

    def to_json(self) -> dict:
        return {
            "source": self.source,
            "images": self.count,
            "of": len(self.centres),
            "origin": None if self.origin is None else self.origin.to_json(),
            "notes": list(self.notes),
        }


def file_priors(path: str | Path, names: list[str], std: float) -> Priors:
    """The priors of ``names`` from the positions file ``path`` (:func:`read_positions`);
    :class:`PositionsError` when they span less than ``std`` (:func:`spread_problem`)."""
    centres = read_positions(path, names)
    problem = spread_problem(centres, std)
    if problem:
        raise PositionsError(f"{path}: {problem}")
    return Priors(centres, f"the positions file {path}")


def track_priors(track: GnssTrack, names: list[str], times: list[float] | None, std: float) -> Priors:
    """The priors of ``names`` from a GNSS ``track`` (:mod:`lburst.geo`): its fixes without the
    jumps (:func:`lburst.geo.fixes.drop_jumps`), in metres east, north and up of its first
    fix, at the images' ``times`` (a timed track, interpolated) or by the images' names (a
    scene's frames).  Positions spread less than ``std`` are not used, with a note; the
    priors of a track that gives no image a position have a count of 0 and say why."""
    track = drop_jumps(track)
    if not track.fixes:
        return Priors(np.full((len(names), 3), np.nan), track.source, None, list(track.notes))
    first = track.fixes[0]
    origin = GeoOrigin(first.lat, first.lon, first.alt)
    enu = origin.to_enu([f.lat for f in track.fixes], [f.lon for f in track.fixes], [f.alt for f in track.fixes])
    centres = np.full((len(names), 3), np.nan)
    notes = list(track.notes)
    if track.timed and times is not None:
        centres = positions_at([f.time for f in track.fixes], enu, times)
        missing = [name for name, c in zip(names, centres) if np.isnan(c).any()]
        if missing:
            last = track.fixes[-1].time
            notes.append(
                f"{len(missing)} of {len(names)} images lie outside {track.source}'s time or in a gap of it "
                f"(its fixes from {track.fixes[0].time:.3f} s to {last:.3f} s), without a position: {missing[0]}"
                + (f" ... {missing[-1]}" if len(missing) > 1 else "")
            )
    else:
        index = {name: i for i, name in enumerate(names)}
        for fix, point in zip(track.fixes, enu):
            if fix.name in index:
                centres[index[fix.name]] = point
    priors = Priors(centres, track.source, origin, notes)
    problem = spread_problem(centres, std)
    if problem:
        notes.append(f"{track.source}: {problem}; not used")
        return Priors(np.full_like(centres, np.nan), track.source, origin, notes)
    return priors


def prior_fit(
    priors: Priors,
    names: list[str],
    centres: dict[str, np.ndarray],
    used: bool,
    std: float,
    alignment: dict | None = None,
) -> dict:
    """What the priors did, for ``result.json``: :meth:`Priors.to_json` with the prior's ``std``,
    whether the mapper ``used`` them, how many registered images (``centres``: name -> model
    camera centre) have one, how far those lie from their priors (m: mean, RMS, max) and
    whether the model is in the priors' frame (:data:`MIN_PLACED` of them at least); notes
    say when it is not, or when it lies far from them, and when ``alignment``
    (:func:`lburst.sfm.prior_alignment.align_to_priors`) had to put it there."""
    data = priors.to_json() | {
        "std": std,
        "used": used,
        "aligned_after_mapping": bool(alignment and alignment["applied"]),
    }
    if alignment and alignment["applied"]:
        data["notes"].append(
            f"COLMAP's mapper left the cameras {alignment['before']:.3g} m RMS from their positions (is the prior's "
            f"standard deviation, {std:g} m, below their real error?); a similarity fitted to them put the model "
            f"in their frame ({alignment['after']:.3g} m RMS)"
        )
    prior = {name: c for name, c in zip(names, priors.centres) if not np.isnan(c).any()}
    both = [name for name in names if name in prior and name in centres]
    data["registered_with_prior"] = len(both)
    data["model_to_priors"] = None
    data["in_frame"] = used and len(both) >= MIN_PLACED
    notes = data["notes"]
    if used and len(both) < MIN_PLACED:
        notes.append(
            f"only {len(both)} registered image(s) have a position, {MIN_PLACED} are needed to place the model: "
            "it is in COLMAP's own frame, not the priors'"
        )
    if both:
        distance = np.array([np.linalg.norm(centres[n] - prior[n]) for n in both])
        rms = float(np.sqrt(np.mean(distance**2)))
        data["model_to_priors"] = {"mean": float(distance.mean()), "rms": rms, "max": float(distance.max())}
        if data["in_frame"] and rms > FAR_FROM_PRIORS * std and not data["aligned_after_mapping"]:
            notes.append(
                f"the cameras lie {rms:.3g} m RMS from their positions, over {FAR_FROM_PRIORS:g} times the prior's "
                f"standard deviation ({std:g} m): the model may be folded, or the positions wrong"
            )
    return data


def describe(data: dict) -> list[str]:
    """Lines that say what :func:`prior_fit`'s ``data`` says: where the positions came from, how
    many, the origin, the views they show turned against their pairs (``turns``,
    :mod:`lburst.sfm.turns`), how far the model lies from them, then its notes."""
    origin = data.get("origin")
    where = ""
    if origin:
        ns, ew = ("N" if origin["latitude"] >= 0 else "S"), ("E" if origin["longitude"] >= 0 else "W")
        where = (
            f"; east, north, up of {abs(origin['latitude']):.7f} {ns}, {abs(origin['longitude']):.7f} {ew}, "
            f"{origin['altitude']:.2f} m ({origin['crs']})"
        )
    how = "held by the mapper" if data.get("used") else "not used"
    lines = [f"positions: {data['images']} of {data['of']} images from {data['source']}{where}; {how}"]
    if data.get("turns"):
        lines.append(f"positions: {describe_turns(data['turns'])}")
    fit = data.get("model_to_priors")
    if fit:
        lines.append(
            f"positions: the {data['registered_with_prior']} registered cameras with one lie {fit['rms']:.3g} m RMS "
            f"(mean {fit['mean']:.3g}, max {fit['max']:.3g}) from them (prior std {data['std']:g} m)"
        )
    if data.get("georeferenced"):
        geo = data["georeferenced"]
        lines.append(
            f"positions: the model in {geo['crs']}: {geo['points']} ({geo['points3D']} points), {geo['cameras']}"
        )
    lines += [f"positions: {note}" for note in data.get("notes", [])]
    return lines
