"""A recording's meta.json is checked where it is read: a JSON object, fps in --fps's range, a
camera COLMAP can use; each problem is one line naming the file and the field."""

import json

import numpy as np
import pytest

from lburst.burst.io import BurstError, write_image
from lburst.burst.meta import MAX_FPS, MIN_FPS, check_fps
from lburst.burst.sources import RecordingOptions, open_recording
from lburst.cli import main

CAMERA = {"model": "PINHOLE", "width": 32, "height": 24, "params": [30.0, 30.0, 16.0, 12.0]}


def _folder(tmp_path, meta: str):
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(3):
        write_image(folder / f"img_{i}.png", np.full((24, 32, 3), 10 * i, np.uint8))
    (folder / "meta.json").write_text(meta)
    return folder


BAD_FPS = ["[30]", '"nan"', "NaN", "Infinity", "-30", "0", "true", "1e-300", "1e300"]


@pytest.mark.parametrize("meta", ["[30]", '"fps"', "30"])
def test_meta_json_that_is_not_an_object_is_one_line_naming_it(tmp_path, meta):
    folder = _folder(tmp_path, meta)
    with pytest.raises(BurstError, match=r"meta.json: must be a JSON object") as err:
        open_recording(folder)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("fps", BAD_FPS)
def test_meta_json_fps_gets_the_checks_of_the_fps_option(tmp_path, fps):
    folder = _folder(tmp_path, f'{{"fps": {fps}}}')
    with pytest.raises(BurstError, match=r"meta.json: fps must be") as err:
        open_recording(folder)
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="--fps"):  # the same bounds as the option
        check_fps(json.loads(fps))


@pytest.mark.parametrize(
    "camera, field",
    [
        ('"PINHOLE"', "camera must be a JSON object"),
        ("[1, 2]", "camera must be a JSON object"),
        ({**CAMERA, "model": "NO_SUCH_MODEL"}, "unknown camera model"),
        ({**CAMERA, "width": "abc"}, "width and height"),
        ({**CAMERA, "height": -24}, "width and height"),
        ({**CAMERA, "width": 32.5}, "width and height"),
        ({**CAMERA, "params": [30.0, 30.0, 16.0]}, "PINHOLE takes 4 params"),
        ({**CAMERA, "params": [30.0, 30.0, "x", 12.0]}, "params must be a list of finite numbers"),
        ({**CAMERA, "params": "30 30 16 12"}, "params must be a list of finite numbers"),
        ({**CAMERA, "params": [-30.0, 30.0, 16.0, 12.0]}, "focal length must be positive"),
        ({k: v for k, v in CAMERA.items() if k != "params"}, "lacks 'params'"),
    ],
)
def test_meta_json_camera_is_checked_with_the_file_named(tmp_path, camera, field):
    pytest.importorskip("pycolmap")
    text = camera if isinstance(camera, str) else json.dumps(camera)
    folder = _folder(tmp_path, f'{{"fps": 10, "camera": {text}}}')
    with pytest.raises(BurstError, match=r"meta.json: camera") as err:
        open_recording(folder)
    assert field in str(err.value) and "\n" not in str(err.value)


def test_a_good_meta_json_is_read(tmp_path):
    folder = _folder(tmp_path, json.dumps({"fps": 12.5, "camera": CAMERA, "kind": "png"}))
    recording = open_recording(folder, RecordingOptions(burst=1, every=1))
    assert recording.fps == 12.5 and recording.camera == CAMERA and recording.meta["kind"] == "png"
    assert [k.time for k, _ in recording.bursts()] == [0.0, 0.08, 0.16]


@pytest.mark.parametrize("meta", ["[30]", '{"fps": 1e-300}', '{"fps": "nan"}', '{"camera": {"model": 1}}'])
def test_extract_of_a_folder_with_a_bad_meta_json_says_one_line(tmp_path, capsys, meta):
    folder = _folder(tmp_path, meta)
    code = main(["extract", str(folder), "--out", str(tmp_path / "out"), "--method", "sift", "--burst", "1"])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err  # extract skips the input, reports it and exits 1
    said = [line for line in err.splitlines() if "meta.json" in line]
    assert said and all(line.split("meta.json: ")[1] == said[0].split("meta.json: ")[1] for line in said), err


def test_the_fps_option_and_meta_json_share_their_bounds(capsys):
    assert (MIN_FPS, MAX_FPS) == (1e-4, 10_000.0)
    try:
        code = main(["extract", "x", "--out", "y", "--fps", "1e-300"])
    except SystemExit as exc:  # argparse's own exit
        code = exc.code
    assert code == 2 and "--fps: must be a number >= 0.0001 and <= 10000" in capsys.readouterr().err


def test_without_pycolmap_the_camera_is_checked_but_for_its_model(tmp_path, monkeypatch):
    """extract needs no sfm extra: a camera is still checked for what needs no COLMAP model."""
    import lburst.camera_dict
    from lburst.extras import MissingExtra

    class NoPycolmap:
        def __getattr__(self, name):
            raise MissingExtra("checking a camera model needs pycolmap: pip install 'lburst[sfm]'")

    monkeypatch.setattr(lburst.camera_dict, "pycolmap", NoPycolmap())
    folder = _folder(tmp_path, json.dumps({"fps": 10, "camera": {**CAMERA, "model": "SOME_MODEL"}}))
    assert open_recording(folder).camera["model"] == "SOME_MODEL"
    (folder / "meta.json").write_text(json.dumps({"fps": 10, "camera": {**CAMERA, "width": "abc"}}))
    with pytest.raises(BurstError, match="meta.json: camera: width and height must be positive integers"):
        open_recording(folder)
