"""``lburst bench homography``: the paper's noisy-burst matching experiment on any sequences.

Protocol (reproducible by anyone):

1. Sequences in Oxford or HPatches layout (:mod:`lburst.bench.sequences`), optionally
   resized to ``--max-side`` with the homographies composed accordingly.
2. Every image I becomes a 5-frame burst whose middle frame is I: frame k is I
   translated by k*(dx, dy), (dx, dy) uniform in [-3, 3]^2, bilinear with reflected
   borders, then Gaussian noise of std sigma (0..255) on every frame and channel,
   rounded and clipped (:func:`lburst.simulate.simulate_burst`); motion and noise come
   from one generator seeded by ``stable_seed(sequence, image index, noise label)``.
   A ``--noise SPEC`` level uses that :mod:`lburst.noise` model instead.  With
   ``--burst-rotation``, ``--burst-zoom`` or ``--burst-flow`` the in-burst motion also
   rotates, zooms and flows non-uniformly (:class:`lburst.burst.motion.BurstMotion`, each
   drawn uniformly up to the given per-frame maximum); such levels are labelled and
   seeded with the motion's name too.
3. Methods: any :func:`lburst.methods.create` spec, each with an input mode
   (:class:`InputMode`, :class:`BenchMethod`): the noisy burst (``burst``), the clean image
   (``gold``: ``gold+X``, or ``gold:CKPT`` for the single-image network ``r2d2:CKPT``), or
   the frames aligned with the true motion and averaged (``oracle-merge``:
   ``oracle-merge+X``); the command line's ``--input MODE`` sets it for every plain spec.  Learned methods keep the top 5000 keypoints.
4. Mutual nearest neighbours; metrics of :mod:`lburst.bench.metrics` for the pairs
   (1, K), K = 2..6; averaged over the 5 pairs of a sequence, then over sequences.
   A second table keeps only pairs rotated by 25 degrees or less (pooled).
5. ``--rotation DEG`` turns images 2-6 of every sequence in-plane by DEG degrees about
   their centre, on a canvas that holds the whole turned image (quarter turns exact,
   others bilinear with black corners), and composes the homographies with the turn:
   the views of neighbouring survey lines (180) or of crossing ones (90).
6. ``--color-jitter B C S H`` changes the colours of images 2-6 of every sequence, each by one
   random brightness, contrast, saturation and hue change up to those amounts
   (:func:`lburst.bench.sequences.recolor_sequence`, seeded): photos of one place from
   different cameras or times of day.

Features are kept in the features store (:mod:`lburst.store`), one file per (method,
noise level, sequence, image) under ``OUT/cache``, keyed as ``lburst extract`` keys them:
the method spec with its weights' SHA-1 and options, and the source (the sequence folder
and image number) with the SHA-1 of the burst's content (:func:`burst_sha1`).  So
retrained weights at the same path, or a sequence image replaced under the same name, are
run again; each file also keeps the seconds its extraction took.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from lburst import matching, store
from lburst.bench.metrics import THRESHOLDS, match_errors, mma, repeatability, rotation_deg
from lburst.bench.sequences import Sequence, list_sequences, read_sequence, recolor_sequence, rotate_sequence
from lburst.burst.io import atomic_path
from lburst.burst.motion import BurstMotion, sample_motion
from lburst.errors import LBurstOSError, LBurstValueError
from lburst.features import Features
from lburst.methods import Method, method_slug
from lburst.methods.merge import merge_burst
from lburst.noise import GaussianNoise, NoiseModel, noise_from_spec
from lburst.photometric import check_jitter
from lburst.simulate import random_motion, simulate_burst, stable_seed
from lburst.strenum import StrEnum
from lburst.viz import new_figure

MAX_ROTATION_DEG = 25.0


@dataclass(frozen=True)
class MotionRange:
    """Largest in-burst motion per frame beyond the shift (0: a pure translation)."""

    rotation_deg: float = 0.0
    zoom: float = 0.0
    flow_px: float = 0.0

    @property
    def label(self) -> str:
        if not (self.rotation_deg or self.zoom or self.flow_px):
            return ""
        return f"rot{self.rotation_deg:g}-zoom{self.zoom:g}-flow{self.flow_px:g}"


@dataclass(frozen=True)
class NoiseLevel:
    label: str
    model: NoiseModel | None
    motion: MotionRange = MotionRange()


def noise_levels(sigmas: list[float], specs: list[str], motion: MotionRange = MotionRange()) -> list[NoiseLevel]:
    suffix = f"+{motion.label}" if motion.label else ""
    levels = [NoiseLevel(f"sigma{s:g}{suffix}", GaussianNoise(float(s)) if s > 0 else None, motion) for s in sigmas]
    return levels + [NoiseLevel(spec + suffix, noise_from_spec(spec), motion) for spec in specs]


def protocol_burst(
    image: np.ndarray, sequence: str, index: int, level: NoiseLevel, frames: int = 5, max_shift: float = 3.0
) -> tuple[np.ndarray, BurstMotion]:
    """The benchmark's burst of ``image`` and its in-burst motion (see the module docstring)."""
    rng = np.random.default_rng(stable_seed(sequence, index, level.label))
    m = level.motion
    if m.label:
        motion = sample_motion(rng, max_shift, m.rotation_deg, m.zoom, m.flow_px)
    else:
        motion = BurstMotion(random_motion(rng, max_shift))
    return simulate_burst(image, frames, motion, level.model, rng), motion


def oracle_merge(burst: np.ndarray, motion: BurstMotion) -> np.ndarray:
    """The burst's frames resampled onto the common frame with the true motion and
    averaged where they cover it (float32 on the burst's scale)."""
    n, h, w = burst.shape[:3]
    total = np.zeros((h, w, 3), np.float32)
    count = np.zeros((h, w, 1), np.float32)
    for i, k in enumerate(range(-(n // 2), n // 2 + 1)):
        p = motion.frame_points(k, (w, h))
        total += cv2.remap(
            burst[i].astype(np.float32), p[..., 0], p[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
        count += ((p[..., 0] >= 0) & (p[..., 0] <= w - 1) & (p[..., 1] >= 0) & (p[..., 1] <= h - 1))[..., None]
    return total / np.maximum(count, 1)


class InputMode(StrEnum):
    """What a benchmarked method sees of a protocol burst."""

    BURST = "burst"  #: the noisy burst
    GOLD = "gold"  #: the clean image alone (an upper bound for a single-image network)
    ORACLE_MERGE = "oracle-merge"  #: the burst's frames aligned with the true motion and averaged


#: how a mode is written before a method spec in ``--methods`` (and names the method's cache)
MODE_PREFIX = {InputMode.BURST: "", InputMode.GOLD: "gold+", InputMode.ORACLE_MERGE: "oracle-merge+"}
#: ``gold:CKPT``, the published spelling of ``gold+r2d2:CKPT`` (the single-image network of CKPT)
GOLD_CHECKPOINT = "gold:"


@dataclass(frozen=True)
class BenchMethod:
    """A method of the benchmark: a :class:`lburst.methods.Method` (or its spec) and its input mode."""

    method: Method
    mode: InputMode = InputMode.BURST

    def __post_init__(self) -> None:
        object.__setattr__(self, "method", Method.of(self.method))

    @classmethod
    def parse(cls, text: str, mode: InputMode | str = InputMode.BURST) -> BenchMethod:
        """``MODE+SPEC`` (``gold+sift``, ``oracle-merge+r2d2:W.pt``), ``gold:CKPT`` (``gold+r2d2:CKPT``),
        or a plain ``SPEC`` in ``mode`` (the command line's ``--input``)."""
        if text.startswith(GOLD_CHECKPOINT):
            return cls(Method.parse("r2d2:" + text[len(GOLD_CHECKPOINT) :]), InputMode.GOLD)
        for prefixed, prefix in MODE_PREFIX.items():
            if prefix and text.startswith(prefix):
                return cls(Method.parse(text[len(prefix) :]), prefixed)
        try:
            plain = InputMode(mode)
        except ValueError:
            modes = ", ".join(m.value for m in InputMode)
            raise LBurstValueError(f"input mode {mode!r} is not one of {modes}") from None
        return cls(Method.parse(text), plain)

    @classmethod
    def of(cls, method: str | Method | BenchMethod) -> BenchMethod:
        """``method`` itself, a :class:`Method` on the noisy burst, or the text of a method (:meth:`parse`)."""
        if isinstance(method, BenchMethod):
            return method
        return cls(method) if isinstance(method, Method) else cls.parse(method)

    @property
    def gold_checkpoint(self) -> bool:
        """The single-image network of a checkpoint on the clean image: written ``gold:CKPT``."""
        return self.mode is InputMode.GOLD and self.method.name == "r2d2" and self.method.arg is not None

    @property
    def name(self) -> str:
        """The method's name in tables: as parsed back by :meth:`parse` (``gold:CKPT`` as published)."""
        if self.gold_checkpoint:
            return GOLD_CHECKPOINT + str(self.method).removeprefix("r2d2:")
        return MODE_PREFIX[self.mode] + str(self.method)

    @property
    def key_prefix(self) -> str:
        """What the store's method spec is prefixed with (as the cache has always had it)."""
        return GOLD_CHECKPOINT if self.gold_checkpoint else MODE_PREFIX[self.mode]


class MethodRunner:
    """Features of one image under the protocol for one benchmark method."""

    def __init__(self, method: BenchMethod | Method | str, top_k: int) -> None:
        self.method_of = BenchMethod.of(method)
        self.spec, self.mode = self.method_of.name, self.method_of.mode
        inner = self.method_of.method
        options = {"top_k": top_k} if inner.accepts("top_k") else {}
        self.extractor = inner.create(**options)
        method = store.method_key(inner, **options)  # the weights' SHA-1 and the options
        self.method = {**method, "spec": self.method_of.key_prefix + method["spec"]}
        self.key = self.method["spec"]  # names the feature cache's folder

    def __call__(self, image: np.ndarray, burst: np.ndarray, motion: BurstMotion) -> Features:
        if self.mode is InputMode.GOLD:
            return self.extractor(image[None])
        if self.mode is InputMode.ORACLE_MERGE:
            if motion.is_translation:
                k = np.arange(len(burst)) - len(burst) // 2
                merged = merge_burst(burst, shifts=k[:, None] * np.asarray(motion.shift)[None])
            else:
                merged = oracle_merge(burst, motion)
            return self.extractor(np.clip(np.round(merged), 0, 255).astype(np.uint8)[None])
        return self.extractor(burst)


def burst_sha1(image: np.ndarray, burst: np.ndarray, motion: BurstMotion) -> str:
    """SHA-1 of what a method sees of one protocol burst: the clean image (``gold:``), the
    noisy burst and its true motion (``oracle-merge+``), with their shapes and dtypes."""
    digest = hashlib.sha1()
    for array in (image, burst):
        digest.update(f"{array.shape}{array.dtype};".encode())
        digest.update(np.ascontiguousarray(array).tobytes())
    digest.update(repr(motion).encode())
    return digest.hexdigest()


def stored_features(
    runner: MethodRunner, path: Path, source: Path, image: np.ndarray, burst: np.ndarray, motion: BurstMotion
) -> tuple[Features, float]:
    """The runner's features of one burst and the seconds they took: from the store at ``path``
    when it holds them under the same key, else computed and stored.  Either way they are
    returned as stored, so a rerun gives the same numbers."""
    key = store.key(runner.method, source, burst_sha1(image, burst, motion))
    found = store.load(path, key)
    if found is None:
        start = time.perf_counter()
        feats = runner(image, burst, motion)
        seconds = time.perf_counter() - start
        store.save(path, feats, (image.shape[1], image.shape[0]), key, seconds=seconds)
        found = store.load(path, key)
        if found is None:
            raise LBurstOSError(f"{path}: features just written cannot be read back")
    return found[0], float(found[2]["seconds"])


def pair_metrics(seq: Sequence, feats: list[Features], k: int, matcher=None) -> dict:
    """Metrics of pair (1, k + 2), matched by ``matcher`` (:mod:`lburst.matching`; default mutual nearest neighbours)."""
    h = seq.homographies[k]
    a, b = feats[0], feats[k + 1]
    matches = (matcher or matching.create())(a, b)
    errors = match_errors(h, a["keypoints"], b["keypoints"], matches)
    n_kp = (len(a["keypoints"]) + len(b["keypoints"])) / 2
    return {
        "mma": mma(errors).tolist(),
        "rep3": repeatability(h, a["keypoints"], b["keypoints"], seq.images[0].shape, seq.images[k + 1].shape, 3.0),
        "matching_score": float((errors <= 3).sum() / n_kp) if n_kp else 0.0,
        "keypoints": n_kp,
        "matches": int(len(matches)),
        "rotation_deg": rotation_deg(h, seq.images[0].shape),
    }


def _mean(rows: list[dict]) -> dict:
    if not rows:
        return {}
    out = {key: float(np.mean([r[key] for r in rows])) for key in ("rep3", "matching_score", "keypoints", "matches")}
    out["mma"] = np.mean([r["mma"] for r in rows], axis=0).tolist()
    if "seconds" in rows[0]:
        out["seconds"] = float(np.mean([r["seconds"] for r in rows]))
    return out


def summarize(per_pair: dict[str, list[dict]], seconds: dict[str, float], kinds: dict[str, str]) -> dict:
    """Means: per sequence, over sequences (``all``), per kind, and pooled pairs rotated <= 25 degrees."""
    per_seq = {s: {**_mean(rows), "seconds": seconds[s]} for s, rows in per_pair.items()}
    out = {"sequences": per_seq, "all": _mean(list(per_seq.values()))}
    for kind in sorted(set(kinds.values()) - {"other"}):
        out[kind] = _mean([per_seq[s] for s in per_seq if kinds[s] == kind])
    small = [r for rows in per_pair.values() for r in rows if r["rotation_deg"] <= MAX_ROTATION_DEG]
    out["rotation_le_25"] = {**_mean(small), "pairs": len(small)}
    return out


def run_homography_benchmark(
    data: str | Path,
    methods: list[str | Method | BenchMethod],
    sigmas: list[float],
    out: str | Path,
    noise_specs: list[str] = (),
    max_side: int | None = None,
    top_k: int = 5000,
    progress: bool = True,
    motion: MotionRange = MotionRange(),
    matcher: str = "mnn",
    every: int = 1,
    rotation: float = 0.0,
    color_jitter: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
) -> dict:
    """Run the protocol, matching with the ``matcher`` spec; write ``results.json``, ``results.md`` and ``mma.png`` in ``out``.
    ``every`` > 1 keeps every ``every``-th sequence in name order (the first, the ``every + 1``-th, ...);
    ``rotation`` turns images 2-6 of every sequence in-plane by that many degrees
    (:func:`lburst.bench.sequences.rotate_sequence`); ``color_jitter`` changes their colours
    (:func:`lburst.bench.sequences.recolor_sequence`)."""
    out = Path(out)
    match = matching.create(matcher)
    color_jitter = check_jitter(color_jitter)
    if not isinstance(every, int) or every < 1:
        raise LBurstValueError(f"every must be an integer >= 1, got {every!r}")
    folders = list_sequences(data)[::every]
    levels = noise_levels(list(sigmas), list(noise_specs), motion)
    runners = {runner.spec: runner for runner in (MethodRunner(m, top_k) for m in methods)}
    results: dict = {
        "protocol": {
            "data": str(data),
            "sigmas": list(sigmas),
            "noise_specs": list(noise_specs),
            "max_side": max_side,
            "every": every,
            "top_k": top_k,
            "thresholds": list(THRESHOLDS),
            "burst_motion": asdict(motion),
            "matcher": matcher,
            "rotation_deg": float(rotation),
            "color_jitter": list(color_jitter),
        },
        "methods": {},
    }
    bar = tqdm(total=len(levels) * len(folders) * len(methods) * 6, desc="homography bench", disable=not progress)
    sequences = {
        f.name: rotate_sequence(recolor_sequence(read_sequence(f, max_side), color_jitter), rotation) for f in folders
    }
    paths = {f.name: f for f in folders}
    kinds = {name: seq.kind for name, seq in sequences.items()}
    for spec, runner in runners.items():
        results["methods"][spec] = {}
        for level in levels:
            per_pair, seconds = {}, {}
            for name, seq in sequences.items():
                feats, times = [], []
                for i, image in enumerate(seq.images):
                    burst, motion = protocol_burst(image, name, i, level)
                    cache = out / "cache" / method_slug(runner.key) / level.label / name / f"{i + 1}.npz"
                    f, t = stored_features(runner, cache, paths[name] / str(i + 1), image, burst, motion)
                    feats.append(f)
                    times.append(t)
                    bar.update(1)
                per_pair[name] = [pair_metrics(seq, feats, k, match) for k in range(5)]
                seconds[name] = float(np.mean(times))
            results["methods"][spec][level.label] = {"summary": summarize(per_pair, seconds, kinds), "pairs": per_pair}
    bar.close()
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "results.json") as tmp:
        tmp.write_text(json.dumps(results, indent=1))
    with atomic_path(out / "results.md") as tmp:
        tmp.write_text(markdown(results))
    plot_mma(results, out / "mma.png")
    return results


def _row(spec: str, s: dict) -> str:
    if not s:
        return f"| {spec} | - | - | - | - | - | - | - | - | - |"
    m = s["mma"]
    secs = f"{s['seconds']:.2f}" if "seconds" in s else "-"
    return (
        f"| {spec} | {m[0]:.3f} | {m[2]:.3f} | {m[4]:.3f} | {m[9]:.3f} | {s['rep3']:.3f} | "
        f"{s['matching_score']:.3f} | {s['keypoints']:.0f} | {s['matches']:.0f} | {secs} |"
    )


def markdown(results: dict) -> str:
    """Tables per noise level: all pairs, split by kind, and pairs rotated <= 25 degrees."""
    head = (
        "| method | MMA@1 | MMA@3 | MMA@5 | MMA@10 | rep@3 | match. score | #kpts | #matches | s/image |\n"
        "|---|---|---|---|---|---|---|---|---|---|"
    )
    methods = results["methods"]
    levels = list(next(iter(methods.values())).keys()) if methods else []
    lines = []
    turn = results["protocol"].get("rotation_deg", 0.0)
    if turn:
        lines += [f"Images 2-6 turned by {turn:g} degrees.", ""]
    jitter = results["protocol"].get("color_jitter") or [0.0] * 4
    if any(jitter):
        lines += [
            "Images 2-6 recoloured (brightness, contrast, saturation, hue up to "
            + ", ".join(f"{v:g}" for v in jitter)
            + ").",
            "",
        ]
    for level in levels:
        first = methods[next(iter(methods))][level]["summary"]
        for part, title in (
            [("all", "all pairs, mean over sequences")]
            + [(k, f"{k} sequences") for k in ("viewpoint", "illumination") if k in first]
            + [
                (
                    "rotation_le_25",
                    f"pairs rotated <= {MAX_ROTATION_DEG:g} deg (pooled, {first['rotation_le_25'].get('pairs', 0)} pairs)",
                )
            ]
        ):
            if not first[part].get("mma"):
                continue  # no such pairs (e.g. no pair rotated <= 25 degrees when images 2-6 are turned)
            lines += [f"### {level}: {title}", "", head]
            lines += [_row(spec, methods[spec][level]["summary"][part]) for spec in methods]
            lines.append("")
    return "\n".join(lines)


def plot_mma(results: dict, path: Path) -> None:
    """MMA against threshold, one panel per noise level, one line per method."""
    methods = results["methods"]
    levels = list(next(iter(methods.values())).keys())
    fig = new_figure((4.5 * len(levels), 4))
    axes = fig.subplots(1, len(levels), squeeze=False)
    for ax, level in zip(axes[0], levels):
        for spec in methods:
            ax.plot(THRESHOLDS, methods[spec][level]["summary"]["all"]["mma"], marker="o", ms=3, label=spec)
        ax.set_title(level)
        ax.set_xlabel("threshold (px)")
        ax.set_ylim(0, 1)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("MMA")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
