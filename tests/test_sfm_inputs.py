"""One question about the kind of input (issue 28): :func:`lburst.sfm.inputs.open_input` asks it,
the pipeline takes the input's defaults from the answer."""

from __future__ import annotations

import ast
from pathlib import Path

import lburst
from lburst.burst.sources import RecordingOptions
from lburst.sfm.inputs import RecordingInput, SceneInput, open_input

SFM = Path(lburst.__file__).parent / "sfm"


def test_open_input_tells_a_scene_from_a_recording(tmp_path):
    (tmp_path / "scene" / "b0").mkdir(parents=True)
    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / "img_0.png").write_bytes(b"")
    (tmp_path / "clip.mp4").write_bytes(b"")
    scene = open_input(tmp_path / "scene")
    assert type(scene) is SceneInput and not scene.time_ordered and not scene.one_camera
    assert isinstance(open_input(tmp_path / "clip.mp4"), RecordingInput)
    assert type(open_input(tmp_path / "frames")) is SceneInput
    recording = open_input(tmp_path / "frames", RecordingOptions(every=4, frame_folders=True))
    assert isinstance(recording, RecordingInput) and recording.time_ordered and recording.one_camera


def test_only_the_inputs_ask_whether_an_input_is_a_recording():
    asking = sorted(
        path.name
        for path in SFM.glob("*.py")
        if any(
            isinstance(node, ast.Name | ast.alias)
            and "is_recording" in (getattr(node, "id", None), getattr(node, "name", None))
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        )
    )
    assert asking == ["inputs.py"], asking
