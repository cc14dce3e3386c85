"""A full disk while writing an output is one line naming the file and the disk, and leaves no
temporary file: features.h5 (h5py tracebacks, then a segmentation fault, and the temporary h5
left behind) and images/*.png ('40229 requested and 28672 written').  Simulated by a file
object that stops writing, and on a real, tiny tmpfs where this process may mount one."""

import errno
import io
import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest

import lburst.burst.io as burst_io
from lburst import store
from lburst.burst.io import atomic_path, h5_file, save_burst, write_features_h5, write_image
from lburst.cli import error_line, main

DISK_FULL = "No space left on device: the disk mounted at "


@pytest.fixture
def disk_holds(monkeypatch):
    """``disk_holds(n)``: files that lburst.burst.io opens for writing take ``n`` bytes, then
    fail as a full disk does (``OSError`` ENOSPC)."""

    def limit(room: int) -> None:
        left = [room]

        class FullDisk(io.FileIO):
            def write(self, data) -> int:
                size = memoryview(data).nbytes
                if size > left[0]:
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                left[0] -= size
                return super().write(data)

        def opened(path, mode="r", *args, **kwargs):
            if not any(c in mode for c in "wax+"):
                return open(path, mode, *args, **kwargs)
            raw = FullDisk(path, mode.replace("b", "").replace("t", ""))
            return io.BufferedRandom(raw) if "+" in mode else io.BufferedWriter(raw)

        monkeypatch.setattr(burst_io, "open", opened, raising=False)

    return limit


def _features(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    return {
        "keypoints": rng.uniform(0, 600, (n, 2)).astype(np.float32),
        "scales": np.ones(n, np.float32),
        "scores": rng.random(n).astype(np.float32),
        "descriptors": rng.normal(size=(n, 128)).astype(np.float32),
        "image_size": np.array([640, 480]),
    }


@pytest.mark.parametrize("room", [0, 900, 20_000, 400_000, 1_500_000])
def test_features_h5_on_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, disk_holds, room):
    disk_holds(room)
    with pytest.raises(OSError) as err:
        with atomic_path(tmp_path / "features.h5") as tmp:
            with h5_file(tmp, "w"):
                pass
            for name in ("a.png", "b.png"):
                write_features_h5(tmp, name, _features())
    line = error_line(err.value)
    assert line.startswith(f"{tmp_path / 'features.h5'}: {DISK_FULL}") and "\n" not in line, line
    assert list(tmp_path.iterdir()) == []


def test_an_image_on_a_full_disk_names_the_disk_and_leaves_no_part(tmp_path, disk_holds):
    disk_holds(5000)
    image = np.random.default_rng(0).integers(0, 256, (200, 300, 3), dtype=np.uint8)
    with pytest.raises(OSError) as err:
        write_image(tmp_path / "a.png", image)
    assert error_line(err.value).startswith(f"{tmp_path / 'a.png'}: {DISK_FULL}")
    assert err.value.errno == errno.ENOSPC and list(tmp_path.iterdir()) == []
    with pytest.raises(OSError) as err:
        save_burst(image[None], tmp_path / "burst")
    assert error_line(err.value).startswith(f"{tmp_path / 'burst' / 'frame_000.png'}: {DISK_FULL}")


def test_a_features_npz_on_a_full_disk_names_the_disk_and_leaves_nothing(tmp_path, disk_holds):
    disk_holds(20_000)
    with pytest.raises(OSError) as err:
        store.save(tmp_path / "b0.npz", _features(), None, key={"method": "m", "source": "s"})
    assert error_line(err.value).startswith(f"{tmp_path / 'b0.npz'}: {DISK_FULL}")
    assert list(tmp_path.iterdir()) == []


def test_the_disk_named_is_the_mount_point_holding_the_file(tmp_path):
    error = burst_io.disk_full(tmp_path / "sub" / "features.h5")
    mount = Path(str(error).split("the disk mounted at ")[1].split(" has ")[0])
    assert os.path.ismount(mount) and (tmp_path == mount or mount in tmp_path.parents)


# --------------------------------------------------------------------------- a real full disk


@pytest.fixture
def tiny_disk(tmp_path):
    """A 4 MiB tmpfs, where this process may mount one (root on Linux); else the test skips."""
    if sys.platform != "linux" or shutil.which("mount") is None or os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root on Linux")
    mount = tmp_path / f"disk-{uuid.uuid4().hex[:8]}"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mount)], capture_output=True)
    if made.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {made.stderr.decode().strip()}")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], check=False)


def _fill(disk: Path, leave: int) -> None:
    """Fill ``disk`` up to ``leave`` bytes free."""
    free = shutil.disk_usage(disk).free
    with open(disk / "filler", "wb") as f:
        f.write(b"\0" * max(0, free - leave))


def _extract(*args) -> subprocess.CompletedProcess:
    code = "import sys; from lburst.cli import main; sys.exit(main(sys.argv[1:]))"
    env = {**os.environ, "LBURST_TRACEBACK": ""}
    return subprocess.run(
        [sys.executable, "-c", code, "extract", *map(str, args)], capture_output=True, text=True, env=env
    )


def test_extract_h5_on_a_real_full_disk(tmp_path, tiny_disk, capsys):
    """The --h5 run in a child process: HDF5's own driver crashed the process (exit 139)."""
    rng = np.random.default_rng(1)
    texture = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8).repeat(4, 0).repeat(4, 1)
    save_burst(np.stack([texture] * 3), tmp_path / "b0")
    out = tiny_disk / "out"
    args = [tmp_path / "b0", "--out", out, "--method", "sift"]
    assert main(["extract", *map(str, args)]) == 0  # the .npz and images/b0.png; then the disk fills
    _fill(tiny_disk, 16 << 10)
    proc = _extract(*args, "--h5")
    lines = [line for line in proc.stderr.splitlines() if "error" in line]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert f"{out / 'features.h5'}: {DISK_FULL}{tiny_disk} has" in lines[0]
    assert sorted(p.name for p in out.iterdir()) == ["b0.npz", "images"]  # no temporary h5


def test_an_image_on_a_real_full_disk(tiny_disk):
    _fill(tiny_disk, 16 << 10)
    image = np.random.default_rng(0).integers(0, 256, (300, 400, 3), dtype=np.uint8)
    with pytest.raises(OSError) as err:
        with atomic_path(tiny_disk / "images" / "a.png") as tmp:
            write_image(tmp, image)
    assert error_line(err.value).startswith(f"{tiny_disk / 'images' / 'a.png'}: {DISK_FULL}{tiny_disk} has")
    assert list((tiny_disk / "images").iterdir()) == []
