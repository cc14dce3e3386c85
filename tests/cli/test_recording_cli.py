"""The command line on recordings: simulate flight --video/--dng, extract and show on them."""

import json

import numpy as np
import pytest

from lburst.burst.io import read_features_npz
from lburst.cli import main

pytest.importorskip("av")


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli")
    assert (
        main(
            [
                "simulate",
                "flight",
                "--video",
                str(out / "f.mp4"),
                "--dng",
                str(out / "f_dng"),
                "--bursts",
                "2",
                "--size",
                "128x96",
                "--noise",
                "lowlight:night",
                "--loop",
            ]
        )
        == 0
    )
    return out


def test_simulate_writes_video_dng_and_ground_truth(recordings):
    meta = json.loads((recordings / "f.meta.json").read_text())
    assert meta["fps"] == 20 and meta["frames"] == 33 and meta["night_flight"]["turn_deg"] == 380
    assert len((recordings / "f.gt.txt").read_text().splitlines()) == 33 + 2  # two comment lines
    assert len(list((recordings / "f_dng").glob("frame_*.dng"))) == 33
    assert (recordings / "f_dng" / "gt.txt").is_file() and (recordings / "f_dng" / "meta.json").is_file()


def test_extract_and_show_take_recordings(recordings, tmp_path, capsys):
    out = tmp_path / "feats"
    assert (
        main(
            [
                "extract",
                str(recordings / "f.mp4"),
                str(recordings / "f_dng"),
                "--every",
                "16",
                "--method",
                "orb",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    for name in ("f", "f_dng"):
        files = sorted(p.name for p in (out / name).glob("*.npz"))
        assert files == ["f000000_t0.000s.npz", "f000016_t0.800s.npz", "f000032_t1.600s.npz"]
        assert len(read_features_npz(out / name / files[1])["keypoints"]) > 0
    png = tmp_path / "show.png"
    assert main(["show", str(recordings / "f_dng"), "--frame", "16", "--out", str(png)]) == 0
    assert png.stat().st_size > 0


def test_extract_reports_a_bad_recording_by_name(tmp_path, capsys):
    bad = tmp_path / "zero.mp4"
    bad.write_bytes(b"")
    assert main(["extract", str(bad), "--every", "4", "--method", "orb", "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert "zero.mp4: empty file (zero-length video)" in err


def test_raw_gain_matters_on_dark_dng(recordings):
    from lburst.burst.raw import Normalisation
    from lburst.burst.sources import RecordingOptions, open_recording

    auto = next(open_recording(recordings / "f_dng", RecordingOptions(burst=3)).bursts())[1]
    linear = next(
        open_recording(
            recordings / "f_dng", RecordingOptions(burst=3, normalisation=Normalisation(gain="none"))
        ).bursts()
    )[1]
    assert linear.dtype == np.uint16 and linear.mean() / 65535 < 0.05  # a dark RAW frame
    assert auto.dtype == np.uint8 and 40 < auto.mean() < 200


def _raw_video(path, frames=100, size=(96, 128)):
    """An uncompressed AVI (rawvideo, > 2 MiB) of a textured image panning right, so that
    bytes changed in its middle change the pixels of middle frames only."""
    import av
    import skimage.data

    texture = skimage.data.astronaut()[::2, ::2]
    with av.open(str(path), "w") as container:
        stream = container.add_stream("rawvideo", rate=20)
        stream.width, stream.height, stream.pix_fmt = size[1], size[0], "bgr24"
        for k in range(frames):
            image = np.ascontiguousarray(texture[50 : 50 + size[0], k : k + size[1]])
            container.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
        container.mux(stream.encode())


def test_a_video_changed_in_its_middle_is_extracted_again(tmp_path):
    video = tmp_path / "v.avi"
    _raw_video(video)
    size = video.stat().st_size
    assert size > 3 << 20  # the middle lies outside the first and last MiB
    args = ["--every", "10", "--method", "orb", "--out"]
    assert main(["extract", str(video), *args, str(tmp_path / "out")]) == 0
    names = sorted(p.name for p in (tmp_path / "out" / "v").glob("*.npz"))
    before = {name: read_features_npz(tmp_path / "out" / "v" / name) for name in names}
    data = bytearray(video.read_bytes())
    frame = data.index(b"00dc", size // 2) + 8  # the pixels of the frame after the middle byte (an AVI chunk)
    data[frame : frame + 30000] = bytes(255 - b for b in data[frame : frame + 30000])
    video.write_bytes(bytes(data))  # same size, same first and last MiB
    assert main(["extract", str(video), *args, str(tmp_path / "out")]) == 0
    assert main(["extract", str(video), *args, str(tmp_path / "fresh")]) == 0
    assert sorted(p.name for p in (tmp_path / "fresh" / "v").glob("*.npz")) == names and len(names) == 10
    changed = []
    for name in names:
        rerun, fresh = (read_features_npz(tmp_path / d / "v" / name) for d in ("out", "fresh"))
        assert rerun.keys() == fresh.keys()
        for key in fresh:
            np.testing.assert_array_equal(rerun[key], fresh[key], err_msg=f"{name}: {key}")
        if any(not np.array_equal(fresh[key], before[name][key]) for key in fresh):
            changed.append(name)
    assert changed and len(changed) < len(names)  # the middle keyframes changed, the others did not


def test_a_frame_folder_with_a_frame_rewritten_at_the_same_size_is_extracted_again(tmp_path):
    import cv2
    import skimage.data

    folder = tmp_path / "rec"
    folder.mkdir()
    (folder / "meta.json").write_text(json.dumps({"fps": 20}))
    texture = skimage.data.astronaut()[::2, ::2]
    for k in range(9):
        cv2.imwrite(str(folder / f"frame_{k:03d}.ppm"), texture[50:146, 3 * k : 3 * k + 128, ::-1])
    args = ["--every", "4", "--burst", "3", "--method", "orb", "--out"]
    assert main(["extract", str(folder), *args, str(tmp_path / "out")]) == 0
    before = read_features_npz(tmp_path / "out" / "rec" / "f000004_t0.200s.npz")
    frame = folder / "frame_004.ppm"
    size = frame.stat().st_size
    cv2.imwrite(str(frame), np.ascontiguousarray(texture[50:146, 12:140][::-1, ::-1, ::-1]))  # upside down
    assert frame.stat().st_size == size
    assert main(["extract", str(folder), *args, str(tmp_path / "out")]) == 0
    after = read_features_npz(tmp_path / "out" / "rec" / "f000004_t0.200s.npz")
    assert not np.array_equal(before["keypoints"], after["keypoints"])
    assert main(["extract", str(folder), *args, str(tmp_path / "fresh")]) == 0
    fresh = read_features_npz(tmp_path / "fresh" / "rec" / "f000004_t0.200s.npz")
    np.testing.assert_array_equal(after["keypoints"], fresh["keypoints"])


def test_extract_takes_keyframes_by_motion(recordings, tmp_path, capsys):
    args = ["extract", str(recordings / "f.mp4"), "--method", "orb", "--out", str(tmp_path / "m")]
    assert main([*args, "--motion", "0.1", "--every", "4"]) == 2
    assert "give --every or --motion, not both" in capsys.readouterr().err
    assert main([*args, "--motion", "0.1"]) == 0
    keys = sorted(int(p.name[1:7]) for p in (tmp_path / "m" / "f").glob("*.npz"))
    assert keys[0] == 0 and 2 <= len(keys) < 33, keys  # a turning camera: keyframes, but not every frame


def test_a_second_cut_of_a_recording_is_listed_and_the_first_is_named_not_mixed_in(recordings, tmp_path, capsys):
    import h5py

    out = tmp_path / "cuts"
    args = ["extract", str(recordings / "f.mp4"), "--method", "orb", "--out", str(out), "--h5"]
    assert main([*args, "--every", "8"]) == 0
    assert main([*args, "--every", "16"]) == 0
    said = capsys.readouterr().out
    cut = json.loads((out / "f" / "cut.json").read_text())
    assert cut["keyframes"] == ["f000000_t0.000s", "f000016_t0.800s", "f000032_t1.600s"]
    assert "every=16" in cut["options"]
    assert "2 keyframes of an earlier cut stay in" in said  # frames 8 and 24
    assert len(list((out / "f").glob("*.npz"))) == 5
    with h5py.File(out / "features.h5") as h5:
        assert sorted(h5["f"].keys()) == [f"{name}.png" for name in cut["keyframes"]]  # as out/images/f/
