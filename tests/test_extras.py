"""Optional dependencies: absent extras give a one-line install hint, and nothing is
imported (or a matplotlib backend chosen) before it is used."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from lburst.burst.io import save_burst
from lburst.extras import LazyModule, MissingExtra, require


def run_python(code: str, block: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter where the modules ``block`` cannot be imported."""
    prelude = "import sys\n" + "".join(f"sys.modules[{name!r}] = None\n" for name in block)
    return subprocess.run([sys.executable, "-c", prelude + code], capture_output=True, text=True)


def test_require_names_the_extra_of_a_missing_package(monkeypatch):
    monkeypatch.setitem(sys.modules, "pycolmap", None)
    with pytest.raises(MissingExtra, match=r"reconstruction needs pycolmap: pip install 'lburst\[sfm\]'"):
        require("pycolmap", "reconstruction")


def test_require_does_not_hide_an_unknown_missing_module():
    with pytest.raises(ModuleNotFoundError) as info:
        require("lburst_no_such_module")
    assert not isinstance(info.value, MissingExtra)


def test_lazy_module_imports_on_first_use():
    lazy = LazyModule("json")
    assert "not loaded" in repr(lazy)
    assert lazy.dumps([1]) == "[1]"
    assert "loaded" in repr(lazy) and "not" not in repr(lazy)


def test_reconstruction_without_pycolmap_says_what_to_install():
    code = (
        "from lburst.sfm.colmap import default_camera, exif_camera\n"
        "print(default_camera(640, 480)['model'])\n"
        "exif_camera('x.jpg')\n"
    )
    out = run_python(code, block=("pycolmap",))
    assert out.returncode != 0
    assert out.stdout.strip() == "SIMPLE_RADIAL"  # what needs no COLMAP still works
    assert "pip install 'lburst[sfm]'" in out.stderr.strip().splitlines()[-1]


def test_extraction_and_the_registry_work_without_the_extras():
    code = (
        "import numpy as np, lburst\n"
        "burst = np.random.default_rng(0).integers(0, 255, (3, 64, 80, 3), dtype=np.uint8)\n"
        "print(len(lburst.methods.available()) > 3, lburst.methods.create('sift')(burst)['descriptors'].shape[1])\n"
    )
    out = run_python(code, block=("pycolmap", "skimage", "matplotlib", "onnx", "onnxruntime", "onnxscript"))
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "128"]


def test_merge_without_scikit_image_says_what_to_install():
    code = (
        "import numpy as np, lburst\n"
        "burst = np.zeros((3, 32, 32, 3), np.uint8)\n"
        "lburst.methods.create('merge+sift')(burst)\n"
    )
    out = run_python(code, block=("skimage",))
    assert out.returncode != 0
    assert "pip install 'lburst[sfm]'" in out.stderr.strip().splitlines()[-1]


def test_cli_prints_one_line_for_a_missing_extra(tmp_path):
    out_dir = str(tmp_path / "b")
    code = f"from lburst.cli import main\nraise SystemExit(main(['simulate', 'burst', '--out', {out_dir!r}]))\n"
    out = run_python(code, block=("skimage",))
    assert out.returncode == 2
    assert out.stderr.strip() == (
        "lburst simulate burst: error: the default photo (give IMAGE instead) needs scikit-image: "
        "pip install 'lburst[sfm]'"
    )


def test_plotting_chooses_no_backend(tmp_path):
    png = str(tmp_path / "k.png")
    code = (
        "import numpy as np\n"
        "import lburst.viz, lburst.demo\n"
        "assert 'matplotlib' not in sys.modules\n"
        "img = np.zeros((40, 60, 3), np.uint8)\n"
        f"lburst.viz.plot_keypoints_and_maps(img, np.array([[5.0, 6.0]]), np.zeros((40, 60)), None, {png!r})\n"
        "assert 'matplotlib.pyplot' not in sys.modules\n"
        "print('ok')\n"
    )
    out = run_python(code)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "k.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plots_need_matplotlib_only_when_drawn(tmp_path):
    pytest.importorskip("matplotlib")
    from lburst.demo import plot_matches

    img = np.zeros((30, 40, 3), np.uint8)
    kp = np.array([[3.0, 4.0], [10.0, 12.0]])
    plot_matches(img, img, kp, kp, tmp_path / "m.png", "test")
    assert (tmp_path / "m.png").stat().st_size > 0


def _cli(args: list[str], block: tuple[str, ...]) -> subprocess.CompletedProcess:
    return run_python(f"from lburst.cli import main\nraise SystemExit(main({args!r}))\n", block=block)


def test_simulating_a_video_without_pyav_says_what_to_install(tmp_path):
    out = _cli(["simulate", "flight", "--video", str(tmp_path / "f.mp4"), "--bursts", "2", "--size", "64x48"], ("av",))
    assert out.returncode == 2
    assert out.stderr.strip() == (
        "lburst simulate flight: error: writing a video (--video) needs av: pip install 'lburst[video]'"
    )
    assert not (tmp_path / "f.mp4").exists()


@pytest.mark.parametrize("command", ["extract", "reconstruct"])
def test_reading_a_video_without_pyav_says_what_to_install(tmp_path, command):
    video = tmp_path / "night.mp4"
    video.write_bytes(b"\x00" * 64)  # never opened: PyAV is missing
    out = _cli([command, str(video), "--every", "8", "--method", "orb", "--out", str(tmp_path / "o")], ("av",))
    assert out.returncode == 2
    assert out.stderr.strip().splitlines()[-1] == (
        f"lburst {command}: error: reading a video needs av: pip install 'lburst[video]'"
    )
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize("command", ["extract", "reconstruct"])
def test_reading_dng_frames_without_rawpy_says_what_to_install(tmp_path, command):
    folder = tmp_path / "night_dng"
    folder.mkdir()
    for i in range(3):
        (folder / f"frame_{i:06d}.dng").write_bytes(b"II*\x00")  # never parsed: rawpy is missing
    out = _cli(
        [command, str(folder), "--every", "1", "--burst", "1", "--method", "orb", "--out", str(tmp_path / "o")],
        ("rawpy",),
    )
    assert out.returncode == 2
    assert out.stderr.strip().splitlines()[-1] == (
        f"lburst {command}: error: reading DNG frames needs rawpy: pip install 'lburst[raw]'"
    )
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize(("module", "extra"), [("av", "video"), ("rawpy", "raw"), ("tifffile", "raw"), ("evo", "evo")])
def test_every_extra_named_is_one_pyproject_defines(module, extra):
    from pathlib import Path

    from lburst.extras import EXTRAS

    tomllib = pytest.importorskip("tomllib")  # Python 3.11+

    assert EXTRAS[module][1] == extra
    pyproject = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    extras = pyproject["project"]["optional-dependencies"]
    assert set(extra for _, extra in EXTRAS.values()) <= set(extras)
    assert any(req.startswith(EXTRAS[module][0]) for req in extras[extra])


def test_reconstruct_without_pycolmap_stops_before_any_feature(tmp_path):
    burst = np.random.default_rng(0).integers(0, 255, (3, 48, 64, 3), dtype=np.uint8)
    for name in ("b0", "b1"):
        save_burst(burst, tmp_path / "scene" / name)
    out = tmp_path / "out"
    proc = _cli(["reconstruct", str(tmp_path / "scene"), "--method", "sift", "--out", str(out)], ("pycolmap",))
    assert proc.returncode == 2
    assert proc.stderr.strip() == "lburst reconstruct: error: reconstruction needs pycolmap: pip install 'lburst[sfm]'"
    assert not out.exists()  # no feature computed, no folder made


def test_check_installed_names_the_extra_without_importing(monkeypatch):
    from lburst.extras import check_installed

    check_installed("json")
    monkeypatch.setitem(sys.modules, "pycolmap", None)
    with pytest.raises(MissingExtra, match=r"pip install 'lburst\[sfm\]'"):
        check_installed("pycolmap", "reconstruction")


def test_the_dev_extra_brings_every_package_a_test_would_skip_without():
    """``pip install -e ".[dev]"`` (what ``make test`` installs) gives every test what it imports
    with ``pytest.importorskip``, so that none skips for a missing package (the kornia ones did)."""
    import re
    from pathlib import Path

    from lburst.extras import EXTRAS

    root = Path(__file__).resolve().parents[1]
    dev = re.search(r"^dev = \[(.*)\]$", (root / "pyproject.toml").read_text(), re.M).group(1)
    listed = {re.split(r"[<>=!~\[ ;]", requirement)[0].lower() for requirement in re.findall(r'"([^"]+)"', dev)}
    extras = set(re.search(r"lburst\[([^\]]*)\]", dev).group(1).split(","))
    sources = "".join(path.read_text(encoding="utf-8") for path in sorted((root / "tests").rglob("*.py")))
    skipped_without = {name.split(".")[0] for name in re.findall(r'importorskip\(\s*"([\w.]+)"', sources)}
    core = {"lburst", "torch", "tomllib"}  # lburst, its own dependencies, the standard library of Python 3.11+
    missing = sorted(
        name for name in skipped_without - core if name not in listed and EXTRAS.get(name, ("", ""))[1] not in extras
    )
    assert "kornia" in skipped_without and not missing, f"add to the dev extra in pyproject.toml: {missing}"
