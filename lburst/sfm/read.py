"""The first stages of a reconstruction (:mod:`lburst.sfm.reconstruct`): the input opened once
and checked before any feature is computed (:func:`open_checked`), and its features read
(:func:`read_features`), with the position priors and the views they show turned
(:mod:`lburst.sfm.turns`): a scene's before its features, a recording's once its keyframes are read."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from lburst.burst.io import check_output_outside
from lburst.cluster.runner import Runner
from lburst.features import Features
from lburst.methods import Method
from lburst.sfm.cameras import CameraPlan, camera_plan
from lburst.sfm.feature_stage import utf8
from lburst.sfm.inputs import InputSource, open_input
from lburst.sfm.match import report_stage
from lburst.sfm.options import Pairs, ReconstructOptions
from lburst.sfm.pairs import make_pairs, pair_plan
from lburst.sfm.positions import Priors, file_priors, parse_positions
from lburst.sfm.result import ReconstructionError, ReconstructionResult, Status
from lburst.sfm.scene import Scene, SceneError
from lburst.sfm.turns import TURN_ROTATIONS, describe_turns, find_turns, switch_on


@dataclass
class Opened:
    """The input, opened once and checked, and what is known before its features: the method
    (with the source's keypoints and, where positions show turned views, rotation sets), the
    options with the source's camera default, the output folder, and a scene's position priors."""

    source: InputSource
    method: Method
    opts: ReconstructOptions
    out: Path
    known_scene: Scene | None = None
    priors: Priors | None = None
    turns: dict | None = None


@dataclass
class Read:
    """The images read and their features, the cameras, the error that stopped the source early,
    and the method, position priors and turns they were read with."""

    scene: Scene
    features: list[Features]
    cams: CameraPlan
    error: str | None
    method: Method
    priors: Priors | None
    turns: dict | None


def open_checked(scene_dir, method: Method, out_dir, opts: ReconstructOptions, extractor) -> Opened:
    """The input opened (the one question about its kind) and checked before any feature is
    computed: a positions file that is bad or names no image, ``--pairs positions`` without
    positions, an output inside the input or not valid UTF-8; a scene's priors and turns."""
    source = open_input(scene_dir, opts.recording)
    if extractor is None:  # a given extractor keeps its own top_k
        method = method.with_default("top_k", source.keypoints)
    if opts.positions is not None:
        parse_positions(opts.positions)
        try:
            known = source.known_names()
        except SceneError as err:
            raise ReconstructionError(str(err)) from err
        if known is not None:
            file_priors(opts.positions, known, opts.position_std)
    opened = Opened(source, method, opts, Path(out_dir))
    try:
        opened.known_scene = source.known_scene()
    except SceneError as err:
        raise ReconstructionError(str(err)) from err
    known_scene = opened.known_scene
    if known_scene is not None and len(known_scene.items) >= 2:  # a scene: priors and turns before the features
        opened.priors = scene_priors(source, known_scene, opts)
        if opts.pairs == Pairs.POSITIONS and known_centres(opened.priors) is None:
            make_pairs(len(known_scene.items), Pairs.POSITIONS, 1)  # refused before any feature is computed
        if extractor is None:
            opened.method, opened.turns = turned_method(
                method, opened.priors, len(known_scene.items), opts, False, opts.progress
            )
    if opts.single_camera is None:  # one camera shot a recording; a scene's photos may come from several
        opened.opts = replace(opts, single_camera=source.one_camera)
    try:
        check_output_outside(opened.out, [scene_dir])
    except ValueError as err:
        raise ReconstructionError(str(err)) from None
    if not utf8(str(opened.out.resolve())):
        raise ReconstructionError(f"{opened.out!s}: the output path is not valid UTF-8, which COLMAP cannot use")
    return opened


def read_features(opened: Opened, scene_dir, extractor, runner: Runner) -> Read:
    """The features of every image (:meth:`lburst.sfm.inputs.InputSource.read`) and the camera
    priors from their sizes; a recording's priors and turns once its keyframes are read (its
    features again with rotation sets where they show turned views).  A source that stopped
    before 2 images leaves a ``result.json`` of :attr:`Status.SOURCE_FAILED`; it and fewer than
    2 images are :class:`ReconstructionError`."""
    source, method, opts, out = opened.source, opened.method, opened.opts, opened.out
    priors, turns = opened.priors, opened.turns
    try:
        scene, features, source_error = source.read(method, out, opts, extractor, runner).unpack()
        if source_error and len(scene.items) < 2:  # nothing to reconstruct: say why in result.json too
            out.mkdir(parents=True, exist_ok=True)
            read = f"{len(scene.items)} keyframe(s) read before the recording stopped; no model"
            error = f"{source_error} ({read})"
            ReconstructionResult(
                str(scene_dir), str(method), str(out), scene.names, status=Status.SOURCE_FAILED, error=error
            ).save()
            raise ReconstructionError(source_error)
        if len(scene.items) < 2:
            raise ReconstructionError(
                f"{scene_dir}: a reconstruction needs at least 2 images, found {len(scene.items)}"
            )
        if opened.known_scene is None:  # a recording: its keyframes and their positions are known once read
            priors = scene_priors(source, scene, opts)
            if extractor is None:
                rotated, turns = turned_method(method, priors, len(scene.items), opts, True, opts.progress)
                if rotated != method:  # its features again, with the rotation sets
                    method = rotated
                    scene, features, source_error = source.read(method, out, opts, extractor, runner).unpack()
        sizes = [(int(f["image_size"][0]), int(f["image_size"][1])) for f in features]
        return Read(scene, features, camera_plan(scene, sizes, opts), source_error, method, priors, turns)
    except SceneError as err:
        raise ReconstructionError(str(err)) from err


def scene_priors(source: InputSource, scene, opts: ReconstructOptions) -> Priors | None:
    """The position priors of the scene's images: the positions file's, else, unless
    ``opts.input_positions`` is off, those the input carries (:mod:`lburst.geo`); ``None``: none."""
    if opts.positions is not None:
        return file_priors(opts.positions, scene.names, opts.position_std)
    return source.gnss_priors(scene, opts.position_std) if opts.input_positions else None


def known_centres(priors: Priors | None) -> np.ndarray | None:
    """The centres of ``priors`` when at least 2 images have one (pairs by position), else ``None``."""
    return priors.centres if priors is not None and priors.count >= 2 else None


def planned_pairs(n: int, opts: ReconstructOptions, time_ordered: bool, priors: Priors | None):
    """The pair plan of ``n`` images and its pairs before retrieval (:func:`lburst.sfm.pairs.make_pairs`)."""
    centres = known_centres(priors)
    plan = pair_plan(n, opts, time_ordered, positions=centres is not None)
    return plan, make_pairs(n, plan.mode, plan.overlap, centres, plan)


def turned_method(
    method: Method, priors: Priors | None, n: int, opts: ReconstructOptions, time_ordered: bool, progress: bool
):
    """``method`` with rotation sets where the positions show the planned pairs turned
    (:mod:`lburst.sfm.turns`), and what was found (``None``: nothing turned, or no positions)."""
    centres = known_centres(priors)
    found = (
        None
        if centres is None
        else find_turns(centres, planned_pairs(n, opts, time_ordered, priors)[1], opts.position_std)
    )
    if found is None:
        return method, None
    rotated = method.with_default("rotations", TURN_ROTATIONS)
    found = switch_on(found, str(method), rotated != method, method.accepts("rotations"))
    if progress:
        report_stage(f"positions: {describe_turns(found)}")
    return rotated, found
