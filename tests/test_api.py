"""The library API: each command's work is a function of ``lburst`` (``lburst.extract``,
``lburst.reconstruct``) that its command line calls, and no library module climbs back into
the command line (``lburst.cli``)."""

from __future__ import annotations

import ast
from pathlib import Path

import cv2
import numpy as np
import skimage.data

import lburst
from lburst.burst.io import save_burst
from lburst.cli import main

ROOT = Path(lburst.__file__).resolve().parent


def _burst(folder: Path, seed: int) -> Path:
    crop = skimage.data.astronaut()[40 * seed : 40 * seed + 240, 100:420]
    save_burst(np.stack([cv2.resize(crop, (160, 120), interpolation=cv2.INTER_AREA)] * 3), folder)
    return folder


def test_extract_writes_what_lburst_extract_writes_and_reports_each_input(tmp_path, capsys):
    good, other = _burst(tmp_path / "in" / "b0", 0), _burst(tmp_path / "in" / "b1", 1)
    broken = tmp_path / "in" / "broken"
    broken.mkdir()
    (broken / "0.png").write_bytes(b"not a PNG")
    report = lburst.extract([good, other, broken], tmp_path / "api", "sift", h5=True)
    assert (report.done, report.already, [p for p, _ in report.failed]) == (2, 0, [broken])
    assert sorted(group for group, _ in report.finished) == ["b0.png", "b1.png"]
    assert main(["extract", str(good), str(other), "--out", str(tmp_path / "cli"), "--method", "sift", "--h5"]) == 0
    assert "2 bursts extracted" in capsys.readouterr().out
    for name in ("b0", "b1"):
        api, cli = (np.load(tmp_path / run / f"{name}.npz") for run in ("api", "cli"))
        for key in ("keypoints", "descriptors", "scores"):
            np.testing.assert_array_equal(api[key], cli[key])
    assert (tmp_path / "api" / "features.h5").is_file()
    again = lburst.extract([good], tmp_path / "api", "sift")  # stored: nothing computed
    assert (again.done, again.already, again.failed) == (0, 1, [])


def test_reconstruct_is_the_pipeline_of_lburst_reconstruct():
    from lburst.sfm.reconstruct import reconstruct_scene

    assert lburst.reconstruct is reconstruct_scene
    assert lburst.ReconstructOptions().num_threads >= 1


def _imported(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def test_no_library_module_imports_the_command_line():
    offenders = [
        str(path.relative_to(ROOT))
        for path in sorted(ROOT.rglob("*.py"))
        if "cli" not in path.relative_to(ROOT).parts[:1]
        and any(name == "lburst.cli" or name.startswith("lburst.cli.") for name in _imported(path))
    ]
    assert offenders == []
