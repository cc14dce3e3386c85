"""Reading bursts (every error names the file) and writing features."""

import os
import stat

import cv2
import h5py
import numpy as np
import pytest

from lburst.burst.io import BurstError, load_burst, read_features_npz, save_burst, write_features_h5, write_features_npz


def _frames(n, h=24, w=32, dtype=np.uint8, seed=0):
    top = np.iinfo(dtype).max
    return np.random.default_rng(seed).integers(0, top, (n, h, w, 3), dtype=dtype)


def test_folder_round_trip_in_natural_order(tmp_path):
    burst = _frames(5)
    for i, frame in enumerate(burst):  # names whose plain sort would be wrong: f10 < f2
        cv2.imwrite(str(tmp_path / f"f{[2, 10, 11, 100, 1000][i]}.png"), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    np.testing.assert_array_equal(load_burst(tmp_path), burst)


def test_save_burst_and_16_bit(tmp_path):
    burst = _frames(3, dtype=np.uint16)
    save_burst(burst, tmp_path / "b")
    loaded = load_burst(tmp_path / "b")
    assert loaded.dtype == np.uint16
    np.testing.assert_array_equal(loaded, burst)


def test_list_single_image_and_grayscale(tmp_path):
    gray = _frames(1)[0, ..., 0]
    cv2.imwrite(str(tmp_path / "g.png"), gray)
    single = load_burst(tmp_path / "g.png")
    assert single.shape == (1, 24, 32, 3) and (single[0, ..., 1] == gray).all()
    paths = []
    for i, frame in enumerate(_frames(3, seed=1)):
        paths.append(tmp_path / f"z{i}.png")
        cv2.imwrite(str(paths[-1]), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    np.testing.assert_array_equal(load_burst(paths[::-1])[0], load_burst(paths[2])[0])  # the given order


def test_video_with_a_frame_range(tmp_path):
    path = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (32, 24))
    if not writer.isOpened():
        pytest.skip("no video codec available")
    frames = [np.full((24, 32, 3), 40 * i, np.uint8) for i in range(6)]
    for frame in frames:
        writer.write(frame)
    writer.release()
    burst = load_burst(path, frames=(1, 4))
    assert burst.shape == (3, 24, 32, 3)
    np.testing.assert_allclose(burst.mean(axis=(1, 2, 3)), [40, 80, 120], atol=3)
    with pytest.raises(BurstError, match="v.avi: frame range 2..9 outside"):
        load_burst(path, frames=(2, 9))


def test_errors_name_the_file_and_the_problem(tmp_path):
    with pytest.raises(BurstError, match="empty folder"):
        (tmp_path / "empty").mkdir()
        load_burst(tmp_path / "empty")
    with pytest.raises(BurstError, match="missing: no such file"):
        load_burst(tmp_path / "missing")
    even = tmp_path / "even"
    save_burst(_frames(4), even)
    with pytest.raises(BurstError, match="even: 4 frames; a burst needs an odd number"):
        load_burst(even)
    sizes = tmp_path / "sizes"
    save_burst(_frames(3), sizes)
    cv2.imwrite(str(sizes / "frame_001.png"), np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(BurstError, match="frame_001.png: size 10x10 differs from the first frame's 32x24"):
        load_burst(sizes)
    corrupt = tmp_path / "corrupt"
    save_burst(_frames(3), corrupt)
    (corrupt / "frame_002.png").write_bytes(b"\x89PNG garbage")
    with pytest.raises(BurstError, match="frame_002.png: not a readable image"):
        load_burst(corrupt)
    truncated = tmp_path / "truncated.jpg"
    ok, data = cv2.imencode(".jpg", _frames(1)[0])
    truncated.write_bytes(data.tobytes()[:20])
    with pytest.raises(BurstError, match="truncated.jpg"):
        load_burst(truncated)


def test_features_npz_and_h5(tmp_path):
    rng = np.random.default_rng(0)
    feats = {
        "keypoints": rng.uniform(0, 30, (7, 2)).astype(np.float32),
        "scales": np.full(7, 32.0, np.float32),
        "scores": rng.uniform(0, 1, 7).astype(np.float32),
        "descriptors": rng.normal(size=(7, 128)).astype(np.float32),
    }
    write_features_npz(tmp_path / "a.npz", feats, (32, 24))
    back = read_features_npz(tmp_path / "a.npz")
    for key in feats:
        np.testing.assert_array_equal(back[key], feats[key])
    with np.load(tmp_path / "a.npz") as raw:
        assert raw["keypoints"].shape == (7, 3) and tuple(raw["imsize"]) == (32, 24)
    write_features_h5(tmp_path / "f.h5", "img", feats, (32, 24))
    write_features_h5(tmp_path / "f.h5", "img", feats, (32, 24))  # replaces, no error
    with h5py.File(tmp_path / "f.h5") as f:
        np.testing.assert_array_equal(f["img/keypoints"][()], feats["keypoints"])
        assert f["img/descriptors"].shape == (128, 7)
        assert tuple(f["img/image_size"][()]) == (32, 24)


def test_atomic_writes_get_the_usual_permissions_and_leave_nothing_on_failure(tmp_path):
    from lburst.burst.io import atomic_path

    old = os.umask(0o022)
    try:
        with atomic_path(tmp_path / "a.bin") as tmp:
            tmp.write_bytes(b"x")  # written in place, as torch.save and h5py do
        assert stat.S_IMODE((tmp_path / "a.bin").stat().st_mode) == 0o644  # not mkstemp's 0o600
        with pytest.raises(RuntimeError), atomic_path(tmp_path / "a.bin") as tmp:
            tmp.write_bytes(b"partial")
            raise RuntimeError("crash")
    finally:
        os.umask(old)
    assert (tmp_path / "a.bin").read_bytes() == b"x" and sorted(p.name for p in tmp_path.iterdir()) == ["a.bin"]
