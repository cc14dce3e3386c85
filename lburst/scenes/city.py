"""A textured toy city for the night flight: streets, photo-textured lots, box buildings
with windows, parked cars and street lamps; and its shading.

World coordinates are metres, z up, the ground is ``z = 0`` (see
:mod:`lburst.scenes.raycast`).  Night lighting (dim ambient light, pools of lamp light
on the ground, lit windows, the lamps themselves) is baked into the textures, so a
surface point has the same colour from every view.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lburst.scenes.raycast import GROUND, Hits
from lburst.scenes.textures import MipTexture, mosaic, noise_field, scatter_shapes

BUILDING, LAMP = 0, 1
FLOOR_TEXELS = 64  # wall texels per storey (and per window column)


@dataclass(frozen=True)
class CityConfig:
    """How the city looks.  Lengths in metres; light levels relative to daylight (1).

    Attributes:
        ground_texel, wall_texel, roof_texel: size of one texel of each material.
        block: period of the street grid; street_width: width of the streets.
        building_density: probability that a lot holds a building.
        min_height, max_height: building heights.
        car_spacing: mean distance between parked cars along a street (0: none).
        ambient: light level of surfaces away from lamps (1: daylight, ~0.3: night).
        lamp_spacing: distance between street lamps along a street (0: no lamps).
        lamp_height, lamp_gain: lamp height and the light it adds on the ground below.
        lit_windows: fraction of windows lit from inside.
    """

    ground_texel: float = 0.06
    wall_texel: float = 0.05
    roof_texel: float = 0.06
    block: float = 32.0
    street_width: float = 9.0
    building_density: float = 0.7
    min_height: float = 4.0
    max_height: float = 22.0
    car_spacing: float = 12.0
    ambient: float = 0.35
    lamp_spacing: float = 24.0
    lamp_height: float = 6.0
    lamp_gain: float = 1.5
    lit_windows: float = 0.35


DAYLIGHT = dict(ambient=1.0, lamp_spacing=0.0, lit_windows=0.0)


@dataclass
class City:
    """Boxes and textures of a city.

    Attributes:
        lo, hi: (B, 3) box corners; kind: (B,) ``BUILDING`` or ``LAMP``.
        ground: texture of the ground; texel ``(row r, column c)`` covers world
            ``x in origin[0] + [c, c + 1) * ground_texel``, ``y in origin[1] + [r, r + 1) * ground_texel``.
        roof, wall: textures of building tops and sides.
        box_uv: (B, 3, 2) texel offsets of each box's faces, indexed by face-normal axis
            (0, 1: walls, 2: roof).
        box_gain: (B, 3) colour gain of each box.
        lamp_colour, sky: (3,) colours 0..255 of lamps and of rays that hit nothing.
    """

    lo: np.ndarray
    hi: np.ndarray
    kind: np.ndarray
    ground: MipTexture
    origin: np.ndarray
    ground_texel: float
    roof: MipTexture
    roof_texel: float
    wall: MipTexture
    wall_texel: float
    box_uv: np.ndarray
    box_gain: np.ndarray
    lamp_colour: np.ndarray
    sky: np.ndarray


def _street_mask(coords: np.ndarray, phase: float, cfg: CityConfig) -> np.ndarray:
    return ((coords - phase) % cfg.block) < cfg.street_width


def _lamps(bounds: np.ndarray, phase: np.ndarray, cfg: CityConfig) -> np.ndarray:
    """(L, 2) lamp positions along one side of every street."""
    if cfg.lamp_spacing <= 0:
        return np.zeros((0, 2))
    side = cfg.street_width - 1.0
    out = []
    for axis in (0, 1):
        lines = np.arange(phase[axis] - cfg.block, bounds[1, axis] + cfg.block, cfg.block) + side
        lines = lines[(lines > bounds[0, axis]) & (lines < bounds[1, axis])]
        other = 1 - axis
        along = np.arange(bounds[0, other], bounds[1, other], cfg.lamp_spacing) + cfg.lamp_spacing / 2
        for line in lines:
            pts = np.empty((len(along), 2))
            pts[:, axis], pts[:, other] = line, along
            out.append(pts)
    return np.concatenate(out) if out else np.zeros((0, 2))


def _light_map(bounds: np.ndarray, lamps: np.ndarray, cfg: CityConfig, shape: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) float32 ground illumination: ambient plus lamp pools (warm)."""
    step = 0.5
    xs = np.arange(bounds[0, 0], bounds[1, 0], step) + step / 2
    ys = np.arange(bounds[0, 1], bounds[1, 1], step) + step / 2
    lamp = np.zeros((len(ys), len(xs)), np.float32)
    h = cfg.lamp_height
    for lx, ly in lamps:
        dx2 = ((xs - lx) ** 2)[None, :]
        dy2 = ((ys - ly) ** 2)[:, None]
        lamp += (cfg.lamp_gain * h**3 / (dx2 + dy2 + h * h) ** 1.5).astype(np.float32)
    lamp = cv2.resize(lamp, (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)
    ambient = cfg.ambient * np.array([0.85, 0.9, 1.0], np.float32)
    warm = np.array([1.0, 0.8, 0.55], np.float32)
    return ambient + lamp[..., None] * warm


def _paint_cars(
    img: np.ndarray, bounds: np.ndarray, phase: np.ndarray, cfg: CityConfig, rng: np.random.Generator
) -> None:
    """Parked cars (coloured rectangles with a dark windscreen) along the streets."""
    if cfg.car_spacing <= 0:
        return
    t = cfg.ground_texel
    for axis in (0, 1):
        other = 1 - axis
        starts = np.arange(phase[axis] - cfg.block, bounds[1, axis], cfg.block)
        for s in starts:
            n = rng.poisson((bounds[1, other] - bounds[0, other]) / cfg.car_spacing)
            for along in rng.uniform(bounds[0, other], bounds[1, other], n):
                across = s + (1.2 if rng.random() < 0.5 else cfg.street_width - 3.0)
                size = {axis: 1.8, other: 4.4}
                lo = {axis: across, other: along}
                colour = rng.integers(20, 256, size=3)
                box = [(lo[a] - bounds[0, a]) / t for a in (0, 1)]
                c0, r0 = int(box[0]), int(box[1])
                c1, r1 = int(box[0] + size[0] / t), int(box[1] + size[1] / t)
                img[max(r0, 0) : max(r1, 0), max(c0, 0) : max(c1, 0)] = colour
                # windscreen: a dark band across the car, a quarter of the way along it
                if axis == 0:
                    q = r0 + (r1 - r0) // 4
                    img[max(q, 0) : max(q + (r1 - r0) // 6, 0), max(c0 + 3, 0) : max(c1 - 3, 0)] = 25
                else:
                    q = c0 + (c1 - c0) // 4
                    img[max(r0 + 3, 0) : max(r1 - 3, 0), max(q, 0) : max(q + (c1 - c0) // 6, 0)] = 25


def _ground(
    bounds: np.ndarray, phase: np.ndarray, lamps: np.ndarray, cfg: CityConfig, rng: np.random.Generator
) -> MipTexture:
    t = cfg.ground_texel
    width, height = (int(np.ceil(d / t)) for d in bounds[1] - bounds[0])
    img = mosaic(height, width, rng)
    # small objects everywhere make every place unique, whatever photo lies under it
    scatter_shapes(img, int(width * height * t * t / 3.0), (int(0.3 / t) + 1, int(1.5 / t) + 2), rng)
    xs = bounds[0, 0] + (np.arange(width) + 0.5) * t
    ys = bounds[0, 1] + (np.arange(height) + 0.5) * t
    street = _street_mask(xs, phase[0], cfg)[None, :] | _street_mask(ys, phase[1], cfg)[:, None]
    asphalt = (70 + 14 * noise_field(height, width, rng, (1.0, 0.4 / t, 2.0 / t)))[..., None]  # grain and stains
    # dashed centre lines
    mid_x = np.abs((xs - phase[0]) % cfg.block - cfg.street_width / 2) < 0.08
    mid_y = np.abs((ys - phase[1]) % cfg.block - cfg.street_width / 2) < 0.08
    dash_x = ((ys - phase[1]) % 6.0) < 3.0
    dash_y = ((xs - phase[0]) % 6.0) < 3.0
    line = (mid_x[None, :] & dash_x[:, None]) | (mid_y[:, None] & dash_y[None, :])
    asphalt = np.where(line[..., None], 220.0, asphalt)
    img = np.where(street[..., None], asphalt.astype(np.uint8), img)
    _paint_cars(img, bounds, phase, cfg, rng)
    lit = img * _light_map(bounds, lamps, cfg, (height, width))
    return MipTexture(lit)


def _walls(cfg: CityConfig, rng: np.random.Generator) -> MipTexture:
    h, w = 16 * FLOOR_TEXELS, 32 * FLOOR_TEXELS
    base = mosaic(h, w, rng).astype(np.float32)
    scatter_shapes(base, h * w // 4000, (4, 24), rng)
    base *= cfg.ambient
    rows, cols = h // FLOOR_TEXELS, w // FLOOR_TEXELS
    lit = rng.random((rows, cols)) < cfg.lit_windows
    warm = np.array([255, 215, 150.0])
    glass = np.array([60, 70, 90.0]) * cfg.ambient
    for r in range(rows):
        for c in range(cols):
            colour = warm * rng.uniform(0.7, 1.0) if lit[r, c] else glass * rng.uniform(0.6, 1.4)
            y, x = r * FLOOR_TEXELS, c * FLOOR_TEXELS
            base[y + 16 : y + 46, x + 14 : x + 50] = colour
    return MipTexture(base)


def _roofs(cfg: CityConfig, rng: np.random.Generator) -> MipTexture:
    n = int(120.0 / cfg.roof_texel)  # 120 m of distinct roof texture
    roofs = mosaic(n, n, rng)
    roofs = np.clip(roofs * (1 + 0.15 * noise_field(n, n, rng, (8.0, 64.0)))[..., None], 0, 255).astype(np.uint8)
    scatter_shapes(roofs, n * n // 3000, (4, 24), rng)
    return MipTexture(roofs * cfg.ambient)


def _buildings(
    bounds: np.ndarray, phase: np.ndarray, cfg: CityConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    lot = cfg.block - cfg.street_width
    lo, hi = [], []
    xs = np.arange(phase[0] - cfg.block, bounds[1, 0], cfg.block) + cfg.street_width
    ys = np.arange(phase[1] - cfg.block, bounds[1, 1], cfg.block) + cfg.street_width
    for x in xs:
        for y in ys:
            if rng.random() >= cfg.building_density:
                continue
            size = rng.uniform(0.35, 0.9, size=2) * lot
            corner = np.array([x, y]) + 1.0 + rng.uniform(0, 1, size=2) * (lot - 2.0 - size)
            height = rng.uniform(cfg.min_height, cfg.max_height)
            lo.append([*corner, 0.0])
            hi.append([*(corner + size), height])
    return np.array(lo).reshape(-1, 3), np.array(hi).reshape(-1, 3)


def build_city(bounds: np.ndarray, cfg: CityConfig, rng: np.random.Generator) -> City:
    """A random city covering ``bounds`` ((2, 2): ``[[x0, y0], [x1, y1]]``) on the ground."""
    bounds = np.asarray(bounds, dtype=np.float64)
    phase = bounds[0] + rng.uniform(0, cfg.block, size=2)
    lamps = _lamps(bounds, phase, cfg)
    lo, hi = _buildings(bounds, phase, cfg, rng)
    kind = np.full(len(lo), BUILDING)
    if len(lamps):
        z = cfg.lamp_height
        lamp_lo = np.column_stack([lamps - 0.3, np.full(len(lamps), z)])
        lamp_hi = np.column_stack([lamps + 0.3, np.full(len(lamps), z + 0.25)])
        lo, hi = np.concatenate([lo, lamp_lo]), np.concatenate([hi, lamp_hi])
        kind = np.concatenate([kind, np.full(len(lamps), LAMP)])
    box_uv = rng.integers(0, 32, size=(len(lo), 3, 2)) * FLOOR_TEXELS
    return City(
        lo=lo,
        hi=hi,
        kind=kind,
        ground=_ground(bounds, phase, lamps, cfg, rng),
        origin=bounds[0].copy(),
        ground_texel=cfg.ground_texel,
        roof=_roofs(cfg, rng),
        roof_texel=cfg.roof_texel,
        wall=_walls(cfg, rng),
        wall_texel=cfg.wall_texel,
        box_uv=box_uv.astype(np.float64),
        box_gain=rng.uniform(0.7, 1.2, size=(len(lo), 3)).astype(np.float32),
        lamp_colour=np.array([255.0, 245.0, 215.0], np.float32),
        sky=np.array([4.0, 5.0, 12.0], np.float32) * cfg.ambient,
    )


def shade(city: City, hits: Hits, focal: float) -> np.ndarray:
    """Colour (H, W, 3) float32 (0..255) of every ray's hit; ``focal`` in pixels sets the
    texture level of detail (pixel footprint ``t / focal`` over the surface's obliquity)."""
    shape = hits.t.shape
    out = np.broadcast_to(city.sky, shape + (3,)).reshape(-1, 3).copy()
    box, axis = hits.box.ravel(), hits.axis.ravel()
    points, dirs, dist = hits.points.reshape(-1, 3), hits.dirs.reshape(-1, 3), hits.t.ravel()

    def lod(idx: np.ndarray, face_axis: int, texel: float) -> np.ndarray:
        """log2 of the pixel footprint on the surface, in texels."""
        cos = np.maximum(np.abs(dirs[idx, face_axis]), 0.05)
        return np.log2(dist[idx] / (focal * texel * np.sqrt(cos)) + 1e-12)

    idx = np.flatnonzero(box == GROUND)
    u = (points[idx, 0] - city.origin[0]) / city.ground_texel
    v = (points[idx, 1] - city.origin[1]) / city.ground_texel
    out[idx] = city.ground.sample(u, v, lod(idx, 2, city.ground_texel))

    on_box = np.flatnonzero(box >= 0)
    kind = city.kind[box[on_box]]
    out[on_box[kind == LAMP]] = city.lamp_colour
    faces = ((2, city.roof, city.roof_texel), (0, city.wall, city.wall_texel), (1, city.wall, city.wall_texel))
    for face_axis, tex, texel in faces:
        idx = on_box[(kind == BUILDING) & (axis[on_box] == face_axis)]
        if not len(idx):
            continue
        b = box[idx]
        x, y, z = points[idx, 0], points[idx, 1], points[idx, 2]
        if face_axis == 2:
            u, v = (x - city.lo[b, 0]) / texel, (y - city.lo[b, 1]) / texel
        else:
            along = y if face_axis == 0 else x
            u, v = (along - city.lo[b, 1 - face_axis]) / texel, -z / texel
        offset = city.box_uv[b, face_axis]
        out[idx] = tex.sample(u + offset[:, 0], v + offset[:, 1], lod(idx, face_axis, texel)) * city.box_gain[b]
    return out.reshape(shape + (3,))
