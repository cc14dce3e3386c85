"""hloc's files: ``matches.h5`` holds each match's real score, not 1; every input of
``lburst reconstruct`` (a scene of bursts, a recording) leaves the same files; the outputs of
``reconstruct`` and of ``extract --h5`` read as hloc's own readers read them, by the names of
the images in ``images/``."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from lburst.matching import create
from lburst.sfm.outputs import write_hloc
from lburst.tum import read_tum


def features(rng, descriptors: np.ndarray) -> dict:
    k = len(descriptors)
    return {
        "keypoints": rng.uniform(0, 60, (k, 2)).astype(np.float32),
        "scales": np.ones(k, np.float32),
        "scores": np.ones(k, np.float32),
        "descriptors": descriptors,
        "image_size": np.array([64, 48], np.int64),
    }


def test_matches_h5_holds_the_matchers_scores(tmp_path):
    rng = np.random.default_rng(0)
    b = rng.normal(size=(40, 16)).astype(np.float32)
    a = b[:30] + 0.4 * rng.normal(size=(30, 16)).astype(np.float32)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    fa, fb = features(rng, a), features(rng, b)
    matches, scores = create("mnn").match(fa, fb)
    assert len(matches) > 10 and len(np.unique(scores)) > 1
    write_hloc(tmp_path, ["a", "b"], [fa, fb], [(0, 1)], [matches], [scores])
    with h5py.File(tmp_path / "matches.h5") as f:
        m0, s0 = f["a.png/b.png/matches0"][()], f["a.png/b.png/matching_scores0"][()]
    np.testing.assert_array_equal(m0[matches[:, 0]], matches[:, 1])
    np.testing.assert_allclose(s0[matches[:, 0]], scores, atol=1e-3)  # float16, as hloc
    assert (s0[m0 < 0] == 0).all()
    write_hloc(tmp_path, ["a", "b"], [fa, fb], [(0, 1)], [matches])  # scores from the descriptors
    with h5py.File(tmp_path / "matches.h5") as f:
        np.testing.assert_allclose(f["a.png/b.png/matching_scores0"][()][matches[:, 0]], scores, atol=1e-3)


# What hloc's readers expect (hloc is not a dependency; the layout of hloc.utils.io, written here
# from its description): an image's group in features.h5 is its file name under the image folder; a
# pair's group in matches.h5 is "name0/name1" with any "/" inside a name replaced by "-", stored in
# either order, holding matches0 (index into image 1, -1 unmatched) and matching_scores0.
def pair_group(first: str, second: str) -> str:
    return "/".join(name.replace("/", "-") for name in (first, second))


def get_keypoints(path, name: str) -> np.ndarray:
    with h5py.File(str(path), "r") as h5:
        return np.asarray(h5[name]["keypoints"])


def get_matches(path, name0: str, name1: str) -> tuple[np.ndarray, np.ndarray]:
    """(M, 2) indices (image ``name0``, image ``name1``) and (M,) scores, whichever order was stored."""
    with h5py.File(str(path), "r") as h5:
        flipped = pair_group(name0, name1) not in h5
        group = h5[pair_group(name1, name0) if flipped else pair_group(name0, name1)]
        partner, scores = np.asarray(group["matches0"]), np.asarray(group["matching_scores0"])
    matched = np.flatnonzero(partner >= 0)
    pairs = np.column_stack([matched, partner[matched]])
    return (pairs[:, ::-1] if flipped else pairs), scores[matched]


def check_as_hloc_reads(out, images=None) -> list[str]:
    """Read ``out`` as hloc's ``reconstruction.main`` does (every image of ``pairs.txt``, or of
    ``features.h5``, from ``out/images`` by its name, its keypoints from ``features.h5`` by the
    same name, each pair's matches from ``matches.h5``); returns the image names."""
    from lburst.burst.io import read_image

    images = images or out / "images"
    with h5py.File(out / "features.h5") as f:
        names = []
        f.visititems(lambda name, obj: names.append(name) if "keypoints" in getattr(obj, "keys", list)() else None)
    assert names and sorted(names) == sorted(p.relative_to(images).as_posix() for p in images.rglob("*.png"))
    for name in names:
        h, w = read_image(images / name).shape[:2]
        kp = get_keypoints(out / "features.h5", name)
        with h5py.File(out / "features.h5") as f:
            assert f[name]["image_size"][()].tolist() == [w, h]
            assert f[name]["descriptors"].shape[1] == len(kp) == len(f[name]["scores"])
        assert len(kp) and (kp >= -0.5).all() and (kp[:, 0] < w).all() and (kp[:, 1] < h).all()
    if (out / "pairs.txt").is_file():
        pairs = [line.split() for line in (out / "pairs.txt").read_text().splitlines()]
        assert pairs and all(a in names and b in names for a, b in pairs)
        for a, b in pairs:
            matches, scores = get_matches(out / "matches.h5", a, b)
            assert matches[:, 0].max(initial=-1) < len(get_keypoints(out / "features.h5", a))
            assert matches[:, 1].max(initial=-1) < len(get_keypoints(out / "features.h5", b))
            assert len(scores) == len(matches) and (scores <= 1.001).all()
        matches, scores = get_matches(out / "matches.h5", *pairs[0])
        assert len(matches) > 20 and len(np.unique(scores)) > 1  # real scores, not all 1
        flipped, _ = get_matches(out / "matches.h5", pairs[0][1], pairs[0][0])
        np.testing.assert_array_equal(flipped, matches[:, ::-1])
    return names


SIFT = ["--method", "sift,max_features=1500", "--threads", "1"]


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """The daylight flight as a scene of 5 single-frame bursts with a reference.json and as a
    folder of PNG frames with meta.json and gt.txt (a recording), each reconstructed with
    `lburst reconstruct`: {"scene": (input, out), "recording": (input, out)}."""
    from lburst.cli import main
    from lburst.scenes.flight_recording import write_flight_png
    from lburst.scenes.night_flight import NightFlightConfig, make_night_flight

    tmp = tmp_path_factory.mktemp("flights")
    cfg = NightFlightConfig.daylight(n_bursts=5, frames_per_burst=1, width=256, height=192, noise="none")
    make_night_flight(tmp / "scene", cfg, progress=False)
    frames = write_flight_png(tmp / "frames", replace(cfg, n_bursts=3, frames_per_burst=5), progress=False)
    runs = {"scene": (tmp / "scene", tmp / "scene_out"), "recording": (frames, tmp / "frames_out")}
    assert main(["reconstruct", str(tmp / "scene"), "--out", str(runs["scene"][1]), *SIFT]) == 0
    recording = ["--every", "16", "--burst", "1"]
    assert main(["reconstruct", str(frames), "--out", str(runs["recording"][1]), *SIFT, *recording]) == 0
    return runs


def layout(out) -> set[str]:
    """The files under ``out``, with the per-image ones (images, features cache) named ``*``."""
    files = set()
    for path in out.rglob("*"):
        if path.is_file():
            parts = path.relative_to(out).parts
            files.add("/".join((*parts[:-1], "*")) if parts[0] in ("images", "features") else "/".join(parts))
    return files


def test_a_scene_and_a_recording_leave_the_same_files(flights):
    (_, scene), (_, recording) = flights["scene"], flights["recording"]
    assert layout(scene) == layout(recording)
    for name in ("features.h5", "matches.h5", "pairs.txt", "trajectory.tum", "reference.tum", "report.md"):
        assert name in layout(scene)
    assert {"colmap/model/images.bin", "colmap/model.ply", "result.json", "keyframes.json"} <= layout(scene)
    for out in (scene, recording):
        result = json.loads((out / "result.json").read_text())
        assert result["registered"] == result["names"] and result["metrics"]["ate_percent"] < 1.0
        times, _ = read_tum(out / "trajectory.tum")
        ref_times, _ = read_tum(out / "reference.tum")
        assert len(times) == len(result["names"]) and np.allclose(times, ref_times)
        assert sorted(p.name for p in (out / "images").iterdir()) == sorted(f"{n}.png" for n in result["names"])


def test_the_outputs_of_reconstruct_read_as_hloc_reads_them(flights):
    for _, out in flights.values():
        names = check_as_hloc_reads(out)
        assert sorted(names) == sorted(f"{n}.png" for n in json.loads((out / "result.json").read_text())["names"])


def test_the_outputs_of_extract_h5_read_as_hloc_reads_them(flights, tmp_path):
    """`lburst extract --h5` of bursts and of a recording: images/ holds the common frame of
    each, and features.h5's groups are those images' names (a recording's under its folder)."""
    from lburst.cli import main

    scene, frames = flights["scene"][0], flights["recording"][0]
    out = tmp_path / "extracted"
    bursts = sorted(str(p) for p in scene.iterdir() if p.is_dir())
    assert main(["extract", *bursts, "--out", str(out), "--method", "sift", "--h5"]) == 0
    assert (
        main(["extract", str(frames), "--every", "16", "--burst", "1", "--out", str(out), "--method", "sift", "--h5"])
        == 0
    )
    names = check_as_hloc_reads(out)
    assert [n for n in names if "/" not in n] == [f"{Path(b).name}.png" for b in bursts]
    assert len([n for n in names if n.startswith("frames/")]) == 5
