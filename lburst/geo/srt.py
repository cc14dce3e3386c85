"""The ``.SRT`` subtitles a DJI drone writes beside its video: one subtitle per frame (or per
second on older models) with the position, read as a timed GNSS track.

A subtitle is a number, a time range ``HH:MM:SS,mmm --> HH:MM:SS,mmm`` on the video's clock
and text; the fix is taken at the start of the range.  The text comes in the forms DJI's
firmware has written (HTML tags such as ``<font>`` are ignored):

- bracketed fields (Mavic 2/3, Air 2/2S, Mini, Phantom 4 RTK):
  ``[latitude: 22.54321] [longitude: 113.95432] [rel_alt: 1.200 abs_alt: 45.678]``, also
  ``[latitude : ...] [longtitude : ...] [altitude: ...]`` (the spelling of some firmware);
- ``GPS(lon,lat,alt)`` or ``GPS (lon, lat, n)``, with the height elsewhere as ``H 21.20m``
  or ``BAROMETER:64.8`` on some models (Phantom 3/4, Mavic Pro, Spark).

The altitude is the first of ``abs_alt``, ``altitude``, ``rel_alt``, ``H``, ``BAROMETER`` and
the third value of ``GPS(...)`` that the subtitle has.  A subtitle at 0, 0 (the drone had no
fix yet) gives no fix; a subtitle without a position, or one outside the Earth's coordinates,
is noted and left out.
"""

from __future__ import annotations

import re
from pathlib import Path

from lburst.geo.fixes import GnssError, GnssTrack, checked

SRT_SUFFIXES = (".SRT", ".srt")
_NUMBER = r"([-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)"
_TIME = re.compile(r"(\d+):(\d\d):(\d\d)[,.](\d{1,3})\s*-->")
_TAG = re.compile(r"<[^>]*>")
_FIELDS = {
    "lat": re.compile(r"\[\s*latitude\s*:\s*" + _NUMBER, re.I),
    "lon": re.compile(r"\[\s*longt?itude\s*:\s*" + _NUMBER, re.I),
    "abs_alt": re.compile(r"abs_alt\s*:\s*" + _NUMBER, re.I),
    "altitude": re.compile(r"\[\s*altitude\s*:\s*" + _NUMBER, re.I),
    "rel_alt": re.compile(r"rel_alt\s*:\s*" + _NUMBER, re.I),
    "height": re.compile(r"(?:^|[\s,])H\s+" + _NUMBER + r"\s*m\b"),
    "barometer": re.compile(r"BAROMETER\s*:\s*" + _NUMBER, re.I),
}
_GPS = re.compile(r"\bGPS\s*\(\s*" + _NUMBER + r"\s*,\s*" + _NUMBER + r"\s*(?:,\s*" + _NUMBER + r"\s*M?)?\s*\)", re.I)
_ALTITUDES = ("abs_alt", "altitude", "rel_alt", "height", "barometer")


def srt_path(video: str | Path) -> Path | None:
    """The DJI subtitle file beside ``video`` (same stem, ``.SRT`` or ``.srt``), if there is one."""
    video = Path(video)
    for suffix in SRT_SUFFIXES:
        path = video.with_suffix(suffix)
        if path.is_file():
            return path
    return None


def _seconds(match: re.Match) -> float:
    h, m, s, ms = match.groups()
    return int(h) * 3600 + int(m) * 60 + int(s) + int(ms.ljust(3, "0")) / 1000


def parse_subtitle(text: str) -> tuple[float, float, float] | None:
    """``(lat, lon, alt)`` of one subtitle's text (module docstring), ``None`` when it has no position."""
    text = _TAG.sub(" ", text)
    found = {key: m.group(1) for key, pattern in _FIELDS.items() if (m := pattern.search(text))}
    gps = _GPS.search(text)
    if "lat" in found and "lon" in found:
        lat, lon = float(found["lat"]), float(found["lon"])
    elif gps:
        lon, lat = float(gps.group(1)), float(gps.group(2))
    else:
        return None
    alt = next((float(found[key]) for key in _ALTITUDES if key in found), None)
    if alt is None:
        alt = float(gps.group(3)) if gps and gps.group(3) else 0.0
    return lat, lon, alt


def read_srt(path: str | Path) -> GnssTrack:
    """The fixes of a DJI ``.SRT`` file (module docstring), timed at each subtitle's start;
    :class:`GnssError` naming the file when it cannot be read or holds no position at all."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as err:
        raise GnssError(f"{path}: cannot read the subtitles ({err})") from None
    candidates, without, no_fix = [], [], 0
    for block in re.split(r"\r?\n\s*\r?\n", text.strip()):
        time = _TIME.search(block)
        if time is None:
            continue
        start = _seconds(time)
        position = parse_subtitle(block[time.end() :])
        if position is None:
            without.append(f"{start:.3f} s")
        elif position[0] == 0 and position[1] == 0:
            no_fix += 1
        else:
            candidates.append((*position, f"{path.name} at {start:.3f} s", start, None))
    if not candidates:
        raise GnssError(f"{path}: no subtitle holds a position (latitude and longitude, or GPS(...))")
    track = checked(f"{path.name} (DJI subtitles, {len(candidates)} fixes)", candidates)
    if without:
        track.notes.insert(0, f"{path}: {len(without)} subtitle(s) without a position (the first at {without[0]})")
    if no_fix:
        track.notes.insert(0, f"{path}: {no_fix} subtitle(s) at latitude 0, longitude 0 (no fix yet); not used")
    return track


def write_srt(path: str | Path, times: list[float], fixes: list[tuple[float, float, float]], fps: float) -> Path:
    """A DJI-style ``.SRT`` (bracketed fields, one subtitle per frame at ``times``) of ``fixes``
    ``(lat, lon, abs_alt)``: what ``lburst simulate flight --video --srt`` writes."""
    blocks = []
    for i, (start, (lat, lon, alt)) in enumerate(zip(times, fixes), 1):
        end = start + 1.0 / fps
        blocks.append(
            f"{i}\n{_stamp(start)} --> {_stamp(end)}\n"
            f'<font size="28">FrameCnt: {i}, DiffTime: {round(1000 / fps)}ms\n'
            f"[iso: 6400] [shutter: 1/60.0] [fnum: 2.8] [ev: 0] "
            f"[latitude: {lat:.8f}] [longitude: {lon:.8f}] [rel_alt: {alt:.3f} abs_alt: {alt:.3f}] </font>\n"
        )
    Path(path).write_text("\n".join(blocks), encoding="utf-8")
    return Path(path)


def _stamp(seconds: float) -> str:
    ms = int(round(seconds * 1000))
    h, rest = divmod(ms, 3_600_000)
    m, rest = divmod(rest, 60_000)
    s, ms = divmod(rest, 1000)
    return f"{h:02d}:{m:02d}:{s:02d},{ms:03d}"
