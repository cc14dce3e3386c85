"""The local metric frame of a reconstruction with GNSS: east, north, up (metres) around an
origin fix, and the UTM zone of that origin, so that a model made in the local frame can be
given back in coordinates that GIS tools place (:mod:`lburst.geo.outputs`).

The conversions are PROJ's (pyproj): geodetic WGS 84 to Earth-centred Cartesian to
topocentric (``+proj=topocentric``), exact on the ellipsoid, so that a camera 1 km from the
origin is where the fix says within a millimetre; and WGS 84 to UTM (EPSG 326zz north, 327zz
south).  Altitudes are taken as the source gives them (EXIF and DJI: above sea level;
``NavSatFix``: above the ellipsoid): a constant offset between the two moves the whole model
up or down, and the local frame keeps it in the origin's altitude.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from lburst.extras import require
from lburst.geo.fixes import check_coordinates


def utm_epsg(lat: float, lon: float) -> int:
    """EPSG code of the WGS 84 UTM zone that holds ``lat``, ``lon`` (326zz north, 327zz south),
    with the zones of southern Norway and Svalbard as UTM draws them."""
    zone = int((lon + 180.0) // 6.0) % 60 + 1
    if 56.0 <= lat < 64.0 and 3.0 <= lon < 12.0:
        zone = 32
    elif 72.0 <= lat < 84.0 and 0.0 <= lon < 42.0:
        zone = 31 if lon < 9.0 else 33 if lon < 21.0 else 35 if lon < 33.0 else 37
    return (32600 if lat >= 0 else 32700) + zone


@dataclass(frozen=True)
class GeoOrigin:
    """The origin of a local east-north-up frame: latitude and longitude (degrees, WGS 84) and
    altitude (metres, as its source gives it)."""

    lat: float
    lon: float
    alt: float

    def __post_init__(self) -> None:
        check_coordinates(self.lat, self.lon, self.alt, "the origin")

    @property
    def epsg(self) -> int:
        """The EPSG code of the UTM zone of the origin (:func:`utm_epsg`)."""
        return utm_epsg(self.lat, self.lon)

    @cached_property
    def _enu(self):
        pyproj = require("pyproj", "converting GNSS positions to metres")
        return pyproj.Transformer.from_pipeline(
            "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad +step +proj=cart +ellps=WGS84 "
            f"+step +proj=topocentric +ellps=WGS84 +lon_0={self.lon!r} +lat_0={self.lat!r} +h_0={self.alt!r}"
        )

    @cached_property
    def _utm(self):
        pyproj = require("pyproj", "converting GNSS positions to UTM")
        return pyproj.Transformer.from_crs("EPSG:4979", f"EPSG:{self.epsg}", always_xy=True)

    def to_enu(self, lat, lon, alt) -> np.ndarray:
        """``(N, 3)`` east, north, up (m) of geodetic positions (arrays of N, or scalars: ``(3,)``)."""
        e, n, u = self._enu.transform(np.asarray(lon, float), np.asarray(lat, float), np.asarray(alt, float))
        return np.stack([e, n, u], axis=-1)

    def to_geodetic(self, enu: np.ndarray) -> np.ndarray:
        """``(N, 3)`` latitude, longitude (degrees) and altitude (m) of east-north-up points."""
        enu = np.asarray(enu, float)
        lon, lat, alt = self._enu.transform(enu[..., 0], enu[..., 1], enu[..., 2], direction="INVERSE")
        return np.stack([lat, lon, alt], axis=-1)

    def to_utm(self, enu: np.ndarray) -> np.ndarray:
        """``(N, 3)`` easting, northing (m, the origin's UTM zone) and altitude of east-north-up points."""
        geodetic = self.to_geodetic(enu)
        x, y, z = self._utm.transform(geodetic[..., 1], geodetic[..., 0], geodetic[..., 2])
        return np.stack([x, y, z], axis=-1)

    def to_json(self) -> dict:
        return {
            "latitude": self.lat,
            "longitude": self.lon,
            "altitude": self.alt,
            "frame": "east, north, up (m) around this origin",
            "crs": f"EPSG:{self.epsg}",
        }
