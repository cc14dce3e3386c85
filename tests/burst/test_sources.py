"""Recordings as burst sources: keyframe schedule, edges and dropped frames, streaming, bad files."""

import numpy as np
import pytest

from lburst.burst.io import BurstError, write_image
from lburst.burst.keyframes import MotionGate
from lburst.burst.raw import Normalisation
from lburst.burst.sources import Keyframe, RecordingOptions, is_recording, open_recording


def _frame(value: int, size=(24, 32), dtype=np.uint8) -> np.ndarray:
    return np.full(size + (3,), value, dtype)


def _folder(tmp_path, indices, dtype=np.uint8, scale=10):
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in indices:
        write_image(folder / f"img_{i}.png", _frame(i * scale, dtype=dtype))  # unpadded: natural sort needed
    (folder / "meta.json").write_text('{"fps": 10}')
    return folder


def _values(burst: np.ndarray) -> list[int]:
    return [int(f[0, 0, 0]) for f in burst]


def test_folder_keyframes_edges_and_dropped_frames(tmp_path):
    folder = _folder(tmp_path, [i for i in range(12) if i != 6])  # frame 6 dropped
    assert is_recording(folder)
    rec = open_recording(folder, RecordingOptions(burst=5, every=4))
    got = list(rec.bursts())
    assert [k.index for k, _ in got] == [0, 4, 8]
    (k0, b0), (k4, b4), (k8, b8) = got
    assert k0 == Keyframe(0, 0.0, 2) and k0.name == "f000000_t0.000s"
    assert _values(b0) == [0, 0, 0, 10, 20]  # before the start: the nearest frame there is
    assert _values(b4) == [20, 30, 40, 50, 50] and k4.filled == 1  # frame 6 dropped: its neighbour 5
    assert k8.time == pytest.approx(0.8) and _values(b8) == [70, 70, 80, 90, 100]
    assert all(b.shape == (5, 24, 32, 3) for _, b in got)


def test_dropped_keyframe_is_skipped_and_every_frame_can_be_a_keyframe(tmp_path):
    folder = _folder(tmp_path, [0, 1, 2, 4, 5])
    keys = [k.index for k, _ in open_recording(folder, RecordingOptions(burst=3, every=1)).bursts()]
    assert keys == [0, 1, 2, 4, 5]


def _video(path, n=40, fps=20, size=(48, 64), faststart=False):
    import av

    with av.open(str(path), "w", options={"movflags": "+faststart"} if faststart else {}) as container:
        stream = container.add_stream("libx264", rate=fps)
        stream.height, stream.width = size
        stream.pix_fmt = "yuv444p"
        stream.options = {"crf": "0"}
        for i in range(n):
            frame = av.VideoFrame.from_ndarray(_frame(min(5 * i, 255), size), format="rgb24")
            frame.pts = i
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode(None):
            container.mux(packet)
    return path


def test_video_streams_keyframe_bursts_with_timestamps(tmp_path):
    pytest.importorskip("av")
    video = _video(tmp_path / "v.mp4")
    rec = open_recording(video, RecordingOptions(burst=5, every=8, start=2))
    assert rec.fps == 20 and rec.frame_count == 40
    got = list(rec.bursts())
    assert [k.index for k, _ in got] == [2, 10, 18, 26, 34]
    assert [k.name for k, _ in got][:2] == ["f000002_t0.100s", "f000010_t0.500s"]
    for k, burst in got:  # the burst is frames k-2..k+2, in order
        assert np.allclose(_values(burst), [5 * min(max(i, 0), 39) for i in range(k.index - 2, k.index + 3)], atol=2)


def test_bad_videos_name_the_file_and_keep_finished_keyframes(tmp_path):
    pytest.importorskip("av")
    empty = tmp_path / "empty.mp4"
    empty.write_bytes(b"")
    with pytest.raises(BurstError, match="empty.mp4.*zero-length"):
        open_recording(empty)
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"not a video" * 100)
    with pytest.raises(BurstError, match="junk.mp4"):
        open_recording(junk)
    video = _video(tmp_path / "v.mp4", n=60)
    data = video.read_bytes()
    (tmp_path / "cut.mp4").write_bytes(data[: len(data) * 2 // 3])  # index at the end: nothing to recover
    with pytest.raises(BurstError, match=r"cut.mp4: no video stream found \(a truncated"):
        open_recording(tmp_path / "cut.mp4")
    video = _video(tmp_path / "fast.mp4", n=60, faststart=True)  # index first: the frames before the cut decode
    data = video.read_bytes()
    (tmp_path / "fastcut.mp4").write_bytes(data[: len(data) * 2 // 3])
    done = []
    with pytest.raises(BurstError, match="fastcut.mp4: .*truncated") as err:
        for keyframe, _ in open_recording(tmp_path / "fastcut.mp4", RecordingOptions(burst=3, every=10)).bursts():
            done.append(keyframe.index)
    assert "\n" not in str(err.value)
    assert done and done == list(range(0, 10 * len(done), 10)) and len(done) < 6


def test_mixed_frame_sizes_name_the_frame(tmp_path):
    folder = _folder(tmp_path, range(8))
    write_image(folder / "img_6.png", np.zeros((10, 10, 3), np.uint8))
    done = []
    with pytest.raises(BurstError, match=r"img_6.png.*10x10.*mixed frame sizes"):
        for keyframe, _ in open_recording(folder, RecordingOptions(burst=3, every=3)).bursts():
            done.append(keyframe.index)
    assert done == [0, 3]  # finished before the bad frame


def test_sixteen_bit_frames_get_one_gain_per_recording(tmp_path):
    folder = _folder(tmp_path, range(9), dtype=np.uint16, scale=100)  # very dark linear frames
    rec = open_recording(
        folder, RecordingOptions(burst=3, every=4, normalisation=Normalisation(percentile=100, target=0.5))
    )
    bursts = list(rec.bursts())
    # the first burst is frames 0, 0, 1 (linear 0, 0, 100): its mean, 100 / 3, goes to 0.5
    assert rec.gain == pytest.approx(0.5 * 65535 / (100 / 3))
    assert all(b.dtype == np.uint8 for _, b in bursts)
    # every burst through that one gain: the linear value v of any frame comes out as v * gain (at a target
    # that leaves the brighter later bursts unclipped; a gain of their own would map each burst's mean to it)
    dim = open_recording(
        folder, RecordingOptions(burst=3, every=4, normalisation=Normalisation(percentile=100, target=0.05))
    )
    values = [_values(b) for _, b in dim.bursts()]
    linear_values = [(0, 0, 100), (300, 400, 500), (700, 800, 800)]
    assert values == [[min(255, round(v * dim.gain / 65535 * 255)) for v in b] for b in linear_values]
    assert values == [[0, 0, 38], [115, 153, 191], [255, 255, 255]]
    linear = open_recording(folder, RecordingOptions(burst=3, every=4, normalisation=Normalisation(gain="none")))
    assert all(b.dtype == np.uint16 for _, b in linear.bursts())
    fixed = open_recording(folder, RecordingOptions(burst=3, every=4, normalisation=Normalisation(gain=65535 / 200)))
    assert _values(next(fixed.bursts())[1]) == [0, 0, 128]  # the default curve is linear: 100 -> half of white
    srgb = open_recording(
        folder, RecordingOptions(burst=3, every=4, normalisation=Normalisation(gain=65535 / 200, curve="srgb"))
    )
    assert _values(next(srgb.bursts())[1]) == [0, 0, 188]


def test_gain_measures_the_scene_not_the_noise():
    """A moonless frame: about 6 counts at white over a black level, read noise 4 counts.  The
    99.5th percentile of single noisy pixels is far above white; that of the burst's mean over
    4x4 blocks is near white, so the gain maps white (not the noise peaks) near the target."""
    rng = np.random.default_rng(0)
    white = 6 / 3839  # linear value of the scene's white
    scene = np.full((96, 128), 0.2 * white)
    scene[:, :16] = white  # 1/8 of the frame is white
    counts = rng.poisson(np.broadcast_to(scene / white * 3, (5, 96, 128))) * 2 + rng.normal(0, 4, (5, 96, 128))
    frames = np.clip(counts / 6 * white, 0, None)[..., None].repeat(3, -1)
    burst = np.round(frames * 65535).astype(np.uint16)
    gain = Normalisation(target=0.8).estimate_gain(burst)
    assert 0.6 < gain * white <= 0.8  # white near the target (the mean keeps a little noise)
    noisy = Normalisation(target=0.8, binning=1).estimate_gain(burst[:1])  # single pixels of one frame
    assert noisy * white < 0.35  # the noise peaks go to the target, white far below it


def test_dng_frames_read_linear_and_without_cfa_fail_clearly(tmp_path):
    pytest.importorskip("rawpy")
    tifffile = pytest.importorskip("tifffile")
    from lburst.burst.raw import read_dng
    from lburst.scenes.dng import mosaic, write_dng

    image = np.zeros((32, 48, 3))
    image[..., 0], image[..., 1], image[..., 2] = 0.5, 0.25, 0.125
    black, white = 256, 4095
    write_dng(tmp_path / "a.dng", np.round(black + mosaic(image) * (white - black)).astype(np.uint16), black, white)
    out = read_dng(tmp_path / "a.dng")
    assert out.dtype == np.uint16 and out.shape == (32, 48, 3)
    assert np.allclose(out[8:-8, 8:-8].reshape(-1, 3).mean(0) / 65535, [0.5, 0.25, 0.125], atol=2e-3)
    tifffile.imwrite(tmp_path / "plain.dng", np.zeros((32, 48), np.uint16))  # LibRaw alone would take it
    with pytest.raises(BurstError, match="plain.dng: not a DNG"):
        read_dng(tmp_path / "plain.dng")
    tifffile.imwrite(
        tmp_path / "nocfa.dng", np.zeros((32, 48), np.uint16), extratags=[(50706, 1, 4, (1, 4, 0, 0), True)]
    )
    with pytest.raises(BurstError, match="nocfa.dng: DNG without a CFA image"):
        read_dng(tmp_path / "nocfa.dng")


def test_options_are_checked():
    with pytest.raises(ValueError, match="odd"):
        RecordingOptions(burst=4)
    with pytest.raises(ValueError, match="every"):
        RecordingOptions(every=0)
    with pytest.raises(ValueError, match="gain"):
        Normalisation(gain="bright")
    with pytest.raises(ValueError, match="binning"):
        Normalisation(binning=0)


@pytest.mark.parametrize("suffix", [".png", ".jpg"])
def test_a_still_image_named_as_a_video_is_refused_by_name(tmp_path, suffix):
    """FFmpeg opens a PNG or JPEG renamed .mp4 as a one-frame stream; lburst must say what it is."""
    pytest.importorskip("av")
    write_image(tmp_path / f"still{suffix}", np.zeros((32, 48, 3), np.uint8))
    (tmp_path / "still.mp4").write_bytes((tmp_path / f"still{suffix}").read_bytes())
    with pytest.raises(BurstError, match=r"still.mp4: a still image \((png|jpeg)\), not a video") as err:
        list(open_recording(tmp_path / "still.mp4", RecordingOptions(burst=1, every=1)).bursts())
    assert "\n" not in str(err.value)


def test_a_start_past_the_last_frame_is_an_error_naming_both(tmp_path):
    pytest.importorskip("av")
    video = _video(tmp_path / "v.mp4")  # 40 frames
    assert [k.index for k, _ in open_recording(video, RecordingOptions(burst=5, every=8, start=39)).bursts()] == [39]
    for options in (
        RecordingOptions(burst=5, every=8, start=40),
        RecordingOptions(burst=5, motion=MotionGate(0.1), start=100),
    ):
        with pytest.raises(BurstError, match=r"v.mp4: --start \d+ is past the last frame \(39\)"):
            list(open_recording(video, options).bursts())


@pytest.mark.parametrize("kind", ["dangling", "loop"])
def test_a_broken_frame_link_is_named_not_dropped(tmp_path, kind):
    folder = _folder(tmp_path, range(6))
    link = folder / "f000006.png"
    if kind == "dangling":
        link.symlink_to(tmp_path / "gone.png")
    else:
        link.symlink_to(folder / "f000006.png")
    with pytest.raises(BurstError, match=r"f000006.png: a broken link") as err:
        open_recording(folder, RecordingOptions(burst=3, every=2))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("rotation", [90, -90, 180])
def test_video_rotation_metadata_turns_frames_as_a_player_shows_them(tmp_path, rotation):
    av = pytest.importorskip("av")
    path = tmp_path / "phone.mp4"
    image = np.zeros((32, 64, 3), np.uint8)
    image[:8, :8] = 255  # a white corner, top left as stored
    with av.open(str(path), "w") as out:
        stream = out.add_stream("libx264", rate=10)
        stream.width, stream.height, stream.pix_fmt = 64, 32, "yuv420p"
        stream.set_display_rotation(rotation)
        for _ in range(5):
            for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    (_, burst), *_ = open_recording(path, RecordingOptions(burst=3, every=2)).bursts()
    expected = np.rot90(image, rotation // 90)  # counter-clockwise by the display angle
    assert burst.shape[1:3] == expected.shape[:2]
    corner = np.unravel_index(np.argmax(expected[..., 0]), expected.shape[:2])
    assert burst[1][corner].mean() > 200 and burst[1].mean() < 80


def test_a_recording_that_fails_before_two_keyframes_still_writes_result_json(tmp_path, capsys):
    import json

    from lburst.cli import main

    folder = _folder(tmp_path, range(12))
    (folder / "img_0.png").write_bytes(b"\x89PNG not an image")
    # nothing to reconstruct from (no keyframe read): an input that cannot be used, exit 2
    assert main(["reconstruct", str(folder), "--method", "sift", "--every", "4", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("lburst reconstruct: error: ") and "img_0.png: not a readable image" in err[-1], err
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["status"] == "source_failed" and result["registered"] == []
    assert "img_0.png" in result["error"] and "no model" in result["error"]


def test_a_frame_folder_without_a_frame_rate_says_it_is_timed_at_30_fps(tmp_path):
    import warnings

    folder = _folder(tmp_path, range(6))
    (folder / "meta.json").unlink()
    options = RecordingOptions(burst=1, every=2, frame_folders=True)
    with pytest.warns(UserWarning, match=r"frames: no frame rate \(--fps, or \"fps\" in meta.json\): .* at 30 fps"):
        rec = open_recording(folder, options)
    assert [k.time for k, _ in rec.bursts()] == pytest.approx([0, 2 / 30, 4 / 30])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # given a rate: no word
        open_recording(folder, RecordingOptions(burst=1, every=2, fps=20, frame_folders=True))
        (folder / "meta.json").write_text('{"fps": 10}')
        open_recording(folder, options)
