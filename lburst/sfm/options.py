"""How to reconstruct: :class:`ReconstructOptions`, its enums (:class:`Pairs`, :class:`Camera`,
:class:`Mapper`) and the measured defaults of a scene and of a recording (docs/defaults.md,
docs/recordings.md)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from lburst.burst.sources import RecordingOptions
from lburst.cluster.spec import ClusterSpec, parse_cluster
from lburst.errors import LBurstValueError
from lburst.numbers import check_integer, check_real
from lburst.sfm.colmap import DEFAULT_THREADS
from lburst.sfm.positions import DEFAULT_STD_M, check_std
from lburst.strenum import StrEnum

AUTO_EXHAUSTIVE_MAX = 20  # pairs='auto' for a scene: exhaustive up to this many images, else sequential
SCENE_OVERLAP = 10  # sequential pairs of a scene: neighbours on each side
# A recording (keyframes in time order), pairs='auto': sequential pairs with this overlap,
# RECORDING_RETRIEVAL retrieval candidates per keyframe, the loop test (ColmapOptions.near)
# for every pair more than RECORDING_NEAR apart, and registration with at least
# RECORDING_ABS_POSE_INLIERS 2D-3D inliers; docs/recordings.md has the measurements.
RECORDING_OVERLAP = 2
RECORDING_NEAR = 2
RECORDING_RETRIEVAL = 5
LOOP_FRACTION = 0.4
RECORDING_ABS_POSE_INLIERS = 10
# mapper='auto': the global mapper from this many images on (None: never).  On the simulated loops of
# 100, 300 and 1000 keyframes it mapped 14.5-15 % of the path off, against 0.76, 3.19 and 1.78 % for
# the incremental mapper (docs/large_surveys.md), so auto does not pick it at any size measured
GLOBAL_MAPPER_FROM: int | None = None
# pairs='positions' (lburst.sfm.pairs.position_pairs): each image with its POSITION_NEIGHBOURS nearest images by
# position within POSITION_RADIUS_M metres; pairs='auto' picks it for a scene of more than AUTO_EXHAUSTIVE_MAX
# images whose positions are known (docs/large_surveys.md has the measurements)
POSITION_NEIGHBOURS = 10
POSITION_RADIUS_M = 100.0


class Pairs(StrEnum):
    """Which image pairs to match (:func:`lburst.sfm.pairs.pair_plan`)."""

    AUTO = "auto"  # a scene: exhaustive up to AUTO_EXHAUSTIVE_MAX images, else by positions or sequential
    EXHAUSTIVE = "exhaustive"
    SEQUENTIAL = "sequential"
    POSITIONS = "positions"  # the nearest images by position (lburst.sfm.pairs.position_pairs)


class Camera(StrEnum):
    """Where the camera prior comes from (:mod:`lburst.sfm.cameras`)."""

    AUTO = "auto"  # the scene's calibration, held fixed; else EXIF; else COLMAP's default
    DEFAULT = "default"  # COLMAP's default prior
    REFERENCE = "reference"  # the scene's reference.json cameras
    REFERENCE_FOCAL = "reference-focal"  # COLMAP's default camera at the reference.json cameras' focal length


class Mapper(StrEnum):
    """COLMAP's mapper (:func:`lburst.sfm.pairs.pair_plan` resolves ``auto`` by the image count)."""

    AUTO = "auto"  # the mapper measured best at the image count: incremental up to 1000 (docs/large_surveys.md)
    INCREMENTAL = "incremental"
    GLOBAL = "global"


def _enum(kind: type[StrEnum], value: str, what: str) -> StrEnum:
    try:
        return kind(value)
    except ValueError:
        expected = ", ".join(repr(str(m)) for m in kind)
        raise LBurstValueError(f"unknown {what} {value!r}: expected {expected}") from None


@dataclass
class ReconstructOptions:
    """How to reconstruct (:mod:`lburst.sfm.reconstruct`'s docstring).

    Attributes:
        pairs: :class:`Pairs` (or its value): ``'exhaustive'``, ``'sequential'`` (neighbours
            up to ``overlap`` apart), ``'positions'`` (each image with its ``neighbours`` nearest
            images by position within ``radius``: :func:`lburst.sfm.pairs.position_pairs`) or
            ``'auto'`` (a scene: exhaustive up to 20 images, else by positions when they are
            known, else sequential; a recording: always sequential, :func:`lburst.sfm.pairs.pair_plan`).
        neighbours, radius: ``pairs='positions'``: how many nearest images (``None``: 10) within
            how many metres (``None``: 100).
        overlap: sequential pairs' reach; ``None``: 10 for a scene, 2 for a recording.
        fallback_exhaustive: rerun with every pair when sequential pairs leave images out.
        camera (:class:`Camera`), camera_model, single_camera, fix_intrinsics: cameras
            (:mod:`lburst.sfm.cameras`).
        mapper: :class:`Mapper`, ``'incremental'``, ``'global'`` or ``'auto'`` (incremental
            from ``GLOBAL_MAPPER_FROM`` images if set, else incremental: docs/large_surveys.md).
        num_threads, seed: for COLMAP (repeatable for one thread count).
        progress: tqdm bars, and a line on stderr per stage of matching and COLMAP with its seconds.
        extra: further :class:`lburst.sfm.colmap.ColmapOptions` fields, e.g. ``max_num_trials``.
        retrieval: with sequential pairs, also each image's this many most similar images
            farther apart (loop-closure candidates, :mod:`lburst.sfm.retrieval`); ``None``:
            5 for a recording, 0 for a scene.
        near: pairs more than this many images apart must also pass the loop test after
            COLMAP's verification (:func:`lburst.sfm.colmap.loop_test`); ``None``: 2 (at
            most the overlap) for a recording, 0 (no test) for a scene.
        loop_fraction: the loop test's fraction of the adjacent pairs' median inlier count.
        abs_pose_inliers: fewest 2D-3D inliers to register an image (incremental mapper);
            ``None``: 10 for a recording (its camera is one, usually calibrated, and the
            keyframes of a dark recording have few tracks), COLMAP's 30 for a scene.
        mapper_threads: threads of the mapper; ``None``: 1 for a recording (the only
            repeatable choice, :class:`lburst.sfm.colmap.ColmapOptions`), ``num_threads``
            for a scene.
        recording: :class:`lburst.burst.sources.RecordingOptions` for a scene that is a
            recording (video or frame folder); ``None``: the defaults.
        matcher: matcher spec (:mod:`lburst.matching`): ``'mnn'`` (mutual nearest
            neighbours), ``'ratio'``, ``'ratio,ratio=0.9'``, ...
        features: a folder that ``lburst extract --out`` or ``lburst reconstruct --out`` wrote:
            a burst's features stored there under the same key (:func:`lburst.store.key`: same
            method and burst) are used, not computed again, once checked
            (:func:`lburst.sfm.feature_stage.load_checked`); ``None``: the output folder.
        matches: a finished run's output folder: its matches of the pairs whose two images
            have the same features there (the same store key) are used if it matched them
            with the same matcher, not matched again (:func:`lburst.sfm.match.match_or_reuse`);
            ``None``: every pair is matched.
        cluster: run the features and matching stages on this cluster (:mod:`lburst.cluster`):
            a :class:`lburst.cluster.spec.ClusterSpec` or its text (``'local:4'``,
            ``'tcp://HOST:PORT'``); ``None``: in this process.
        positions: a positions file (``NAME X Y Z`` per image, :mod:`lburst.sfm.positions`):
            the incremental mapper holds each camera near its prior, ``position_std`` metres
            on each coordinate; ``None``: the positions the input carries, if any.
        input_positions: without ``positions``, take the positions the input carries as
            priors (the EXIF GPS of its frames, a DJI ``.SRT``, a bag's ``NavSatFix``:
            :mod:`lburst.geo`); ``False``: no priors (vision alone).
    """

    pairs: Pairs = Pairs.AUTO
    overlap: int | None = None
    neighbours: int | None = None
    radius: float | None = None
    fallback_exhaustive: bool = False
    camera: Camera = Camera.AUTO
    camera_model: str = "SIMPLE_RADIAL"
    single_camera: bool | None = None
    fix_intrinsics: bool = False
    mapper: Mapper = Mapper.INCREMENTAL
    num_threads: int = DEFAULT_THREADS
    seed: int = 0
    progress: bool = True
    extra: dict[str, int | float | bool | str] = field(default_factory=dict)
    retrieval: int | None = None
    near: int | None = None
    loop_fraction: float = LOOP_FRACTION
    abs_pose_inliers: int | None = None
    mapper_threads: int | None = None
    recording: RecordingOptions | None = None
    matcher: str = "mnn"
    features: str | Path | None = None
    matches: str | Path | None = None
    cluster: ClusterSpec | str | None = None
    positions: str | Path | None = None
    position_std: float = DEFAULT_STD_M
    input_positions: bool = True

    def __post_init__(self) -> None:
        self.position_std = check_std(self.position_std)
        self.pairs = _enum(Pairs, self.pairs, "pairing")
        if self.neighbours is not None:
            self.neighbours = check_integer(self.neighbours, "--pair-neighbours", 1)
        if self.radius is not None:
            self.radius = check_real(self.radius, "--pair-radius (m)", 0, low_open=True)
        self.camera = _enum(Camera, self.camera, "camera option")
        self.mapper = _enum(Mapper, self.mapper, "mapper")
        if self.positions is not None and self.mapper == Mapper.GLOBAL:
            raise LBurstValueError("--positions needs the incremental mapper: COLMAP's global mapper takes no priors")
        if isinstance(self.cluster, str):
            self.cluster = parse_cluster(self.cluster)
