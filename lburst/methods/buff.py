"""BuFF: burst feature finder (Ravendran, Bryson, Dansereau, RA-L 2023).

Features with a well-defined scale *and apparent motion*.  For every candidate slope
``(u, v)`` px/frame the frames are shifted by ``t * (u, v)`` (``t = k - N // 2``) onto
the common frame and averaged ("slope image"); a SIFT difference-of-Gaussians scale
space is built for each slope image and keypoints are extrema over (x, y, scale,
slope) jointly, refined to sub-pixel, sub-scale and sub-slope, filtered for contrast
and edges as SIFT, and described by SIFT orientation and descriptor computed on the
slope image at the keypoint's slope, scale and orientation.

How it is computed: each frame gets its own Gaussian/DoG pyramid once and the DoG of
a slope image is the mean of the frames' DoGs resampled at ``p + t * s`` (identical to
shifting, averaging and then blurring: all are linear and shift-invariant; see
:mod:`lburst.methods.buff_scale`, which also explains why the resampling is cubic).
Per octave the maximum and the minimum DoG over all slopes are streamed (no slope stack
is kept); keypoints are 3x3x3 extrema of those in (x, y, scale) above SIFT's
pre-threshold.  These are exactly the 4-D extrema whose slope neighbourhood is the
whole slope range (the strictest 4-D neighbourhood: at each position and scale the
best-aligned slope wins, which suits a static scene seen by a moving camera, where a
pixel has one apparent motion); their grid slope is the arg-extremum.  Position and
scale are refined by SIFT's Taylor step on the DoG at that slope.  The slope is refined
on the local *energy* of the merged DoG around the keypoint (a single DoG value hardly
changes with slope and is noisy; see ``Buff._subslope``).

Differences from OpenCV's SIFT: the image is not doubled before the first octave (4x
the work for 81 slope images); the descriptor is SIFT's 4x4x8 histogram sampled on a
rotated grid (:mod:`lburst.methods.sift_describe`), not OpenCV's code.

Its speed: docs/results/matching.md.

Output (see :mod:`lburst.features`): ``keypoints`` in common-frame pixels, ``scales``
SIFT-style diameters ``2 * sigma``, ``scores`` the interpolated |DoG| contrast,
``orientations`` radians (OpenCV's angle convention), ``slopes`` ``(K, 2)`` (u, v)
px/frame, ``descriptors`` 128-D float32, ``image_size`` the frames' (width, height).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lburst.burst.frames import gray_unit, time_offsets
from lburst.errors import LBurstValueError
from lburst.features import Features, empty_features, image_size, select
from lburst.methods import register, sift_describe
from lburst.methods.buff_scale import OctaveStack, frame_pyramids

BORDER = 5  # pixels kept from the octave's border, as SIFT
MAX_REFINE_STEPS = 5
ENERGY_WINDOW = 1.5  # slope energy window sigma, in units of the keypoint's level sigma
SLOPE_CLIMB = 4  # hill-climbing steps on the slope grid


@dataclass(frozen=True)
class BuffConfig:
    """BuFF settings (SIFT's defaults for the scale space).

    Attributes:
        slope_min, slope_max, slope_step: the slope grid per axis in px/frame
            (inclusive range); 2-D ``(u, v)`` grid unless ``direction`` is set.
        direction: ``(dx, dy)``: search slopes only along this dominant motion direction
            (a 1-D grid of ``s * direction / |direction|``).
        sigma: blur of the first level of each octave; ``init_sigma`` the assumed blur
            of the input.
        layers: scale levels per octave with extrema (SIFT's nOctaveLayers).
        octaves: number of octaves (``None``: as many as keep the short side >= 16 px, at most 8).
        contrast_threshold: SIFT's (on [0, 1] images): reject |DoG| * layers below it.
        edge_threshold: reject principal-curvature ratios above it.
        max_features: keep the strongest (by contrast) after orientation assignment.
        min_slope_sharpness: drop keypoints whose slope is not sharply defined (see
            ``Buff._subslope``; 0 keeps all, about 0.01 drops most edge-like and coarse ones).
    """

    slope_min: float = -2.0
    slope_max: float = 2.0
    slope_step: float = 0.5
    direction: tuple[float, float] | None = None
    sigma: float = 1.6
    init_sigma: float = 0.5
    layers: int = 3
    octaves: int | None = None
    contrast_threshold: float = 0.04
    edge_threshold: float = 10.0
    max_features: int = 5000
    min_slope_sharpness: float = 0.0

    def slope_grid(self) -> tuple[np.ndarray, tuple[int, ...]]:
        """Slopes ``(S, 2)`` (u, v) px/frame and the grid's shape (``(n,)`` 1-D, ``(nv, nu)`` 2-D, u fastest)."""
        if self.slope_step <= 0 or self.slope_max < self.slope_min:
            raise LBurstValueError(f"bad slope range {self.slope_min}..{self.slope_max} step {self.slope_step}")
        values = np.arange(self.slope_min, self.slope_max + 1e-6 * self.slope_step, self.slope_step)
        if self.direction is not None:
            d = np.asarray(self.direction, np.float64)
            if d.shape != (2,) or not np.linalg.norm(d) > 0:
                raise LBurstValueError(f"direction must be a non-zero (dx, dy), got {self.direction}")
            return (values[:, None] * (d / np.linalg.norm(d))[None]).astype(np.float64), (len(values),)
        v, u = np.meshgrid(values, values, indexing="ij")
        return np.stack([u.ravel(), v.ravel()], 1), (len(values), len(values))


def _extrema(dmax: np.ndarray, dmin: np.ndarray, threshold: float, border: int) -> tuple[np.ndarray, ...]:
    """(level, y, x, sign) of 3x3x3 maxima of ``dmax`` above ``threshold`` and minima of ``dmin`` below -threshold."""
    kernel = np.ones((3, 3), np.uint8)
    found = []
    for values, sign, op in ((dmax, 1, cv2.dilate), (dmin, -1, cv2.erode)):
        spatial = np.stack([op(v, kernel) for v in values])
        if sign > 0:
            neigh = np.maximum(np.maximum(spatial[:-2], spatial[1:-1]), spatial[2:])
            keep = (values[1:-1] >= neigh) & (values[1:-1] > threshold)
        else:
            neigh = np.minimum(np.minimum(spatial[:-2], spatial[1:-1]), spatial[2:])
            keep = (values[1:-1] <= neigh) & (values[1:-1] < -threshold)
        keep[:, :border] = keep[:, -border:] = False
        keep[:, :, :border] = keep[:, :, -border:] = False
        lvl, y, x = np.nonzero(keep)
        found.append((lvl + 1, y, x, np.full(len(lvl), sign, np.int8)))
    return tuple(np.concatenate(parts) for parts in zip(*found))


class Buff:
    """The BuFF extractor: ``Buff(config)(burst) -> features`` (see the module docstring)."""

    def __init__(self, config: BuffConfig = BuffConfig(), cache_mb: int = 384) -> None:
        self.config = config
        self.slopes, self.grid_shape = config.slope_grid()
        self.cache_limit = cache_mb << 20
        self.name = "buff"

    def __call__(self, burst: np.ndarray) -> Features:
        frames = gray_unit(burst)
        cfg = self.config
        n, h, w = frames.shape
        t = time_offsets(n).astype(np.float64)
        frame_shifts = t[None, :, None] * self.slopes[:, None, :]  # (S, N, 2) px at octave 0
        max_shift = float(np.abs(frame_shifts).max(initial=0.0))
        octaves = cfg.octaves or max(1, min(8, int(np.log2(min(h, w) / 16)) + 1))
        found = []
        for octv in frame_pyramids(frames, cfg.sigma, cfg.init_sigma, cfg.layers, octaves, max_shift, self.cache_limit):
            if min(octv.shape) <= 2 * BORDER + 2:
                break
            found.append(self._detect(octv, frame_shifts / 2**octv.index))
            octv.cache.clear()
        return {**self._describe(found, n), "image_size": image_size(w, h)}

    def _detect(self, octv: OctaveStack, shifts: np.ndarray) -> dict[str, np.ndarray]:
        """Keypoints of one octave: positions/levels refined, slopes, contrast; in octave units."""
        cfg = self.config
        h, w = octv.shape
        dmax, dmin = octv.slope_extrema(shifts)
        border = BORDER + int(np.ceil(np.abs(shifts).max(initial=0.0)))
        threshold = 0.5 * cfg.contrast_threshold / cfg.layers
        lvl, y, x, sign = _extrema(dmax, dmin, threshold, min(border, min(h, w) // 2 - 1))
        del dmax, dmin
        if len(lvl) == 0:
            return {}
        # best slope of each candidate: the arg-extremum over the grid
        values = np.stack([octv.gather(sh, lvl, y, x) for sh in shifts], 1)  # (C, S)
        best = np.argmax(values * sign[:, None], axis=1)
        if len(best) > 2 * cfg.max_features:  # the global strongest are (nearly all) among each octave's
            keep = np.argsort(-np.abs(values[np.arange(len(best)), best]), kind="stable")[: 2 * cfg.max_features]
            lvl, y, x, best = lvl[keep], y[keep], x[keep], best[keep]
        return self._refine(octv, lvl, y, x, best, shifts)

    def _refine(self, octv: OctaveStack, lvl, y, x, best, shifts) -> dict[str, np.ndarray]:
        """SIFT's Taylor refinement (x, y, level) at the grid slope ``best``, contrast and edge tests, then
        the slope refinement of :meth:`_subslope`.  Returns per-keypoint arrays in octave units."""
        cfg = self.config
        h, w = octv.shape
        alive = np.ones(len(lvl), bool)
        for step in range(MAX_REFINE_STEPS + 1):
            cube = self._cube(octv, lvl, y, x, best, shifts)  # (C, 3, 3, 3) level, y, x
            grad, hess = _derivatives(cube)
            singular = ~(np.abs(np.linalg.det(hess)) > 1e-18)
            hess[singular] = np.eye(3)
            offset = -np.linalg.solve(hess, grad[..., None])[..., 0]  # (dx, dy, dlevel)
            alive &= ~singular
            done = np.all(np.abs(offset) < 0.5, axis=1)
            move = ~done & alive
            if step == MAX_REFINE_STEPS or not move.any():
                break
            x = x + np.where(move, np.rint(offset[:, 0]).astype(np.int64), 0)
            y = y + np.where(move, np.rint(offset[:, 1]).astype(np.int64), 0)
            lvl = lvl + np.where(move, np.rint(offset[:, 2]).astype(np.int64), 0)
            alive &= (
                (lvl >= 1) & (lvl <= cfg.layers) & (x >= BORDER) & (x < w - BORDER) & (y >= BORDER) & (y < h - BORDER)
            )
            x, y, lvl = np.where(alive, x, BORDER), np.where(alive, y, BORDER), np.where(alive, lvl, 1)
        alive &= done
        contrast = cube[:, 1, 1, 1] + 0.5 * np.einsum("ci,ci->c", grad, offset)
        alive &= np.abs(contrast) * cfg.layers >= cfg.contrast_threshold
        trace = hess[:, 0, 0] + hess[:, 1, 1]
        det2 = hess[:, 0, 0] * hess[:, 1, 1] - hess[:, 0, 1] ** 2
        r = cfg.edge_threshold
        alive &= (det2 > 0) & (trace**2 * r < (r + 1) ** 2 * det2)
        keep = np.nonzero(alive)[0]
        lvl, y, x, best, offset, contrast = lvl[keep], y[keep], x[keep], best[keep], offset[keep], contrast[keep]
        slopes, sharpness = self._subslope(octv, lvl, y, x, best, shifts)
        if cfg.min_slope_sharpness > 0:
            sharp = sharpness >= cfg.min_slope_sharpness
            lvl, y, x, offset, contrast = lvl[sharp], y[sharp], x[sharp], offset[sharp], contrast[sharp]
            slopes, sharpness, keep = slopes[sharp], sharpness[sharp], keep[sharp]
        return {
            "x": x + offset[:, 0],
            "y": y + offset[:, 1],
            "level": lvl,
            "sublevel": offset[:, 2],
            "contrast": np.abs(contrast),
            "slope": slopes,
            "octave": np.full(len(keep), octv.index),
            "sharpness": sharpness,
            "gauss": octv.gauss,
        }

    def _cube(self, octv, lvl, y, x, best, shifts) -> np.ndarray:
        """DoG values ``(C, 3, 3, 3)`` around each (level, y, x) at grid slope ``best`` (C,) of ``shifts`` (S, N, 2)."""
        d = np.arange(-1, 2)
        L, Y, X = np.broadcast_arrays(
            lvl[:, None, None, None] + d[None, :, None, None],
            y[:, None, None, None] + d[None, None, :, None],
            x[:, None, None, None] + d[None, None, None, :],
        )
        return octv.gather_slopes(shifts, best, L, Y, X)

    def _slope_energy(self, octv: OctaveStack, lvl, y, x, shifts: np.ndarray) -> np.ndarray:
        """Gaussian-weighted energy of the slope-merged DoG around each keypoint.

        ``shifts`` ``(C, M, N, 2)``: M candidate slopes per keypoint as per-frame shifts in
        octave pixels.  The window has sigma ``ENERGY_WINDOW`` x the level's sigma.
        Returns ``(C, M)``.
        """
        cfg = self.config
        c, m = shifts.shape[:2]
        energy = np.zeros((c, m))
        for level in np.unique(lvl):
            sel = np.nonzero(lvl == level)[0]
            sigma = ENERGY_WINDOW * cfg.sigma * 2.0 ** (level / cfg.layers)
            r = int(np.ceil(2 * sigma))
            off = np.arange(-r, r + 1, dtype=np.float32)
            weight = np.exp(-(off[None, :] ** 2 + off[:, None] ** 2) / (2 * sigma**2))
            total = np.zeros((len(sel), m, 2 * r + 1, 2 * r + 1), np.float32)
            for k in range(shifts.shape[2]):
                px = x[sel, None, None, None] + off[None, None, None, :] + shifts[sel, :, k, 0, None, None] + octv.pad
                py = y[sel, None, None, None] + off[None, None, :, None] + shifts[sel, :, k, 1, None, None] + octv.pad
                px, py = np.broadcast_arrays(px, py)
                total += remap(octv.dog_padded[k, level], px, py, cv2.INTER_CUBIC)
            energy[sel] = (total.astype(np.float64) ** 2 * weight).sum((2, 3))
        return energy

    def _subslope(self, octv, lvl, y, x, best, shifts) -> tuple[np.ndarray, np.ndarray]:
        """Refine each keypoint's slope on the local energy of the slope-merged DoG.

        The DoG value at the extremum alone varies little with the slope (a blob of
        sigma 2 px barely changes when two frames are misaligned by 1 px), so it is
        noisy; the energy of the merged DoG over a window around the keypoint averages
        that noise.  Starting at the grid slope of the 4-D extremum, hill-climb on the
        3 (1-D grid) or 3x3 (2-D grid) neighbourhood (at most ``SLOPE_CLIMB`` steps),
        then take a Newton step of a quadratic fit, clipped to half a grid step.

        Returns the slopes ``(C, 2)`` and their *sharpness*: the smallest curvature of
        the energy (eigenvalue of minus its Hessian, in grid steps) relative to the peak
        energy; 0 when the peak is on the grid's edge or not a peak in every direction
        (e.g. an edge-like structure, ambiguous along itself).
        """
        c = len(best)
        shape = self.grid_shape
        if c == 0:
            return np.zeros((0, 2)), np.zeros(0)
        coords = np.array(np.unravel_index(best, shape))  # (ndim, C); 2-D: (v index, u index)
        nd = len(shape)
        ramp = np.arange(-1, 2)
        vals = np.zeros((c, 3**nd))
        moved = np.ones(c, bool)
        for _ in range(SLOPE_CLIMB + 1):
            active = np.nonzero(moved)[0]
            clipped = [np.clip(coords[a, active][:, None] + ramp[None], 0, shape[a] - 1) for a in range(nd)]
            if nd == 1:
                nb = clipped[0]  # (A, 3)
            else:
                nb = np.ravel_multi_index((clipped[0][:, :, None], clipped[1][:, None, :]), shape).reshape(-1, 9)
            vals[active] = self._slope_energy(octv, lvl[active], y[active], x[active], shifts[nb])
            arg = vals[active].argmax(1)
            centre = nb.shape[1] // 2
            moved[:] = False
            moved[active] = arg != centre
            if not moved.any():
                break
            new = np.array(np.unravel_index(nb[np.arange(len(active)), arg], shape))
            coords[:, active] = np.where(moved[active][None], new, coords[:, active])
        interior = np.all((coords > 0) & (coords < np.array(shape)[:, None] - 1), axis=0)
        if nd == 1:
            grad = (vals[:, 2] - vals[:, 0])[:, None] / 2
            hess = (vals[:, 2] - 2 * vals[:, 1] + vals[:, 0])[:, None, None]
            unit = (self.slopes[1] - self.slopes[0])[None] if len(self.slopes) > 1 else np.zeros((1, 2))
        else:
            e = vals.reshape(c, 3, 3)
            gu, gv = (e[:, 1, 2] - e[:, 1, 0]) / 2, (e[:, 2, 1] - e[:, 0, 1]) / 2
            huu = e[:, 1, 2] - 2 * e[:, 1, 1] + e[:, 1, 0]
            hvv = e[:, 2, 1] - 2 * e[:, 1, 1] + e[:, 0, 1]
            huv = (e[:, 2, 2] - e[:, 2, 0] - e[:, 0, 2] + e[:, 0, 0]) / 4
            grad = np.stack([gu, gv], 1)
            hess = np.stack([np.stack([huu, huv], 1), np.stack([huv, hvv], 1)], 1)
            unit = np.diag([self.config.slope_step] * 2)
        curvature = np.linalg.eigvalsh(-hess).min(1)
        peak = interior & (curvature > 0) & ~moved
        safe = np.where(peak[:, None, None], hess, -np.eye(hess.shape[1])[None])
        step = np.clip(-np.linalg.solve(safe, grad[..., None])[..., 0], -0.5, 0.5) * peak[:, None]
        slopes = self.slopes[np.ravel_multi_index(coords, shape)] + step @ unit
        sharpness = np.where(peak, curvature / np.maximum(vals[:, centre], 1e-30), 0.0)
        return slopes, sharpness

    def _describe(self, found: list[dict], n: int) -> Features:
        """Orientation and SIFT descriptor of every keypoint on its slope image at its octave level."""
        cfg = self.config
        found = [f for f in found if f and len(f["x"])]
        if not found:
            feats = empty_features(128)
            feats.update(orientations=np.zeros(0, np.float32), slopes=np.zeros((0, 2), np.float32))
            return feats
        contrast = np.concatenate([f["contrast"] for f in found])
        order = np.argsort(-contrast, kind="stable")[: cfg.max_features]
        rank = np.zeros(len(contrast), bool)
        rank[order] = True
        t = time_offsets(n).astype(np.float64)
        out = {k: [] for k in ("keypoints", "scales", "scores", "orientations", "slopes", "descriptors")}
        start = 0
        for f in found:
            sel = rank[start : start + len(f["x"])]
            start += len(f["x"])
            o = int(f["octave"][0])
            for level in np.unique(f["level"][sel]):
                m = sel & (f["level"] == level)
                xs, ys, slope = f["x"][m], f["y"][m], f["slope"][m]
                sigma_oct = cfg.sigma * 2.0 ** ((level + f["sublevel"][m]) / cfg.layers)
                shifts = t[None, :, None] * slope[:, None, :] / 2**o  # (C, N, 2)
                images = f["gauss"][:, level]
                sampler = _patch_sampler(images, shifts)
                centres = np.stack([np.rint(xs), np.rint(ys)], 1)
                idx, angle = sift_describe.orientations(sampler, centres, sigma_oct)
                pts = np.stack([xs, ys], 1)[idx]
                desc = sift_describe.descriptors(_patch_sampler(images, shifts[idx]), pts, sigma_oct[idx], angle)
                out["keypoints"].append(pts * 2**o)
                out["scales"].append(2 * sigma_oct[idx] * 2**o)
                out["scores"].append(f["contrast"][m][idx])
                out["orientations"].append(angle)
                out["slopes"].append(slope[idx])
                out["descriptors"].append(desc)
        feats = {k: np.concatenate(v).astype(np.float32) for k, v in out.items()}
        keep = np.argsort(-feats["scores"], kind="stable")[: cfg.max_features]
        return select(feats, keep)


def _patch_sampler(images: np.ndarray, shifts: np.ndarray):
    """Sampler for :mod:`lburst.methods.sift_describe`: mean over frames of ``images`` ``(N, h, w)``
    sampled (bilinear) at ``grid + shifts[c, k]`` (``shifts`` (C, N, 2) octave px)."""

    def sample(grid: np.ndarray) -> np.ndarray:
        c, p, q, _ = grid.shape
        total = np.zeros((c, p, q), np.float32)
        for k in range(len(images)):
            g = grid + shifts[:, k, None, None, :].astype(np.float32)
            total += remap(images[k], g[..., 0], g[..., 1])
        return total / len(images)

    return sample


def remap(image: np.ndarray, x: np.ndarray, y: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
    """``image`` (h, w) float32 sampled at positions ``x``, ``y`` (any equal shapes ending in Q; bilinear
    unless ``interpolation`` says otherwise), replicating the border (OpenCV ``remap``, in chunks of
    rows below its 32767 limit)."""
    shape = x.shape
    q = shape[-1]
    xf = np.ascontiguousarray(x, np.float32).reshape(-1, q)
    yf = np.ascontiguousarray(y, np.float32).reshape(-1, q)
    rows = 32000
    out = np.empty(xf.shape, np.float32)
    for i in range(0, len(xf), rows):
        out[i : i + rows] = cv2.remap(
            image, xf[i : i + rows], yf[i : i + rows], interpolation, borderMode=cv2.BORDER_REPLICATE
        )
    return out.reshape(shape)


def _derivatives(cube: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient ``(C, 3)`` and Hessian ``(C, 3, 3)`` in (x, y, level) by central differences of ``cube`` (C, 3, 3, 3)."""
    c = cube[:, 1, 1, 1]
    dx = (cube[:, 1, 1, 2] - cube[:, 1, 1, 0]) / 2
    dy = (cube[:, 1, 2, 1] - cube[:, 1, 0, 1]) / 2
    ds = (cube[:, 2, 1, 1] - cube[:, 0, 1, 1]) / 2
    dxx = cube[:, 1, 1, 2] + cube[:, 1, 1, 0] - 2 * c
    dyy = cube[:, 1, 2, 1] + cube[:, 1, 0, 1] - 2 * c
    dss = cube[:, 2, 1, 1] + cube[:, 0, 1, 1] - 2 * c
    dxy = (cube[:, 1, 2, 2] - cube[:, 1, 2, 0] - cube[:, 1, 0, 2] + cube[:, 1, 0, 0]) / 4
    dxs = (cube[:, 2, 1, 2] - cube[:, 2, 1, 0] - cube[:, 0, 1, 2] + cube[:, 0, 1, 0]) / 4
    dys = (cube[:, 2, 2, 1] - cube[:, 2, 0, 1] - cube[:, 0, 2, 1] + cube[:, 0, 0, 1]) / 4
    grad = np.stack([dx, dy, ds], 1).astype(np.float64)
    hess = np.stack([np.stack([dxx, dxy, dxs], 1), np.stack([dxy, dyy, dys], 1), np.stack([dxs, dys, dss], 1)], 1)
    return grad, hess.astype(np.float64)


@dataclass(frozen=True)
class BuffOptions(BuffConfig):
    """The :class:`BuffConfig` fields, plus ``slope_range`` (``min:max``, setting both slope
    bounds at once) and ``cache_mb`` (memory for the per-frame pyramids)."""

    slope_range: tuple[float, float] | None = None
    cache_mb: int = 384

    def config(self) -> BuffConfig:
        values = {name: getattr(self, name) for name in BuffConfig.__dataclass_fields__}
        if self.slope_range is not None:
            values["slope_min"], values["slope_max"] = self.slope_range
        return BuffConfig(**values)


@register("buff", BuffOptions)
def buff(arg: None, options: BuffOptions) -> Buff:
    """BuFF: keypoints with a scale and an apparent motion, found across the burst."""
    return Buff(options.config(), cache_mb=options.cache_mb)
