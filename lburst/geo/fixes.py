"""GNSS fixes as lburst takes them from a camera's or robot's files, checked, and their
positions at the times of the frames.

A :class:`Fix` is a latitude and longitude (degrees, WGS 84), an altitude (metres) and,
where the source has one, a time on the recording's clock (s) or the name of the image it
belongs to.  A :class:`GnssTrack` is the fixes of one source (the EXIF of a recording's
frames, a DJI ``.SRT``, a bag's ``NavSatFix`` topic) with notes on what it could not use:
a fix outside the Earth's coordinates (:func:`check_coordinates`), a frame without one, and,
in a timed track, a fix that lies farther from the last good one than the platform can fly
in the time between them (:func:`drop_jumps`: :data:`MAX_SPEED` m/s plus
:data:`JUMP_SLACK_M` m of receiver noise).  :func:`positions_at` interpolates a timed track
to frame times, linearly, where the GNSS rate is lower than the frame rate; a frame before
the first fix, after the last one (an ``.SRT`` shorter than its video) or in a gap longer
than :data:`MAX_GAP_S` gets none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lburst.errors import LBurstValueError

#: the fastest a platform is taken to fly (m/s; 216 km/h, above any survey drone or robot)
MAX_SPEED = 60.0
#: what a fix may wander between two fixes beside the flight itself (m: a consumer receiver's noise)
JUMP_SLACK_M = 10.0
#: the longest time (s) between two fixes that a position is interpolated across
MAX_GAP_S = 2.0
#: how far (s) before the first fix or after the last one a frame still takes that fix
END_TOLERANCE_S = 0.1
#: how many dropped fixes a note names one by one
NAMED_IN_NOTE = 3

EARTH_RADIUS_M = 6_371_000.0


class GnssError(LBurstValueError):
    """GNSS data lburst cannot use; the message names the file, frame or topic and the problem."""


def check_coordinates(lat, lon, alt, where: str) -> None:
    """:class:`GnssError` naming ``where`` unless ``lat`` is in [-90, 90], ``lon`` in
    [-180, 180] and ``alt`` a finite number of metres above -1000 and below 100 km."""
    for value, what in ((lat, "latitude"), (lon, "longitude"), (alt, "altitude")):
        if not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(value):
            raise GnssError(f"{where}: the {what} must be a finite number, got {value!r}")
    if not -90.0 <= lat <= 90.0:
        raise GnssError(f"{where}: latitude {lat:g} is outside -90..90 degrees")
    if not -180.0 <= lon <= 180.0:
        raise GnssError(f"{where}: longitude {lon:g} is outside -180..180 degrees")
    if not -1000.0 <= alt <= 100_000.0:
        raise GnssError(f"{where}: altitude {alt:g} m is outside -1000..100000 m")


@dataclass(frozen=True)
class Fix:
    """One GNSS fix: where it came from (``where``: a file, a frame, a message, as notes name
    it), its time on the recording's clock (s) and the image it belongs to, where known."""

    lat: float
    lon: float
    alt: float
    where: str
    time: float | None = None
    name: str | None = None


@dataclass
class GnssTrack:
    """The fixes of one source (``source``: what it is, as the report says it) and notes on
    what of it could not be used (one line each)."""

    source: str
    fixes: list[Fix]
    notes: list[str] = field(default_factory=list)

    @property
    def timed(self) -> bool:
        return bool(self.fixes) and all(f.time is not None for f in self.fixes)


def checked(
    track_source: str, candidates: list[tuple[float, float, float, str, float | None, str | None]]
) -> GnssTrack:
    """A track of ``candidates`` ``(lat, lon, alt, where, time, name)``, those outside the
    Earth's coordinates (:func:`check_coordinates`) left out with a note each."""
    fixes, notes = [], []
    for lat, lon, alt, where, time, name in candidates:
        try:
            check_coordinates(lat, lon, alt, where)
        except GnssError as err:
            notes.append(f"{err}; not used")
            continue
        fixes.append(Fix(float(lat), float(lon), float(alt), where, time, name))
    return GnssTrack(track_source, fixes, notes)


def _distance(a: Fix, b: Fix) -> float:
    """Metres between two fixes (a local flat Earth: within 0.5 % over tens of kilometres)."""
    north = math.radians(b.lat - a.lat) * EARTH_RADIUS_M
    east = math.radians(b.lon - a.lon) * EARTH_RADIUS_M * math.cos(math.radians((a.lat + b.lat) / 2))
    return math.sqrt(north**2 + east**2 + (b.alt - a.alt) ** 2)


def _too_fast(a: Fix, b: Fix, max_speed: float) -> bool:
    return _distance(a, b) > JUMP_SLACK_M + max_speed * abs(b.time - a.time)


def drop_jumps(track: GnssTrack, max_speed: float = MAX_SPEED) -> GnssTrack:
    """``track`` (timed) without the fixes the platform cannot have flown to: the first fix
    kept is the first one its successor agrees with, and each later one must lie within
    ``max_speed`` (plus :data:`JUMP_SLACK_M`) of the last one kept; a note says which were
    dropped.  An untimed track is returned as it is."""
    fixes = sorted(track.fixes, key=lambda f: f.time) if track.timed else track.fixes
    if not track.timed or len(fixes) < 2:
        return GnssTrack(track.source, list(fixes), list(track.notes))
    start = next((i for i in range(len(fixes) - 1) if not _too_fast(fixes[i], fixes[i + 1], max_speed)), 0)
    kept, dropped = [fixes[start]], list(fixes[:start])
    for fix in fixes[start + 1 :]:
        if _too_fast(kept[-1], fix, max_speed):
            dropped.append(fix)
        else:
            kept.append(fix)
    notes = list(track.notes)
    if dropped:
        named = "; ".join(
            f"{f.where} ({_distance(kept[0], f):.0f} m from the first good fix)" for f in dropped[:NAMED_IN_NOTE]
        )
        more = f" and {len(dropped) - NAMED_IN_NOTE} more" if len(dropped) > NAMED_IN_NOTE else ""
        notes.append(
            f"{len(dropped)} fix(es) of {track.source} jump farther than the platform can fly "
            f"({max_speed:g} m/s), dropped: {named}{more}"
        )
    return GnssTrack(track.source, kept, notes)


def positions_at(times: np.ndarray, points: np.ndarray, at: np.ndarray, max_gap: float = MAX_GAP_S) -> np.ndarray:
    """``(N, 3)`` positions at times ``at`` (N,), interpolated linearly in the points ``(M, 3)``
    (metres, a local frame) of fixes at ``times`` (M,), increasing; NaN rows where no fix lies
    within :data:`END_TOLERANCE_S` before the first or after the last, or where the fixes on
    either side are more than ``max_gap`` s apart."""
    times, points, at = np.asarray(times, float), np.asarray(points, float), np.asarray(at, float)
    out = np.full((len(at), 3), np.nan)
    if not len(times):
        return out
    for axis in range(3):
        out[:, axis] = np.interp(at, times, points[:, axis])
    after = np.searchsorted(times, at, side="left").clip(1, max(len(times) - 1, 1))
    gap = times[after] - times[after - 1] if len(times) > 1 else np.zeros(len(at))
    outside = (at < times[0] - END_TOLERANCE_S) | (at > times[-1] + END_TOLERANCE_S)
    inside = (at >= times[0]) & (at <= times[-1]) & ~np.isin(at, times)  # a fix's own time takes the fix
    out[outside | (inside & (gap > max_gap))] = np.nan
    return out
