"""ROS bags as recordings: images, the camera and GNSS fixes of a robot's log, read with the
pure-Python ``rosbags`` library (no ROS install).

A bag is a ROS 1 ``.bag`` file, or a ROS 2 bag: a folder with ``metadata.yaml`` and its
``.db3`` (sqlite3) or ``.mcap`` files, or one such file alone.  :class:`BagReader` takes one
image topic, ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage``: the only one the bag
has, or the one ``topic`` names (with several, the error lists them).  Frames come in bag
order, numbered from 0 (a frame's index is its message's place in the topic), timed by their
header stamps in seconds from the first frame's.  ``Image`` encodings read: ``mono8``,
``mono16``, ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8`` and the Bayer ones (``bayer_rggb8``,
``bayer_bggr8``, ``bayer_gbrg8``, ``bayer_grbg8`` and their 16-bit forms, demosaiced
bilinearly); 16-bit frames stay linear uint16 (normalised as DNG frames are,
:mod:`lburst.burst.raw`).  ``CompressedImage``: JPEG or PNG.

The camera is the ``sensor_msgs/CameraInfo`` of the image topic's namespace (``/cam/image_raw``
-> ``/cam/camera_info``), or the bag's only one: ``K`` and the ``plumb_bob`` distortion as a
COLMAP camera (``PINHOLE``, ``OPENCV`` or ``FULL_OPENCV``), held fixed like a ``meta.json``
camera.  A CameraInfo with a zero focal length (an uncalibrated camera) is refused naming the
topic; a ``meta.json`` beside the bag (``X.meta.json`` or inside its folder) with a ``camera``
(``null``: estimate it) is taken instead of any CameraInfo.  The fixes are those of the bag's
``sensor_msgs/NavSatFix`` topic (the one with the most messages, if several), on the frames'
clock; a message without a fix (status -1) is left out.

:class:`BagWriter` writes bags (ROS 1, or ROS 2 with sqlite3 or mcap storage) for tests and
``lburst simulate flight --bag``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lburst.burst.io import BurstError
from lburst.extras import require
from lburst.geo.fixes import GnssTrack, checked

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
NAVSAT = "sensor_msgs/msg/NavSatFix"
#: a bag given as one file
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
#: Bayer encodings -> the OpenCV conversion (OpenCV names a pattern by its second row)
BAYER = {"rggb": "BayerBG2RGB", "bggr": "BayerRG2RGB", "gbrg": "BayerGR2RGB", "grbg": "BayerGB2RGB"}
ENCODINGS = ("mono8", "mono16", "rgb8", "bgr8", "rgba8", "bgra8", *(f"bayer_{p}{b}" for p in BAYER for b in (8, 16)))


def is_bag(path: str | Path) -> bool:
    """A ROS 1 ``.bag``, a ROS 2 ``.db3`` or ``.mcap`` file, or a folder with ``metadata.yaml``."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in BAG_SUFFIXES


def _stamp(msg) -> int:
    """A message's header stamp in nanoseconds (integers: no rounding at epoch times)."""
    return int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)


def decode_image(msg, msgtype: str, where: str) -> np.ndarray:
    """An ``Image`` or ``CompressedImage`` message as RGB ``(H, W, 3)`` uint8 or uint16
    (module docstring); :class:`BurstError` naming ``where`` for what cannot be read."""
    import cv2

    if msgtype == COMPRESSED:
        image = cv2.imdecode(np.asarray(msg.data, np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise BurstError(f"{where}: the compressed image ({msg.format!r}) cannot be decoded")
        if image.ndim == 2:
            return np.repeat(image[..., None], 3, axis=2)
        return cv2.cvtColor(image, cv2.COLOR_BGRA2RGB if image.shape[2] == 4 else cv2.COLOR_BGR2RGB)
    encoding = msg.encoding.lower().replace("8uc1", "mono8").replace("16uc1", "mono16")
    if encoding not in ENCODINGS:
        raise BurstError(f"{where}: encoding {msg.encoding!r} is not supported ({', '.join(ENCODINGS)})")
    wide = encoding.endswith("16")
    channels = 4 if encoding.endswith("a8") else 3 if encoding in ("rgb8", "bgr8") else 1
    dtype = np.dtype(">u2" if msg.is_bigendian else "<u2") if wide else np.dtype(np.uint8)
    row = msg.width * channels * dtype.itemsize
    data = np.asarray(msg.data, np.uint8)
    if msg.step < row or len(data) < msg.step * msg.height or not msg.width or not msg.height:
        raise BurstError(f"{where}: {msg.width}x{msg.height} {msg.encoding} needs {row} bytes a row, has {msg.step}")
    rows = data[: msg.step * msg.height].reshape(msg.height, msg.step)[:, :row]
    image = (
        np.ascontiguousarray(rows).view(dtype).reshape(msg.height, msg.width, channels).astype(dtype.newbyteorder("="))
    )
    if encoding.startswith("bayer_"):
        return cv2.cvtColor(image[..., 0], getattr(cv2, f"COLOR_{BAYER[encoding[6:10]]}"))
    if channels == 1:
        return np.repeat(image, 3, axis=2)
    if encoding.startswith("bgr"):
        image = image[..., 2::-1]
    return np.ascontiguousarray(image[..., :3])


def camera_from_info(msg, where: str) -> dict:
    """A COLMAP camera dict of a ``CameraInfo`` (module docstring); :class:`BurstError` naming
    ``where`` for a zero or non-finite focal length or principal point."""
    K = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, float).reshape(3, 3)
    D = [float(v) for v in (getattr(msg, "d", None) if hasattr(msg, "d") else msg.D)]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not np.isfinite([fx, fy, cx, cy]).all() or fx <= 0 or fy <= 0:
        raise BurstError(
            f"{where}: CameraInfo with focal length {fx:g}, {fy:g} (an uncalibrated camera); give the camera, or "
            '{"camera": null} to have it estimated, in a meta.json beside the bag'
        )
    fx, fy, cx, cy = float(fx), float(fy), float(cx), float(cy)
    camera = {"width": int(msg.width), "height": int(msg.height)}
    if not any(D) or msg.distortion_model not in ("plumb_bob", "rational_polynomial"):
        return camera | {"model": "PINHOLE", "params": [fx, fy, cx, cy]}
    D = (D + [0.0] * 8)[:8]
    if not any(D[4:]):
        return camera | {"model": "OPENCV", "params": [fx, fy, cx, cy, *D[:4]]}
    return camera | {"model": "FULL_OPENCV", "params": [fx, fy, cx, cy, *D[:4], D[4], *D[5:8]]}


@dataclass(frozen=True)
class BagFrame:
    """One image of the bag: its index in the topic, time (s from the first frame), RGB image."""

    index: int
    time: float
    image: np.ndarray


class BagReader:
    """The image topic, camera and GNSS of a bag (module docstring); every problem is a
    :class:`BurstError` naming the bag and the topic."""

    def __init__(self, path: str | Path, topic: str | None = None):
        self.path = Path(path)
        highlevel = require("rosbags.highlevel", "reading a ROS bag")
        try:
            self._reader = highlevel.AnyReader([self.path])
            self._reader.open()
        except Exception as err:  # rosbags' errors have no common base: a bad bag in any way
            raise BurstError(f"{self.path}: not a readable ROS bag ({type(err).__name__}: {err})") from None
        topics = {c.topic: c.msgtype for c in self._reader.connections}
        images = sorted(t for t, kind in topics.items() if kind in (IMAGE, COMPRESSED))
        listed = ", ".join(f"{t} ({k.split('/')[-1]})" for t, k in sorted(topics.items())) or "none"
        if topic is None and len(images) != 1:
            which = (
                "no image topic"
                if not images
                else f"{len(images)} image topics ({', '.join(images)}): pick one with --topic"
            )
            raise BurstError(f"{self.path}: {which}; its topics: {listed}")
        self.topic = topic or images[0]
        if self.topic not in images:
            raise BurstError(
                f"{self.path}: no image topic {self.topic!r}; its image topics: {', '.join(images) or 'none'}"
            )
        self.msgtype = topics[self.topic]
        self.connections = [c for c in self._reader.connections if c.topic == self.topic]
        self.count = sum(c.msgcount for c in self.connections)
        if not self.count:
            raise BurstError(f"{self.path}: the image topic {self.topic} has no messages")
        self.t0 = _stamp(self._first(self.connections))

    def close(self) -> None:
        self._reader.close()

    def span(self) -> float:
        """Seconds the bag spans (its index's first to last message, without reading them)."""
        return max(0, self._reader.end_time - self._reader.start_time) * 1e-9

    def _messages(self, connections) -> Iterator[object]:
        for connection, _, raw in self._reader.messages(connections=connections):
            yield self._reader.deserialize(raw, connection.msgtype)

    def _first(self, connections):
        return next(self._messages(connections))

    def frames(self) -> Iterator[BagFrame]:
        """The frames in bag order (module docstring)."""
        for index, msg in enumerate(self._messages(self.connections)):
            where = f"{self.path}: {self.topic} message {index}"
            yield BagFrame(index, (_stamp(msg) - self.t0) * 1e-9, decode_image(msg, self.msgtype, where))

    def camera(self) -> dict | None:
        """The camera of the image topic's ``CameraInfo`` (module docstring), ``None`` without one."""
        infos = sorted({c.topic for c in self._reader.connections if c.msgtype == CAMERA_INFO})
        namespace = self.topic.rsplit("/", 1)[0] if self.topic.count("/") > 1 else ""
        near = [t for t in infos if namespace and t.startswith(namespace + "/")]
        chosen = near[0] if near else infos[0] if len(infos) == 1 else None
        if chosen is None:
            return None
        connections = [c for c in self._reader.connections if c.topic == chosen]
        if not sum(c.msgcount for c in connections):
            return None
        return camera_from_info(self._first(connections), f"{self.path}: {chosen}")

    def gnss_track(self) -> GnssTrack | None:
        """The fixes of the bag's ``NavSatFix`` topic on the frames' clock, ``None`` without one."""
        counts: dict[str, int] = {}
        for c in self._reader.connections:
            if c.msgtype == NAVSAT:
                counts[c.topic] = counts.get(c.topic, 0) + c.msgcount
        if not counts or not max(counts.values()):
            return None
        topic = max(sorted(counts), key=counts.get)
        candidates, no_fix = [], 0
        for index, msg in enumerate(self._messages([c for c in self._reader.connections if c.topic == topic])):
            if msg.status.status < 0:
                no_fix += 1
                continue
            where = f"{self.path.name}: {topic} message {index}"
            candidates.append((msg.latitude, msg.longitude, msg.altitude, where, (_stamp(msg) - self.t0) * 1e-9, None))
        track = checked(f"{self.path.name}: {topic} (NavSatFix, {len(candidates)} fixes)", candidates)
        if no_fix:
            track.notes.insert(0, f"{self.path}: {topic}: {no_fix} message(s) without a fix (status -1); not used")
        if len(counts) > 1:
            track.notes.insert(
                0, f"{self.path}: {len(counts)} NavSatFix topics ({', '.join(sorted(counts))}); took {topic}"
            )
        return track


class BagWriter:
    """A bag at ``path`` for tests and the simulator: ROS 1 for a ``.bag`` path, else a ROS 2
    folder with ``storage`` ``'sqlite3'`` or ``'mcap'``.  Use as a context manager."""

    def __init__(self, path: str | Path, storage: str = "sqlite3"):
        self.path = Path(path)
        typesys = require("rosbags.typesys", "writing a ROS bag")
        self.ros1 = self.path.suffix == ".bag"
        if self.ros1:
            from rosbags.rosbag1 import Writer

            self.store = typesys.get_typestore(typesys.Stores.ROS1_NOETIC)
            self._writer = Writer(self.path)
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer

            self.store = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
            self._writer = Writer(self.path, version=8, storage_plugin=StoragePlugin[storage.upper()])
        self._connections: dict[str, object] = {}

    def __enter__(self) -> BagWriter:
        self._writer.open()
        return self

    def __exit__(self, *exc) -> None:
        self._writer.close()

    def _write(self, topic: str, msgtype: str, stamp: float, msg) -> None:
        if topic not in self._connections:
            self._connections[topic] = self._writer.add_connection(topic, msgtype, typestore=self.store)
        data = self.store.serialize_ros1(msg, msgtype) if self.ros1 else self.store.serialize_cdr(msg, msgtype)
        self._writer.write(self._connections[topic], int(round(stamp * 1e9)), data)

    def _header(self, stamp: float, frame: str = "camera"):
        types = self.store.types
        sec = int(np.floor(stamp))
        time = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((stamp - sec) * 1e9)) % 10**9)
        if self.ros1:
            return types["std_msgs/msg/Header"](seq=0, stamp=time, frame_id=frame)
        return types["std_msgs/msg/Header"](stamp=time, frame_id=frame)

    def image(self, topic: str, stamp: float, pixels: np.ndarray, encoding: str) -> None:
        """An ``Image`` of ``pixels`` (H, W[, C]) stored as they are under ``encoding``."""
        pixels = np.ascontiguousarray(pixels)
        h, w = pixels.shape[:2]
        msg = self.store.types[IMAGE](
            header=self._header(stamp),
            height=h,
            width=w,
            encoding=encoding,
            is_bigendian=0,
            step=pixels.nbytes // h,
            data=pixels.reshape(-1).view(np.uint8),
        )
        self._write(topic, IMAGE, stamp, msg)

    def compressed(self, topic: str, stamp: float, rgb: np.ndarray, quality: int = 95) -> None:
        """A JPEG ``CompressedImage`` of ``rgb`` (H, W, 3) uint8."""
        import cv2

        ok, data = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, quality])
        msg = self.store.types[COMPRESSED](header=self._header(stamp), format="jpeg", data=data.reshape(-1))
        self._write(topic, COMPRESSED, stamp, msg)

    def camera_info(self, topic: str, stamp: float, camera: dict) -> None:
        """A ``CameraInfo`` of a ``PINHOLE`` or ``OPENCV`` COLMAP camera dict."""
        fx, fy, cx, cy, *dist = camera["params"]
        K = np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], float)
        P = np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], float)
        fields = {"d" if not self.ros1 else "D": np.array((dist + [0.0] * 5)[:5], float)}
        fields |= (
            {"k": K, "r": np.eye(3).reshape(-1), "p": P}
            if not self.ros1
            else {"K": K, "R": np.eye(3).reshape(-1), "P": P}
        )
        roi = self.store.types["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        msg = self.store.types[CAMERA_INFO](
            header=self._header(stamp),
            height=camera["height"],
            width=camera["width"],
            distortion_model="plumb_bob",
            binning_x=0,
            binning_y=0,
            roi=roi,
            **fields,
        )
        self._write(topic, CAMERA_INFO, stamp, msg)

    def navsat(self, topic: str, stamp: float, lat: float, lon: float, alt: float, status: int = 0) -> None:
        """A ``NavSatFix`` (``status`` -1: no fix)."""
        types = self.store.types
        msg = types[NAVSAT](
            header=self._header(stamp, "gps"),
            status=types["sensor_msgs/msg/NavSatStatus"](status=status, service=1),
            latitude=lat,
            longitude=lon,
            altitude=alt,
            position_covariance=np.zeros(9),
            position_covariance_type=0,
        )
        self._write(topic, NAVSAT, stamp, msg)
