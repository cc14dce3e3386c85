"""GPS in the EXIF of a frame (JPEG, TIFF, DNG: what drones and phones write), read and
written with piexif.

The GPS IFD holds latitude and longitude as degrees, minutes and seconds (three rationals)
with a hemisphere (``N``/``S``, ``E``/``W``), and the altitude as one rational with a
reference (0: above sea level, 1: below).  :func:`read_gps` reads them; a frame without GPS
gives ``None``, a GPS IFD that is malformed (a zero denominator, a missing hemisphere) a
:class:`lburst.geo.fixes.GnssError` naming the file.  :func:`frames_track` reads the frames of
a recording or scene into one track, and says how many lacked a fix.
:func:`write_gps_jpeg` writes a JPEG with its position (``lburst simulate flight --jpg``),
seconds to 1/10000 (3 mm) and the altitude to the millimetre.
"""

from __future__ import annotations

import io
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from lburst.extras import require
from lburst.geo.fixes import GnssError, GnssTrack, checked

#: frame files whose EXIF may hold GPS
EXIF_SUFFIXES = (".jpg", ".jpeg", ".tif", ".tiff", ".dng")
SECONDS_DENOMINATOR = 10_000
ALTITUDE_DENOMINATOR = 1_000


def _rational(value, path: Path, tag: str) -> float:
    try:
        num, den = value
    except (TypeError, ValueError):
        raise GnssError(f"{path}: EXIF {tag} is not a rational ({value!r})") from None
    if not den:
        raise GnssError(f"{path}: EXIF {tag} has a zero denominator")
    return num / den


def _degrees(dms, ref, path: Path, tag: str, positive: bytes, negative: bytes) -> float:
    if not isinstance(dms, (tuple, list)) or len(dms) != 3:
        raise GnssError(f"{path}: EXIF {tag} is not degrees, minutes, seconds ({dms!r})")
    d, m, s = (_rational(v, path, tag) for v in dms)
    ref = ref.strip(b"\x00 ").upper() if isinstance(ref, bytes) else ref
    if ref not in (positive, negative):
        raise GnssError(f"{path}: EXIF {tag}Ref is {ref!r}, not {positive.decode()} or {negative.decode()}")
    value = d + m / 60.0 + s / 3600.0
    return -value if ref == negative else value


def read_gps(path: str | Path) -> tuple[float, float, float] | None:
    """``(latitude, longitude, altitude)`` from the EXIF GPS of ``path`` (degrees, metres; an
    altitude missing: 0), or ``None`` when it has none."""
    piexif = require("piexif", "reading GPS from EXIF")
    path = Path(path)
    try:
        exif = piexif.load(str(path))
    except (piexif.InvalidImageDataError, ValueError, OSError, KeyError, IndexError, TypeError) as err:
        raise GnssError(f"{path}: cannot read its EXIF ({err})") from None
    gps = exif.get("GPS") or {}
    tags = piexif.GPSIFD
    if tags.GPSLatitude not in gps or tags.GPSLongitude not in gps:
        return None
    lat = _degrees(gps[tags.GPSLatitude], gps.get(tags.GPSLatitudeRef), path, "GPSLatitude", b"N", b"S")
    lon = _degrees(gps[tags.GPSLongitude], gps.get(tags.GPSLongitudeRef), path, "GPSLongitude", b"E", b"W")
    alt = _rational(gps[tags.GPSAltitude], path, "GPSAltitude") if tags.GPSAltitude in gps else 0.0
    if gps.get(tags.GPSAltitudeRef) in (1, b"\x01"):
        alt = -alt
    return lat, lon, alt


def frames_track(frames: Iterable[tuple[Path, float | None, str | None]], what: str) -> GnssTrack | None:
    """The EXIF GPS of ``frames`` (``(file, time on the recording's clock or None, image name
    or None)``) as one track named after ``what`` (the recording or scene), or ``None`` when
    no frame has one.  Frames without GPS, with a malformed one or with coordinates outside
    the Earth's are noted (how many, the first named) and left without a fix."""
    candidates, missing, notes, files = [], [], [], 0
    for path, time, name in frames:
        if Path(path).suffix.lower() not in EXIF_SUFFIXES:
            continue
        files += 1
        try:
            gps = read_gps(path)
        except GnssError as err:
            notes.append(f"{err}; not used")
            continue
        if gps is None:
            missing.append(Path(path).name)
        else:
            candidates.append((*gps, str(path), time, name))
    if not candidates:
        return None
    track = checked(f"the EXIF GPS of {len(candidates)} of {files} frames of {what}", candidates)
    if missing:
        track.notes.insert(0, f"{what}: {len(missing)} of {files} frames have no EXIF GPS (the first: {missing[0]})")
    track.notes[:0] = notes
    return track


def _dms(value: float) -> tuple[tuple[int, int], tuple[int, int], tuple[int, int]]:
    total = round(abs(value) * 3600 * SECONDS_DENOMINATOR)  # in 1/10000 arc seconds, carried exactly
    degrees, rest = divmod(total, 3600 * SECONDS_DENOMINATOR)
    minutes, seconds = divmod(rest, 60 * SECONDS_DENOMINATOR)
    return (int(degrees), 1), (int(minutes), 1), (int(seconds), SECONDS_DENOMINATOR)


def gps_exif(lat: float, lon: float, alt: float) -> bytes:
    """The EXIF block (piexif's bytes) of a GPS position."""
    piexif = require("piexif", "writing GPS into EXIF")
    tags = piexif.GPSIFD
    gps = {
        tags.GPSVersionID: (2, 3, 0, 0),
        tags.GPSLatitudeRef: b"N" if lat >= 0 else b"S",
        tags.GPSLatitude: _dms(lat),
        tags.GPSLongitudeRef: b"E" if lon >= 0 else b"W",
        tags.GPSLongitude: _dms(lon),
        tags.GPSAltitudeRef: 0 if alt >= 0 else 1,
        tags.GPSAltitude: (int(round(abs(alt) * ALTITUDE_DENOMINATOR)), ALTITUDE_DENOMINATOR),
    }
    return piexif.dump({"0th": {}, "Exif": {}, "GPS": gps, "1st": {}, "thumbnail": None})


def write_gps_jpeg(path: str | Path, rgb: np.ndarray, lat: float, lon: float, alt: float, quality: int = 95) -> Path:
    """``rgb`` (H, W, 3) uint8 as a JPEG at ``path`` with its GPS position in the EXIF."""
    import cv2

    piexif = require("piexif", "writing GPS into EXIF")
    ok, data = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise GnssError(f"{path}: OpenCV could not encode the JPEG")
    out = io.BytesIO()
    piexif.insert(gps_exif(lat, lon, alt), data.tobytes(), out)
    Path(path).write_bytes(out.getvalue())
    return Path(path)
