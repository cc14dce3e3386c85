"""A model made in a GNSS frame, written for GIS tools: its 3D points as a LAS point cloud in
UTM with the CRS recorded (QGIS, CloudCompare, PDAL read it), and its cameras as GeoJSON.

The model's frame is east, north, up in metres around an origin fix
(:class:`lburst.geo.frame.GeoOrigin`).  :func:`write_las` converts each point to the
origin's UTM zone (easting, northing, altitude as the fixes gave it) and writes LAS 1.4,
point format 7 (RGB), coordinates to the millimetre, with the zone's WGS 84 / UTM CRS as a
WKT record (laspy).  :func:`write_cameras_geojson` writes one GeoJSON point feature per
registered camera (longitude, latitude, altitude, RFC 7946's WGS 84) with its name, its
heading (degrees clockwise from north), pitch (degrees above the horizon) and roll of the
viewing direction, and its camera-to-ENU rotation as a quaternion ``[w, x, y, z]``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from lburst.extras import pycolmap, require
from lburst.geo.frame import GeoOrigin

LAS_FILE = "model.las"
GEOJSON_FILE = "cameras.geojson"
LAS_SCALE = 0.001  # m


def write_las(path: str | Path, origin: GeoOrigin, points: np.ndarray, colours: np.ndarray | None = None) -> Path:
    """``points`` (N, 3) east, north, up of ``origin`` (m), with ``colours`` (N, 3) uint8, as a
    LAS file in the origin's UTM zone (module docstring)."""
    laspy = require("laspy", "writing a LAS point cloud")
    pyproj = require("pyproj", "writing a LAS point cloud")
    utm = origin.to_utm(np.asarray(points, float).reshape(-1, 3))
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.scales = np.full(3, LAS_SCALE)
    header.offsets = np.floor(utm.min(axis=0)) if len(utm) else np.zeros(3)
    header.add_crs(pyproj.CRS.from_epsg(origin.epsg))
    las = laspy.LasData(header)
    las.x, las.y, las.z = utm[:, 0], utm[:, 1], utm[:, 2]
    if colours is not None and len(utm):
        rgb = np.asarray(colours, np.uint16).reshape(-1, 3) * 257
        las.red, las.green, las.blue = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    las.write(str(path))
    return Path(path)


def camera_feature(name: str, R: np.ndarray, t: np.ndarray, origin: GeoOrigin, **properties) -> dict:
    """The GeoJSON feature of a camera with world-to-camera pose ``R``, ``t`` in the ENU frame."""
    R, t = np.asarray(R, float), np.asarray(t, float)
    lat, lon, alt = origin.to_geodetic(-R.T @ t)
    east, north, up = R.T @ np.array([0.0, 0.0, 1.0])  # the viewing direction
    right = R.T @ np.array([1.0, 0.0, 0.0])
    level = np.cross([east, north, up], [0.0, 0.0, 1.0])  # the horizontal to the right of the view
    roll = np.degrees(np.arctan2(np.dot(np.cross(level, right), [east, north, up]), np.dot(level, right)))
    x, y, z, w = Rotation.from_matrix(R.T).as_quat()
    props = {
        "name": name,
        "heading_deg": float(np.degrees(np.arctan2(east, north)) % 360),
        "pitch_deg": float(np.degrees(np.arcsin(np.clip(up, -1, 1)))),
        "roll_deg": float(roll) if np.linalg.norm(level) > 1e-9 else 0.0,
        "enu_from_camera_wxyz": [float(w), float(x), float(y), float(z)],
        **properties,
    }
    return {"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat, alt]}, "properties": props}


def write_cameras_geojson(
    path: str | Path, origin: GeoOrigin, poses: dict[str, tuple], properties: dict | None = None
) -> Path:
    """The cameras ``poses`` (name -> world-to-camera ``(R, t)`` in the ENU frame) as a GeoJSON
    feature collection (module docstring); ``properties``: name -> further properties."""
    features = [camera_feature(n, R, t, origin, **(properties or {}).get(n, {})) for n, (R, t) in poses.items()]
    data = {"type": "FeatureCollection", "features": features}
    Path(path).write_text(json.dumps(data, indent=1))
    return Path(path)


def write_georeferenced(out: Path, origin: GeoOrigin, model_dir: Path, poses: dict[str, tuple]) -> dict:
    """``OUT/model.las`` from the COLMAP model in ``model_dir`` and ``OUT/cameras.geojson`` from
    ``poses``; returns what ``result.json`` records of them (file names and CRS)."""
    rec = pycolmap.Reconstruction(str(model_dir))
    points = np.array([p.xyz for p in rec.points3D.values()]).reshape(-1, 3)
    colours = np.array([p.color for p in rec.points3D.values()], np.uint8).reshape(-1, 3)
    write_las(out / LAS_FILE, origin, points, colours)
    write_cameras_geojson(out / GEOJSON_FILE, origin, poses)
    return {"points": LAS_FILE, "points3D": len(points), "cameras": GEOJSON_FILE, "crs": f"EPSG:{origin.epsg}"}
