"""The synthetic night flight: a drone flies over a toy city and takes a burst of frames
at regular spacing, with exact ground-truth cameras.

Trajectory: at time ``s`` (seconds) the drone is at altitude ``altitude`` and has flown
``speed * s`` metres along a path that starts at the origin heading ``heading_deg``
(counter-clockwise from +x).  By default (``survey_lines = 0``) the path is an arc that
turns steadily by ``turn_deg`` over the flight.  A survey (``survey_lines = L >= 2``) is a
lawnmower pattern instead: ``L`` straight lines of ``line_length``, parallel to the
heading, line ``i`` flown the other way from line ``i - 1`` and ``i * line_spacing`` to the
left of the first (counter-clockwise from the heading), joined by semicircular turns of
radius ``line_spacing / 2``; neighbouring lines thus see the ground turned by 180 degrees.
A survey's bursts cover its whole path (``L * line_length + (L - 1) * pi * line_spacing /
2`` metres), so its ``n_bursts`` is derived (:func:`survey_bursts`), and ``OUT/survey.json``
gives the line of each burst (:func:`survey_line`).  The camera looks forward along the
path and down, ``pitch_deg`` from nadir, with a small deterministic attitude wobble
(``shake_deg``).  Burst ``i`` is centred at time
``i * burst_spacing / speed``; its frame ``k`` (0-based, of ``frames_per_burst``) is
rendered from the pose at ``(k - mid) * frame_interval`` seconds later, so the frames of
a burst see the scene with real parallax, and the middle frame is the common frame whose
pose goes into ``reference.json`` (see :mod:`lburst.sfm.reference` for conventions).

Scene folder written by :func:`make_night_flight`::

    OUT/night_flight.json        the configuration (a re-run with another one is refused)
    OUT/0000/frame_000.png ...   uint8 RGB frames of each burst, temporal order
    OUT/reference.json           exact poses of the common frames
    OUT/survey.json              a survey only: burst name -> its line (-1: on a turn)
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from lburst.burst.io import atomic_path, save_burst
from lburst.errors import LBurstValueError
from lburst.memory import check_memory, gib
from lburst.noise import noise_from_spec
from lburst.numbers import check_integer, check_real
from lburst.scenes.city import DAYLIGHT, City, CityConfig, build_city, shade
from lburst.scenes.raycast import cast, intrinsics, rays_through
from lburst.sfm.reference import Reference

CONFIG_FILE = "night_flight.json"
SURVEY_FILE = "survey.json"
SURVEY_FIELDS = ("survey_lines", "line_length", "line_spacing")
Noise = Callable[[np.ndarray, np.random.Generator], np.ndarray]
#: bytes per texel of the ground texture that building the city holds at its peak: 55 measured
#: (peak resident memory of make_city, 447 MiB for the default flight's 8.5 M texels, 1105 MiB for
#: 40 bursts' 22 M)
CITY_BYTES_PER_TEXEL = 56
#: bytes per rendered pixel (``width * height * supersample**2``) at the peak of rendering one
#: frame (rays, hits, shading): 185 measured (tracemalloc, 1600x1200 and 800x600 at supersample 2)
RENDER_BYTES_PER_PIXEL = 192
#: bursts whose views estimate the ground a flight sees (:func:`flight_bytes`)
SAMPLED_BURSTS = 256


@dataclass(frozen=True)
class NightFlightConfig:
    """The flight, the camera, the noise and the city.  Lengths in metres, times in seconds.

    Attributes:
        n_bursts, frames_per_burst: number of bursts and frames per burst (odd); a survey
            replaces ``n_bursts`` by the count its path makes (:func:`survey_bursts`).
        width, height, hfov_deg: image size and horizontal field of view.
        altitude, speed, heading_deg, turn_deg: flight (see module docstring).
        pitch_deg: camera tilt from nadir, forward.
        frame_interval: time between frames of a burst (speed * interval = motion per frame).
        burst_spacing: distance flown between consecutive common frames.
        shake_deg: amplitude of the attitude wobble.
        supersample: render at this many times the resolution and area-average (anti-aliasing).
        exposure: gain applied to the rendered image before noise and 8-bit rounding.
        noise: noise spec for :func:`lburst.noise.noise_from_spec` (``'none'``: clean).
        seed: seed of the city and of the noise.
        city: how the city looks (:data:`lburst.scenes.city.DAYLIGHT` for a day flight).
        survey_lines: 0 (the arc path) or the number ``L >= 2`` of survey lines (``turn_deg``
            then does not apply).
        line_length, line_spacing: length of a survey line and distance between neighbouring lines.
    """

    n_bursts: int = 15
    frames_per_burst: int = 5
    width: int = 640
    height: int = 480
    hfov_deg: float = 60.0
    altitude: float = 40.0
    speed: float = 5.0
    heading_deg: float = 0.0
    turn_deg: float = 30.0
    pitch_deg: float = 35.0
    frame_interval: float = 0.05
    burst_spacing: float = 8.0
    shake_deg: float = 0.3
    supersample: int = 1
    exposure: float = 1.0
    noise: str = "none"
    seed: int = 0
    city: CityConfig = field(default_factory=CityConfig)
    survey_lines: int = 0
    line_length: float = 80.0
    line_spacing: float = 24.0

    def __post_init__(self) -> None:
        self._check_survey()
        if self.frames_per_burst < 1 or self.frames_per_burst % 2 == 0:
            raise LBurstValueError(f"frames_per_burst must be odd, got {self.frames_per_burst}")
        if self.n_bursts < 1 or self.width < 8 or self.height < 8 or self.supersample < 1:
            raise LBurstValueError("n_bursts >= 1, image size >= 8 and supersample >= 1 are required")
        if self.pitch_deg + self.vfov_deg / 2 >= 85:
            raise LBurstValueError(
                f"pitch {self.pitch_deg} deg sees the horizon; lower it below {85 - self.vfov_deg / 2:.0f}"
            )
        if self.city.max_height >= self.altitude - 2:
            raise LBurstValueError("buildings must stay below the flight altitude")
        _noise(self.noise)  # a bad spec fails here, before the city is built

    def _check_survey(self) -> None:
        """Check the survey fields and, for a survey, derive ``n_bursts`` from its path."""
        if check_integer(self.survey_lines, "survey_lines", 0) == 1:
            raise LBurstValueError("survey_lines must be 0 (the arc path) or >= 2 (survey lines), got 1")
        check_real(self.line_length, "line_length", 0, low_open=True)
        check_real(self.line_spacing, "line_spacing", 0, low_open=True)
        if self.survey_lines:
            check_real(self.burst_spacing, "burst_spacing", 0, low_open=True)
            check_real(self.speed, "speed", 0, low_open=True)
            object.__setattr__(self, "n_bursts", survey_bursts(self))

    @property
    def vfov_deg(self) -> float:
        return float(np.degrees(2 * np.arctan(np.tan(np.radians(self.hfov_deg) / 2) * self.height / self.width)))

    def to_dict(self) -> dict[str, Any]:
        """The fields as JSON-ready data; an arc flight with the default survey fields leaves
        them out (its ``night_flight.json`` is what it was before surveys existed)."""
        data = dataclasses.asdict(self)
        defaults = {f.name: f.default for f in dataclasses.fields(self) if f.name in SURVEY_FIELDS}
        if all(data[name] == value for name, value in defaults.items()):
            for name in SURVEY_FIELDS:
                del data[name]
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "NightFlightConfig":
        data = dict(data)
        data["city"] = CityConfig(**data.get("city", {}))
        return cls(**data)

    @classmethod
    def daylight(cls, **kwargs: Any) -> "NightFlightConfig":
        """The same flight in daylight (no lamps, no lit windows)."""
        city = kwargs.pop("city", CityConfig())
        return cls(city=dataclasses.replace(city, **DAYLIGHT), **kwargs)


def burst_name(i: int) -> str:
    return f"{i:04d}"


def frame_time(cfg: NightFlightConfig, burst: int, frame: int) -> float:
    """Time (s) of ``frame`` of ``burst``; the middle frame is at ``burst * spacing / speed``."""
    return burst * cfg.burst_spacing / cfg.speed + (frame - cfg.frames_per_burst // 2) * cfg.frame_interval


def path_length(cfg: NightFlightConfig) -> float:
    """Metres of path from the first common frame to the end: ``(n_bursts - 1) *
    burst_spacing`` for the arc, ``L * line_length + (L - 1) * pi * line_spacing / 2`` for a survey."""
    if not cfg.survey_lines:
        return (cfg.n_bursts - 1) * cfg.burst_spacing
    lines = cfg.survey_lines
    return float(lines * cfg.line_length + (lines - 1) * np.pi * cfg.line_spacing / 2)


def survey_bursts(cfg: NightFlightConfig) -> int:
    """Bursts of a survey: one every ``burst_spacing`` metres from the start of its path to its end."""
    return int(np.floor(path_length(cfg) / cfg.burst_spacing + 1e-9)) + 1


def _survey_place(cfg: NightFlightConfig, s: float) -> tuple[int, float, bool]:
    """``(i, u, on_line)``: ``s`` metres into a survey is ``u`` metres past the start of line
    ``i``, on the line itself or (``on_line`` false) on the turn after it.  Before the start
    and after the end the first and last lines go on straight."""
    period = cfg.line_length + np.pi * cfg.line_spacing / 2
    i = int(np.clip(np.floor(s / period), 0, cfg.survey_lines - 1))
    u = s - i * period
    if i < cfg.survey_lines - 1 and u >= period - 1e-9:  # the start of the next line, up to rounding
        i, u = i + 1, u - period
    return i, u, i == cfg.survey_lines - 1 or u <= cfg.line_length + 1e-9


def _survey_point(cfg: NightFlightConfig, s: float) -> tuple[np.ndarray, float]:
    """Ground position (2,) and heading (radians) ``s`` metres along a survey path."""
    i, u, on_line = _survey_place(cfg, s)
    psi0 = np.radians(cfg.heading_deg)
    forward = np.array([np.cos(psi0), np.sin(psi0)])
    left = np.array([-np.sin(psi0), np.cos(psi0)])
    sign = 1 - 2 * (i % 2)  # +1: along the heading, -1: against it
    psi = psi0 + (i % 2) * np.pi
    start = i * cfg.line_spacing * left + (i % 2) * cfg.line_length * forward
    if on_line:
        return start + sign * u * forward, psi
    kappa = sign / (cfg.line_spacing / 2)  # turns alternate: left after even lines, right after odd ones
    turned = psi + kappa * (u - cfg.line_length)
    arc = np.array([np.sin(turned) - np.sin(psi), np.cos(psi) - np.cos(turned)]) / kappa
    return start + sign * cfg.line_length * forward + arc, turned


def _arc_point(cfg: NightFlightConfig, s: float) -> tuple[np.ndarray, float]:
    """Ground position (2,) and heading (radians) ``s`` metres along the arc path."""
    total = max((cfg.n_bursts - 1) * cfg.burst_spacing, 1e-9)
    kappa = np.radians(cfg.turn_deg) / total  # heading change per metre
    psi0 = np.radians(cfg.heading_deg)
    psi = psi0 + kappa * s
    if abs(kappa) < 1e-12:
        xy = s * np.array([np.cos(psi0), np.sin(psi0)])
    else:
        xy = np.array([np.sin(psi) - np.sin(psi0), np.cos(psi0) - np.cos(psi)]) / kappa
    return xy, psi


def path_point(cfg: NightFlightConfig, s: float) -> tuple[np.ndarray, float]:
    """Ground position (2,) and heading (radians, counter-clockwise from +x) ``s`` metres
    along the flight's path (arc or survey, see the module docstring)."""
    return _survey_point(cfg, s) if cfg.survey_lines else _arc_point(cfg, s)


def survey_line(cfg: NightFlightConfig, burst: int) -> int:
    """The survey line (0-based) that the common frame of ``burst`` lies on, or -1 when it
    is on a turn; ``ValueError`` for an arc flight."""
    if not cfg.survey_lines:
        raise LBurstValueError("survey_line needs a survey (survey_lines >= 2)")
    i, _, on_line = _survey_place(cfg, burst * cfg.burst_spacing)
    return i if on_line else -1


def camera_pose(cfg: NightFlightConfig, time: float) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera ``(R (3, 3), t (3,))`` of the drone's camera at ``time``."""
    xy, psi = path_point(cfg, cfg.speed * time)
    centre = np.array([xy[0], xy[1], cfg.altitude])
    heading = np.array([np.cos(psi), np.sin(psi), 0.0])
    theta = np.radians(cfg.pitch_deg)
    z_axis = np.sin(theta) * heading + np.array([0.0, 0.0, -np.cos(theta)])
    x_axis = np.array([heading[1], -heading[0], 0.0])
    y_axis = np.cross(z_axis, x_axis)
    base = np.stack([x_axis, y_axis, z_axis])
    wobble = np.radians(cfg.shake_deg) * np.sin(
        2 * np.pi * np.array([1.3, 0.9, 0.7]) * time + np.array([0.4, 1.7, 2.9])
    )
    R = Rotation.from_rotvec(wobble).as_matrix() @ base
    return R, -R @ centre


def burst_poses(cfg: NightFlightConfig, burst: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Poses of the frames of ``burst`` in temporal order."""
    return [camera_pose(cfg, frame_time(cfg, burst, k)) for k in range(cfg.frames_per_burst)]


def reference(cfg: NightFlightConfig) -> Reference:
    """Exact cameras of the common frames; ``length`` is the polyline length of their centres."""
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    mid = cfg.frames_per_burst // 2
    poses = {burst_name(i): camera_pose(cfg, frame_time(cfg, i, mid)) for i in range(cfg.n_bursts)}
    centres = np.array([-R.T @ t for R, t in poses.values()])
    length = float(np.linalg.norm(np.diff(centres, axis=0), axis=1).sum())
    camera = {
        "model": "PINHOLE",
        "width": cfg.width,
        "height": cfg.height,
        "params": [K[0, 0], K[1, 1], K[0, 2], K[1, 2]],
    }
    return Reference(source="synthetic", camera=camera, poses=poses, length=length)


def gnss_positions(cfg: NightFlightConfig, std: float) -> dict[str, np.ndarray]:
    """What a GNSS receiver would log for the common frames: each true camera centre plus
    Gaussian noise of ``std`` metres on each coordinate, seeded by the config's seed."""
    rng = np.random.default_rng([cfg.seed, 2])
    return {name: -R.T @ t + rng.normal(0.0, std, 3) for name, (R, t) in reference(cfg).poses.items()}


def ground_bounds(cfg: NightFlightConfig, margin: float = 10.0, bursts: Sequence[int] | None = None) -> np.ndarray:
    """(2, 2) ``[[x0, y0], [x1, y1]]`` covering the ground seen by every frame (of ``bursts``, default all)."""
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    w, h = cfg.width, cfg.height
    xs, ys = np.linspace(0, w, 33), np.linspace(0, h, 25)
    uv = np.concatenate(
        [
            np.column_stack([xs, np.zeros_like(xs)]),
            np.column_stack([xs, np.full_like(xs, h)]),
            np.column_stack([np.zeros_like(ys), ys]),
            np.column_stack([np.full_like(ys, w), ys]),
        ]
    )
    pts = []
    for i in range(cfg.n_bursts) if bursts is None else bursts:
        for k in (0, cfg.frames_per_burst - 1):
            R, t = camera_pose(cfg, frame_time(cfg, i, k))
            border = rays_through(K, R, uv)
            dz = np.minimum(border[:, 2], -1e-3)
            dist = np.minimum(-cfg.altitude / dz, 8 * cfg.altitude)
            pts.append((-R.T @ t)[:2] + dist[:, None] * border[:, :2])
    pts = np.concatenate(pts)
    return np.stack([pts.min(0) - margin, pts.max(0) + margin])


def flight_bytes(cfg: NightFlightConfig) -> tuple[float, float, float]:
    """Estimated peak memory of the flight's city (bytes, from the ground it sees: the views of
    at most :data:`SAMPLED_BURSTS` bursts spread along the path, which cost milliseconds where all
    of a long survey's would cost minutes), of rendering one frame (bytes), and the ground's area (m^2)."""
    sample = np.unique(np.linspace(0, cfg.n_bursts - 1, min(cfg.n_bursts, SAMPLED_BURSTS)).round().astype(int))
    (x0, y0), (x1, y1) = ground_bounds(cfg, bursts=sample)
    area = float((x1 - x0) * (y1 - y0))
    texels = area / cfg.city.ground_texel**2
    return (
        texels * CITY_BYTES_PER_TEXEL,
        float(cfg.width * cfg.height) * cfg.supersample**2 * RENDER_BYTES_PER_PIXEL,
        area,
    )


def check_flight_memory(cfg: NightFlightConfig) -> None:
    """``ValueError`` with the figure and what lowers it when the city and the rendering of one
    frame (:func:`flight_bytes`) would need more than half of the machine's memory."""
    city, frame, area = flight_bytes(cfg)
    if city >= frame:
        what = f"the city under this flight ({area / 1e6:.3g} km^2 of ground in view) with a frame's rendering"
        lower = "fly a shorter path (--bursts, --spacing; --survey, --line-length, --line-spacing)"
    else:
        pixels = f"{cfg.width}x{cfg.height}" + (f" x{cfg.supersample} supersampled" if cfg.supersample > 1 else "")
        what = f"rendering a {pixels} frame (with the city, {gib(city)})"
        lower = "render smaller frames (--size, --supersample)"
    check_memory(city + frame, what, lower)


def make_city(cfg: NightFlightConfig) -> City:
    """The flight's city: random from ``cfg.seed``, styled by ``cfg.city``, covering the ground in
    view; ``ValueError`` first when it and a frame's rendering would not fit (:func:`check_flight_memory`)."""
    check_flight_memory(cfg)
    return build_city(ground_bounds(cfg), cfg.city, np.random.default_rng([cfg.seed, 0]))


def render_view(
    city: City, K: np.ndarray, R: np.ndarray, t: np.ndarray, width: int, height: int, supersample: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free image (H, W, 3) float32 0..255 and z-depth (H, W) (``inf``: sky) of a camera."""
    s = supersample
    Ks = np.diag([s, s, 1.0]) @ K
    hits = cast(Ks, R, t, width * s, height * s, city.lo, city.hi)
    image = shade(city, hits, Ks[0, 0])
    depth = hits.t * (hits.dirs @ R[2])
    if s > 1:
        image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
        depth = depth[s // 2 :: s, s // 2 :: s]  # nearest sample (exact at odd s)
    return image, depth


def view_overlaps(
    cfg: NightFlightConfig,
    city: City | None = None,
    scale: float = 0.25,
    pairs: Sequence[tuple[int, int]] | None = None,
) -> np.ndarray:
    """(n_bursts - 1,) fraction of the pixels of common frame ``i + 1`` whose surface point
    is in view and unoccluded in common frame ``i`` (computed at ``scale`` x resolution);
    with ``pairs`` ``[(a, b), ...]``, that fraction for common frame ``b`` seen from ``a``."""
    city = make_city(cfg) if city is None else city
    w, h = max(int(cfg.width * scale), 8), max(int(cfg.height * scale), 8)
    K = intrinsics(w, h, cfg.hfov_deg)
    pairs = [(i, i + 1) for i in range(cfg.n_bursts - 1)] if pairs is None else pairs
    poses = reference(cfg).poses
    views = {}
    for i in sorted({i for pair in pairs for i in pair}):
        R, t = poses[burst_name(i)]
        hits = cast(K, R, t, w, h, city.lo, city.hi)
        views[i] = (R, t, hits.points, hits.t * (hits.dirs @ R[2]))
    out = []
    for (Ra, ta, _, depth_a), (_, _, points_b, depth_b) in ((views[a], views[b]) for a, b in pairs):
        pts = points_b[np.isfinite(depth_b)]
        cam = pts @ Ra.T + ta
        uv = cam[:, :2] / cam[:, 2:] * K[[0, 1], [0, 1]] + K[:2, 2]
        col, row = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        inside = (cam[:, 2] > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        seen = depth_a[row[inside], col[inside]]
        visible = np.abs(seen - cam[inside, 2]) < 0.03 * cam[inside, 2]
        out.append(visible.sum() / (w * h))
    return np.array(out)


def _noise(spec: str) -> Noise | None:
    if spec in ("", "none"):
        return None

    return noise_from_spec(spec)


def render_burst(cfg: NightFlightConfig, burst: int, city: City | None = None, noisy: bool = True) -> np.ndarray:
    """Frames (F, H, W, 3) uint8 of ``burst``, scaled by ``cfg.exposure``; noise from
    ``cfg.noise`` (seeded by the config's seed, the burst and the frame) unless ``noisy``
    is false."""
    city = make_city(cfg) if city is None else city
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    noise = _noise(cfg.noise) if noisy else None
    frames = []
    for k, (R, t) in enumerate(burst_poses(cfg, burst)):
        image, _ = render_view(city, K, R, t, cfg.width, cfg.height, cfg.supersample)
        image *= cfg.exposure
        if noise is not None:
            image = noise(image, np.random.default_rng([cfg.seed, 1, burst, k]))
        frames.append(np.clip(np.round(image), 0, 255).astype(np.uint8))
    return np.stack(frames)


def clean_common_frames(cfg: NightFlightConfig, city: City | None = None) -> dict[str, np.ndarray]:
    """Noise-free common (middle) frames scaled by ``cfg.exposure``, burst name -> (H, W, 3) uint8."""
    city = make_city(cfg) if city is None else city
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    out = {}
    for name, (R, t) in reference(cfg).poses.items():
        image, _ = render_view(city, K, R, t, cfg.width, cfg.height, cfg.supersample)
        out[name] = np.clip(np.round(image * cfg.exposure), 0, 255).astype(np.uint8)
    return out


def make_night_flight(
    out_dir: str | Path, cfg: NightFlightConfig = NightFlightConfig(), progress: bool = True
) -> Reference:
    """Render the flight into the scene folder ``out_dir`` and return its reference.

    Bursts already in ``out_dir`` are kept (resume); a folder made with another
    configuration is refused with ``ValueError``.
    """
    check_flight_memory(cfg)  # before the folder is made
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    config_path = out / CONFIG_FILE
    if config_path.exists():
        try:
            old = json.loads(config_path.read_text())
        except json.JSONDecodeError as err:
            raise LBurstValueError(f"{config_path}: not valid JSON ({err})") from err
        if old != json.loads(json.dumps(cfg.to_dict())):
            raise LBurstValueError(f"{config_path}: {out} was made with another configuration; use a new folder")
    else:
        with atomic_path(config_path) as tmp:
            tmp.write_text(json.dumps(cfg.to_dict(), indent=1))
    todo = [i for i in range(cfg.n_bursts) if not (out / burst_name(i)).is_dir()]
    if todo:
        city = make_city(cfg)
        bar = range(len(todo))
        if progress:
            from tqdm import tqdm

            bar = tqdm(bar, desc="night flight", unit="burst")
        for j in bar:
            i = todo[j]
            save_burst(render_burst(cfg, i, city), out / burst_name(i), whole=True)
    ref = reference(cfg)
    ref.save(out / "reference.json")
    if cfg.survey_lines:
        lines = {burst_name(i): survey_line(cfg, i) for i in range(cfg.n_bursts)}
        with atomic_path(out / SURVEY_FILE) as tmp:
            tmp.write_text(json.dumps(lines, indent=1))
    return ref
