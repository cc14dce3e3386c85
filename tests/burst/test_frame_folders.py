"""A plain folder of frames (PNG/JPEG/TIFF, no meta.json) is a recording when --every or --motion
asks for keyframes, in `lburst extract` and `lburst reconstruct`; without them it stays one burst.
Without a meta.json camera, reconstruction estimates the camera and says so."""

import argparse
import contextlib
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

from lburst.burst.io import write_image
from lburst.burst.sources import RecordingOptions, is_recording
from lburst.cli import main
from lburst.cli.options import recording_options


def _frames(folder, n, size=(96, 128), seed=0):
    """``n`` textured frames ``img_0.png ...`` panning 2 px a frame, no meta.json."""
    rng = np.random.default_rng(seed)
    texture = rng.integers(0, 256, (size[0], size[1] + 2 * n, 3), dtype=np.uint8)
    folder.mkdir(parents=True)
    for i in range(n):
        write_image(folder / f"img_{i}.png", np.ascontiguousarray(texture[:, 2 * i : 2 * i + size[1]]))
    return folder


def _args(**given):
    defaults = dict(
        burst_frames=5, every=None, motion=None, start=0, fps=None, raw_gain="auto", raw_curve="linear", topic=None
    )
    return argparse.Namespace(**{**defaults, **given})


def test_a_frame_folder_is_a_recording_only_when_keyframes_are_asked_for(tmp_path):
    folder = _frames(tmp_path / "frames", 4)
    assert not is_recording(folder)
    assert not is_recording(folder, RecordingOptions())
    assert is_recording(folder, RecordingOptions(frame_folders=True))
    assert not recording_options(_args()).frame_folders
    assert recording_options(_args(every=8)).frame_folders and recording_options(_args(motion=0.1)).frame_folders
    # a scene (sub-folders of bursts) stays a scene whatever the options
    scene = tmp_path / "scene"
    _frames(scene / "b0", 3)
    assert not is_recording(scene, RecordingOptions(frame_folders=True))
    # frame_folders changes no burst, so cached features stay valid
    assert RecordingOptions(frame_folders=True).signature() == RecordingOptions().signature()


def test_extract_cuts_a_frame_folder_without_meta_json_with_every(tmp_path, capsys):
    folder = _frames(tmp_path / "night", 12)
    out = tmp_path / "out"
    assert main(["extract", str(folder), "--every", "4", "--burst", "3", "--method", "orb", "--out", str(out)]) == 0
    assert sorted(p.name for p in (out / "night").glob("*.npz")) == [
        "f000000_t0.000s.npz",
        "f000004_t0.133s.npz",
        "f000008_t0.267s.npz",
    ]
    assert not (out / "night.npz").exists()


def test_extract_cuts_a_frame_folder_without_meta_json_with_motion(tmp_path, capsys):
    folder = _frames(tmp_path / "night", 30)
    out = tmp_path / "out"
    assert main(["extract", str(folder), "--motion", "0.05", "--burst", "3", "--method", "orb", "--out", str(out)]) == 0
    keyframes = sorted(p.name for p in (out / "night").glob("*.npz"))
    assert keyframes and keyframes[0] == "f000000_t0.000s.npz"  # the first candidate is the first keyframe


def test_without_every_or_motion_a_frame_folder_stays_one_burst(tmp_path, capsys):
    folder = _frames(tmp_path / "burst", 5)
    out = tmp_path / "out"
    assert main(["extract", str(folder), "--method", "orb", "--out", str(out)]) == 0
    assert (out / "burst.npz").is_file() and not (out / "burst").exists()


@pytest.fixture(scope="module")
def estimated(tmp_path_factory):
    """`lburst reconstruct FRAMES --every 16` on a folder of PNG frames without meta.json: (out, stdout, exit code)."""
    from lburst.scenes.flight_recording import write_flight_png
    from lburst.scenes.night_flight import NightFlightConfig

    tmp = tmp_path_factory.mktemp("estimated")
    cfg = NightFlightConfig.daylight(n_bursts=3, width=256, height=192, noise="none")
    folder = write_flight_png(tmp / "frames", cfg, progress=False)
    (folder / "meta.json").unlink()
    (folder / "gt.txt").unlink()
    out = tmp / "out"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(
            ["reconstruct", str(folder), "--method", "sift,max_features=1500", "--every", "16", "--burst", "1"]
            + ["--out", str(out), "--threads", "1"]
        )
    return out, printed.getvalue(), code


def test_reconstruct_takes_a_frame_folder_without_meta_json_and_says_the_camera_is_estimated(estimated):
    out, printed, code = estimated
    assert code == 0
    result = json.loads((out / "result.json").read_text())
    assert result["names"] == [f"f{i:06d}_t{i / 30:.3f}s" for i in range(0, 65, 16)]  # fps 30 without meta.json
    assert result["registered"] == result["names"]
    said = "estimated, one for all keyframes (no meta.json camera)"
    assert result["metrics"]["camera"] == said
    assert f"Camera: {said}." in (out / "report.md").read_text()
    assert f"camera: {said}" in printed
    import pycolmap

    assert len(pycolmap.Reconstruction(str(out / "colmap" / "model")).cameras) == 1  # one camera shot them
    assert (out / "trajectory.tum").is_file()


def test_the_readme_hloc_snippet_reads_a_reconstruction_as_hloc_does(estimated):
    """docs/your_data.md (linked from the README's "Your own data"): the h5py lines that read features.h5 / matches.h5 as hloc.utils.io
    does (a group per image with keypoints, descriptors (D, K), scores; a group per pair
    "name0/name1" with matches0 and matching_scores0), run on a reconstruction's output."""
    out, _, _ = estimated
    section = (Path(__file__).parents[2] / "docs" / "your_data.md").read_text()
    (code,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    scope: dict = {}
    exec(compile(code.replace('Path("night_video")', f"Path({str(out)!r})"), "your_data.md", "exec"), scope)
    name0, name1 = scope["name0"], scope["name1"]
    assert (out / "images" / name0).is_file() and (out / "images" / name1).is_file()
    kp0, kp1, desc0, pairs = scope["kp0"], scope["kp1"], scope["desc0"], scope["pairs"]
    assert kp0.shape[1] == 2 and desc0.shape == (128, len(kp0)) and scope["scores0"].shape == (len(kp0),)
    assert len(pairs) > 20 and pairs[:, 0].max() < len(kp0) and pairs[:, 1].max() < len(kp1)
    # the same matches lburst gave COLMAP for this pair
    verified = np.load(out / "colmap" / "input.npz")
    names = [f"{n}.png" for n in json.loads((out / "result.json").read_text())["names"]]
    q = [tuple(p) for p in verified["pairs"].tolist()].index((names.index(name0), names.index(name1)))
    np.testing.assert_array_equal(np.sort(pairs, axis=0), np.sort(verified[f"m_{q}"], axis=0))
    np.testing.assert_array_equal(scope["xy0"], kp0[pairs[:, 0]])


def test_reconstruct_with_a_meta_json_camera_says_it_was_held_fixed(tmp_path, capsys):
    from lburst.scenes.flight_recording import write_flight_png
    from lburst.scenes.night_flight import NightFlightConfig

    cfg = NightFlightConfig.daylight(n_bursts=3, width=256, height=192, noise="none")
    folder = write_flight_png(tmp_path / "frames", cfg, progress=False)
    out = tmp_path / "out"
    code = main(
        ["reconstruct", str(folder), "--method", "sift,max_features=1500", "--every", "16", "--burst", "1"]
        + ["--out", str(out), "--threads", "1"]
    )
    assert code == 0
    result = json.loads((out / "result.json").read_text())
    assert result["registered"] == result["names"] and len(result["names"]) == 5
    assert result["metrics"]["camera"] == "meta.json, held fixed"
    assert result["metrics"]["ate_percent"] < 1.0


def test_show_takes_a_frame_of_a_frame_folder_without_meta_json(tmp_path, capsys):
    folder = _frames(tmp_path / "night", 12)
    assert main(["show", str(folder), "--frame", "4", "--frames", "5", "--out", str(tmp_path / "k.png")]) == 0
    assert (tmp_path / "k.png").stat().st_size > 0
    # without --frame the folder is one burst, and 12 frames are not one
    assert main(["show", str(folder), "--out", str(tmp_path / "b.png")]) == 2
    assert "a burst needs an odd number" in capsys.readouterr().err
