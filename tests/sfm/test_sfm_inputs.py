"""One question about the kind of input (issue 28): :mod:`lburst.sfm.inputs` asks it
(:func:`open_input`, :func:`open_bursts`), the pipeline takes the input's defaults from the
answer, and ``extract``, ``show`` and ``reconstruct`` read every input through its sources."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np

import lburst
from lburst import store
from lburst.burst.io import save_burst
from lburst.burst.sources import RecordingOptions
from lburst.sfm.inputs import BurstInput, RecordingInput, SceneInput, open_bursts, open_input
from lburst.sfm.options import ReconstructOptions

ROOT = Path(lburst.__file__).parent


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


def test_only_the_sources_ask_whether_an_input_is_a_recording():
    """``is_recording`` is defined in lburst/burst/sources.py and named nowhere else in the
    package but lburst/sfm/inputs.py (no other module imports or calls it)."""
    asking = sorted(
        path.relative_to(ROOT).as_posix()
        for path in ROOT.rglob("*.py")
        if any(
            isinstance(node, ast.Name | ast.alias | ast.Attribute)
            and "is_recording" in (getattr(node, "id", None), getattr(node, "name", None), getattr(node, "attr", None))
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        )
    )
    assert asking == ["sfm/inputs.py"], asking


def test_open_bursts_tells_a_burst_from_a_recording(tmp_path):
    """``extract`` and ``show``: a whole video or a folder of frames is one burst unless the
    options cut it (``--every``/``--motion``/``--frame``); a folder with meta.json is a recording."""
    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / "img_0.png").write_bytes(b"")
    (tmp_path / "clip.mp4").write_bytes(b"")
    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "meta.json").write_text("{}")
    assert type(open_bursts(tmp_path / "clip.mp4")) is BurstInput
    assert type(open_bursts(tmp_path / "frames", RecordingOptions())) is BurstInput
    cut = RecordingOptions(every=4, frame_folders=True)
    assert isinstance(open_bursts(tmp_path / "clip.mp4", cut), RecordingInput)
    assert isinstance(open_bursts(tmp_path / "frames", cut), RecordingInput)
    assert isinstance(open_bursts(tmp_path / "rec"), RecordingInput)
    assert open_bursts(tmp_path / "rec").folder == "rec" and open_bursts(tmp_path / "clip.mp4").folder == ""


def _keys(source) -> list[tuple[str, dict]]:
    return [(b.name, b.key) for b in source.keyframe_bursts(store.method_key("sift"))]


def test_every_source_yields_named_bursts_keyed_as_the_store_keys_them(tmp_path):
    """A scene's burst and the same folder given alone have one key (so reconstruct finds what
    extract stored); a recording's keyframes are keyed by the recording, its cut and their names."""
    frames = np.random.default_rng(0).integers(0, 255, (3, 24, 32, 3), dtype=np.uint8)
    for name in ("b0", "b1"):
        save_burst(frames, tmp_path / "scene" / name)
    scene = _keys(SceneInput(tmp_path / "scene"))
    assert [name for name, _ in scene] == ["b0", "b1"]
    assert scene[0] == _keys(BurstInput(tmp_path / "scene" / "b0"))[0]
    assert scene[0][1] == store.key(store.method_key("sift"), tmp_path / "scene" / "b0")
    save_burst(np.concatenate([frames] * 3), tmp_path / "rec", whole=True)
    (tmp_path / "rec" / "meta.json").write_text("{}")
    source = open_bursts(tmp_path / "rec", RecordingOptions(burst=3, every=4))
    bursts = list(source.keyframe_bursts(store.method_key("sift")))
    assert [b.index for b in bursts] == [0, 4, 8] and bursts[1].load().shape == (3, 24, 32, 3)
    assert {b.key["source"]["keyframe"] for b in bursts} == {b.name for b in bursts}
    assert len({b.key["source"]["sha1"] for b in bursts}) == 1


def test_reading_a_scene_shows_a_bar_over_its_bursts_only_when_asked(tmp_path, capsys, monkeypatch):
    """``lburst reconstruct`` spends most of its time on features: a bar says how far it is
    (here at once; it waits :data:`lburst.cluster.runner.BAR_DELAY_S` otherwise)."""
    monkeypatch.setattr("lburst.cluster.runner.BAR_DELAY_S", 0.0)
    frames = np.random.default_rng(0).integers(0, 255, (3, 48, 64, 3), dtype=np.uint8)
    for name in ("b0", "b1"):
        save_burst(frames, tmp_path / "scene" / name)
    source = SceneInput(tmp_path / "scene")
    source.read("sift", tmp_path / "quiet", ReconstructOptions(progress=False))
    assert "features" not in capsys.readouterr().err
    keyframes = source.read("sift", tmp_path / "loud", ReconstructOptions(progress=True))
    assert "features: " in capsys.readouterr().err and len(keyframes.features) == 2


def test_a_scene_keeps_8000_keypoints_unless_the_spec_says_otherwise(tmp_path):
    """A scene's photos lie farther apart than a recording's keyframes: a learned method whose
    spec sets no ``top_k`` keeps :data:`PHOTO_SET_KEYPOINTS` there (the key of its stored
    features says so), a recording its method's own 4,000, and a spec's ``top_k`` wins."""
    import cv2

    from lburst.model.network import LBurstNet, NetConfig, save_checkpoint
    from lburst.sfm import reconstruct_scene
    from lburst.sfm.inputs import PHOTO_SET_KEYPOINTS

    assert SceneInput.keypoints == PHOTO_SET_KEYPOINTS == 8000 and RecordingInput.keypoints is None
    ckpt = tmp_path / "w.pt"
    save_checkpoint(LBurstNet(NetConfig(frames=1)), ckpt)
    scene = tmp_path / "scene"
    scene.mkdir()
    for i in range(2):
        image = np.random.default_rng(i).integers(0, 256, size=(96, 128, 3), dtype=np.uint8)
        cv2.imwrite(str(scene / f"{i}.png"), image)
    for spec, top_k in ((f"r2d2:{ckpt}", "8000"), (f"r2d2:{ckpt},top_k=50", "50")):
        out = tmp_path / f"out{top_k}"
        reconstruct_scene(scene, spec, out, ReconstructOptions(progress=False))
        meta = store.read_meta(out / "features" / "0.npz")
        assert meta["key"]["method"] == store.method_key(f"r2d2:{ckpt},top_k={top_k}"), meta["key"]["method"]
