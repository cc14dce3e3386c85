"""Reading bursts and writing results safely."""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import shutil
import struct
import tempfile
import warnings
from pathlib import Path
from typing import Iterator, Sequence

import cv2
import numpy as np

from lburst.errors import LBurstOSError, LBurstValueError
from lburst.memory import check_memory


def file_sha1(path: str | Path) -> str:
    """Hex SHA-1 of a file's bytes."""
    digest = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success.

    A crash or exception leaves any earlier ``path`` untouched and no partial file; the
    temporary file of a writer that was killed is removed by the next write of ``path``
    (its name holds the writer's pid).  The file gets the permissions a plain
    ``open(path, "w")`` would give (``mkstemp`` makes it owner-only).  An ``OSError`` of
    the write (a read-only folder, a full disk) names ``path``.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(path)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp" + path.suffix)
    except OSError as exc:
        raise _naming(exc, path) from exc
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        try:
            yield tmp_path
            if tmp_path.exists():
                os.chmod(tmp_path, 0o666 & ~_umask())
            os.replace(tmp_path, path)
        except OSError as exc:
            if exc.filename is None or os.fsdecode(exc.filename) == tmp:
                raise _naming(exc, path) from exc
            raise
    finally:
        if tmp_path.is_dir():
            shutil.rmtree(tmp_path, ignore_errors=True)
        elif tmp_path.exists():
            tmp_path.unlink()


def _naming(exc: OSError, path: Path) -> OSError:
    """``exc`` again, naming ``path`` (the file being written) instead of a temporary name, and
    for a full disk the disk (:func:`disk_full`)."""
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return disk_full(path, exc.errno)
    return OSError(exc.errno, exc.strerror or str(exc), os.fspath(path))


def disk_full(path: str | Path, code: int = errno.ENOSPC) -> LBurstOSError:
    """The error of a write of ``path`` that found its disk full (or its quota spent), naming the
    file, the disk (its mount point) and the space left there: ``PATH: No space left on device:
    the disk mounted at /data has 0.1 MiB free; free some space there, or write elsewhere``."""
    folder = Path(os.path.abspath(path)).parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    mount = folder
    while not os.path.ismount(mount) and mount != mount.parent:
        mount = mount.parent
    try:
        free = f"has {shutil.disk_usage(folder).free / 2**20:.1f} MiB free"
    except OSError:
        free = "is full"
    return LBurstOSError(
        code,
        f"{os.strerror(code)}: the disk mounted at {mount} {free}; free some space there, or write elsewhere",
        os.fspath(path),
    )


def remove_stale_temporaries(path: str | Path) -> list[Path]:
    """Remove the temporary files that :func:`atomic_path` left for ``path`` in processes
    that are gone (killed while writing); returns what was removed."""
    import glob

    path = Path(path)
    removed = []
    for found in glob.glob(glob.escape(os.fspath(path.parent / f".{path.name}.")) + "*.*.tmp*"):
        pid = Path(found).name[len(path.name) + 2 :].split(".", 1)[0]
        if not pid.isdigit() or _alive(int(pid)):
            continue
        with contextlib.suppress(OSError):
            if os.path.isdir(found):
                shutil.rmtree(found)
            else:
                os.unlink(found)
            removed.append(Path(found))
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


class BurstError(LBurstValueError):
    """A burst that cannot be read; the message names the file and the problem."""


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".ppm", ".pgm", ".pnm", ".webp")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg")


def check_output_outside(out: str | Path, inputs: Sequence[str | Path]) -> None:
    """``ValueError`` when the output folder ``out`` is, or is inside, an input folder: a
    second run would read the first run's outputs as input (``reconstruct S --out S`` took
    ``S/images/`` for a burst; ``extract B --out B`` recomputed every time)."""
    target = Path(os.path.abspath(out))
    for source in inputs:
        folder = Path(os.path.abspath(source))
        if folder.is_dir() and (target == folder or folder in target.parents):
            raise LBurstValueError(
                f"{out}: the output folder is {'' if target == folder else 'inside '}the input {source}; choose one outside it"
            )


def natural_key(name: str) -> list:
    """Sort key that orders ``f2`` before ``f10``."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def opencv_path(path: str | Path) -> str:
    """``path`` as the str that OpenCV (or pycolmap) takes: ``BurstError`` for a name that is
    not valid UTF-8 (OpenCV crashes the process on one).  Images are read and written
    through bytes (:func:`decode_file`, :func:`write_image`) and need no such check."""
    text = str(path)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise BurstError(
            f"{text.encode('utf-8', 'backslashreplace').decode()}: the name is not valid UTF-8, "
            f"which OpenCV cannot open; rename it"
        ) from None
    return text


#: bytes per pixel that decoding an image holds at its peak: OpenCV's image (up to four 16-bit
#: channels) and its RGB copy
DECODE_BYTES_PER_PIXEL = 16
#: bytes per pixel of a decoded frame kept in a burst (three channels, up to 16 bits)
FRAME_BYTES_PER_PIXEL = 6
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def header_size(path: str | Path) -> tuple[int, int] | None:
    """An image file's (width, height) from its header, without decoding it (a PNG's IHDR, else
    PIL, which reads no further than the header); ``None`` when neither knows the file (OpenCV then
    decides).  ``BurstError`` for an image that PIL refuses as a decompression bomb (over 179 M pixels)."""
    try:
        with open(path, "rb") as f:
            head = f.read(24)
    except OSError:
        return None
    if len(head) == 24 and head[:8] == _PNG_SIGNATURE and head[12:16] == b"IHDR":  # one cut inside it: OpenCV decides
        width, height = struct.unpack(">II", head[16:24])
        return int(width), int(height)
    try:
        from PIL import Image
    except ImportError:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            with Image.open(path) as image:
                return image.size
        except Image.DecompressionBombError as exc:  # PIL's message gives the pixels, not the size
            pixels = re.search(r"\((\d+) pixels\)", str(exc))
            many = f"{int(pixels.group(1)) / 1e6:.0f} million pixels" if pixels else "too many pixels"
            raise BurstError(f"{path}: {many}, more than PIL reads (179 million); resize it") from None
        except (OSError, ValueError, SyntaxError, EOFError, IndexError, struct.error):
            return None


def check_frames_memory(paths: Sequence[str | Path]) -> None:
    """``BurstError`` before any decoding when the images ``paths`` of a burst (their header sizes,
    :func:`header_size`), held together, with the decoding of one, would need more than half of the
    machine's memory (a 600 kB PNG can hold 25000x25000 pixels)."""
    sizes = [s for s in (header_size(p) for p in paths) if s is not None]
    if not sizes:
        return
    largest = max(w * h for w, h in sizes)
    need = sum(w * h for w, h in sizes) * FRAME_BYTES_PER_PIXEL + largest * DECODE_BYTES_PER_PIXEL
    (w, h), first = sizes[0], Path(paths[0])
    what = f"{first}: a {w}x{h} image" if len(paths) == 1 else f"{first.parent}: {len(paths)} frames of {w}x{h}"
    try:
        check_memory(need, what, "resize the images")
    except ValueError as exc:
        raise BurstError(str(exc)) from None


def decode_file(path: str | Path, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray | None:
    """The image in file ``path`` as OpenCV decodes it (BGR), or ``None`` if it cannot be decoded.

    The file is read as bytes, so any file name works (``cv2.imread`` crashes on names
    that are not valid UTF-8).  A JPEG without its end marker (a truncated file, which
    libjpeg would fill with grey) counts as undecodable."""
    data = np.fromfile(path, np.uint8)
    if data.size == 0:
        return None
    if data[:2].tobytes() == b"\xff\xd8" and not _jpeg_complete(data.tobytes()):
        return None
    return cv2.imdecode(data, flags)


def _jpeg_complete(data: bytes) -> bool:
    """True when the last scan of a JPEG is followed by its end-of-image marker (entropy-coded
    data cannot hold ``FF D9``: a coded ``FF`` is always followed by ``00``)."""
    scan = data.rfind(b"\xff\xda")
    return scan >= 0 and data.find(b"\xff\xd9", scan) >= 0


def write_image(path: str | Path, rgb: np.ndarray) -> None:
    """Write an RGB (or grayscale) uint8/uint16 image; the format is ``path``'s suffix.

    Encoded in memory and written as bytes, so any file name works; ``OSError`` naming
    the file when it cannot be encoded or written."""
    path = Path(path)
    image = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR) if rgb.ndim == 3 else rgb
    ok, data = cv2.imencode(path.suffix or ".png", image)
    if not ok:
        raise LBurstOSError(f"{path}: could not encode a {rgb.dtype} {rgb.shape} image as {path.suffix or '.png'}")
    try:
        with open(path, "wb") as f:  # NumPy's tofile said only '40229 requested and 28672 written' on a full disk
            f.write(data)
    except OSError as exc:
        with contextlib.suppress(OSError):
            path.unlink()  # what was written of it
        raise _naming(exc, path) from None


def read_image(path: str | Path) -> np.ndarray:
    """An image file as RGB ``(H, W, 3)`` uint8 or uint16 (grayscale repeated, alpha dropped)."""
    path = Path(path)
    if not path.is_file():
        raise BurstError(f"{path}: no such file")
    check_frames_memory([path])
    image = decode_file(path)
    if image is None:
        raise BurstError(f"{path}: not a readable image (corrupt, truncated or unsupported format)")
    if image.dtype not in (np.uint8, np.uint16):
        raise BurstError(f"{path}: unsupported pixel type {image.dtype} (use 8 or 16 bit)")
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    elif image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    elif image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    else:
        raise BurstError(f"{path}: {image.shape[2]} channels (expected 1, 3 or 4)")
    return image


def _read_video(path: Path, frames: slice | tuple[int, int] | None) -> list[np.ndarray]:
    capture = cv2.VideoCapture(opencv_path(path))
    if not capture.isOpened():
        raise BurstError(f"{path}: not a readable video")
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    start, stop = (
        (0, count) if frames is None else (frames.start or 0, frames.stop) if isinstance(frames, slice) else frames
    )
    stop = count if stop is None else stop
    if not 0 <= start < stop <= count:
        capture.release()
        raise BurstError(f"{path}: frame range {start}..{stop} outside the video's {count} frames")
    capture.set(cv2.CAP_PROP_POS_FRAMES, start)
    out = []
    for index in range(start, stop):
        ok, frame = capture.read()
        if not ok:
            capture.release()
            raise BurstError(f"{path}: could not decode frame {index}")
        out.append(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
    capture.release()
    return out


def burst_files(path: str | Path) -> list[Path]:
    """The frame files of a burst folder, naturally sorted; error if there are none."""
    folder = Path(path)
    files = sorted(
        (p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".")),
        key=lambda p: natural_key(p.name),
    )
    if not files:
        raise BurstError(f"{folder}: empty folder (no {', '.join(IMAGE_SUFFIXES)} frames)")
    return files


def load_burst(source: str | Path | Sequence[str | Path], frames: slice | tuple[int, int] | None = None) -> np.ndarray:
    """Read a burst as ``(N, H, W, 3)`` uint8 or uint16 RGB, in temporal order.

    ``source`` is a folder of frames (sorted naturally: ``f2`` before ``f10``), a list of
    frame files (in the given order), one image (N = 1) or a video file (``frames``
    picks a range ``(start, stop)``, stop exclusive).  N must be odd and all frames
    must share one size and dtype; any problem raises :class:`BurstError` naming the
    file.
    """
    if isinstance(source, (list, tuple)):
        if not source:
            raise BurstError("empty list of frames")
        paths = [Path(p) for p in source]
        check_frames_memory(paths)
        images = [read_image(p) for p in paths]
    else:
        path = Path(source)
        if path.is_dir():
            paths = burst_files(path)
            check_frames_memory(paths)
            images = [read_image(p) for p in paths]
        elif path.suffix.lower() in VIDEO_SUFFIXES:
            if not path.is_file():
                raise BurstError(f"{path}: no such file")
            images = _read_video(path, frames)
            paths = [path] * len(images)
        elif path.exists():
            paths, images = [path], [read_image(path)]
        else:
            raise BurstError(f"{path}: no such file or folder")
    first = images[0]
    for p, image in zip(paths, images):
        if image.shape != first.shape:
            raise BurstError(
                f"{p}: size {image.shape[1]}x{image.shape[0]} differs from the first frame's "
                f"{first.shape[1]}x{first.shape[0]} ({paths[0]})"
            )
        if image.dtype != first.dtype:
            raise BurstError(f"{p}: {image.dtype} differs from the first frame's {first.dtype}")
    if len(images) % 2 == 0:
        where = paths[0].parent if len(set(paths)) > 1 else paths[0]
        raise BurstError(
            f"{where}: {len(images)} frames; a burst needs an odd number (the middle one is the common frame)"
        )
    return np.stack(images)


def frame_name(k: int) -> str:
    """The file name of frame ``k`` (0-based, temporal order) of a burst folder: ``frame_000.png``."""
    return f"frame_{k:03d}.png"


def save_burst(burst: np.ndarray, folder: str | Path, whole: bool = False) -> list[Path]:
    """Write a burst's frames as ``folder/frame_000.png ...`` (8 or 16 bit PNG), atomically each.

    ``whole``: write the folder at once instead: the frames go into a temporary folder
    next to it, which then replaces ``folder`` (and whatever it held), so a burst folder
    that exists is complete (scenes count a burst as done when its folder exists)."""
    folder = Path(folder)
    if whole:
        folder.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}.", suffix=".tmp"))
        try:
            for k, frame in enumerate(burst):
                write_image(tmp / frame_name(k), frame)
            shutil.rmtree(folder, ignore_errors=True)
            os.replace(tmp, folder)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return [folder / frame_name(k) for k in range(len(burst))]
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, frame in enumerate(burst):
        path = folder / frame_name(i)
        with atomic_path(path) as tmp:
            write_image(tmp, frame)
        paths.append(path)
    return paths


def to_uint8(image: np.ndarray) -> np.ndarray:
    """A uint8 or uint16 image (any shape) as uint8: uint16 scaled by 255/65535 and rounded."""
    if image.dtype == np.uint16:
        return np.clip(np.rint(image * (255.0 / 65535.0)), 0, 255).astype(np.uint8)
    return image


def features_image_size(features: dict[str, np.ndarray], image_size: tuple[int, int] | None) -> tuple[int, int]:
    """The (W, H) to store with ``features``: ``image_size``, else the features' own
    ``image_size``; ``ValueError`` when neither is there or the two differ."""
    own = features.get("image_size")
    own = None if own is None else (int(own[0]), int(own[1]))
    if image_size is None and own is None:
        raise LBurstValueError("the image size (W, H) is needed: the features have no image_size")
    if image_size is not None and own is not None and tuple(int(v) for v in image_size) != own:
        raise LBurstValueError(f"image size {tuple(image_size)} differs from the features' image_size {own}")
    return own if image_size is None else (int(image_size[0]), int(image_size[1]))


def write_features_npz(
    path: str | Path,
    features: dict[str, np.ndarray],
    image_size: tuple[int, int] | None = None,
    meta: dict | None = None,
) -> Path:
    """``.npz`` with ``keypoints`` (K, 3) x, y, scale (pixel centres at integer coordinates),
    ``descriptors`` (K, D), ``scores`` (K,) and ``imsize`` (W, H) (``image_size``, by default
    the features' own, stored once as ``imsize``), and ``meta`` as a JSON string ``_meta``
    (see :mod:`lburst.store`); written atomically."""
    import json

    path = Path(path)
    image_size = features_image_size(features, image_size)
    keypoints = np.concatenate([features["keypoints"], features["scales"][:, None]], 1).astype(np.float32)
    stored_apart = ("keypoints", "scales", "descriptors", "scores", "image_size", "imsize")
    extra = {k: v for k, v in features.items() if k not in stored_apart}
    if meta is not None:
        extra["_meta"] = np.array(json.dumps(meta, ensure_ascii=True))
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(
            f,
            keypoints=keypoints,
            descriptors=features["descriptors"],
            scores=features["scores"],
            imsize=np.array(image_size, np.int32),
            **extra,
        )
    return path


def read_features_npz(path: str | Path) -> dict[str, np.ndarray]:
    """Features written by :func:`write_features_npz` in the features-dict layout, with
    ``image_size`` (2,) int64 from the stored ``imsize`` (which is kept too, as stored)."""
    with np.load(path) as data:
        out = {k: data[k] for k in data.files if not k.startswith("_")}
    kp = out.pop("keypoints")
    out["keypoints"], out["scales"] = kp[:, :2].copy(), kp[:, 2].copy()
    if "imsize" in out:
        out["image_size"] = out["imsize"].astype(np.int64)
    return out


@contextlib.contextmanager
def h5_file(path: str | Path, mode: str = "a") -> Iterator:
    """An ``h5py.File`` for writing ``path``: ``mode`` ``'w'`` a new file, ``'a'`` the file there
    (a new one where there is none, or an empty one).  It is written through a Python file object
    (h5py's ``fileobj`` driver), so that a failed write (a full disk) is the ``OSError`` it is:
    HDF5's own driver (HDF5 2.0) crashed the process (a segmentation fault) closing a file after one."""
    import h5py

    path = Path(path)
    new = mode == "w" or not path.exists() or path.stat().st_size == 0
    with open(path, "w+b" if new else "r+b") as raw, h5py.File(raw, "w" if new else "r+") as f:
        yield f


def write_features_h5(
    path: str | Path, name: str, features: dict[str, np.ndarray], image_size: tuple[int, int] | None = None
) -> None:
    """Add or replace group ``name`` in an hloc-style ``features.h5``: ``keypoints`` (K, 2)
    float32 (pixel centres at integer coordinates, as hloc; COLMAP adds 0.5),
    ``descriptors`` (D, K), ``scores`` (K,), ``image_size`` (W, H) (by default the features' own);
    written by :func:`h5_file`."""
    image_size = features_image_size(features, image_size)
    with h5_file(path, "a") as f:
        if name in f:
            del f[name]
        group = f.create_group(name)
        group.create_dataset("keypoints", data=features["keypoints"].astype(np.float32))
        group.create_dataset("descriptors", data=np.ascontiguousarray(features["descriptors"].T))
        group.create_dataset("scores", data=features["scores"].astype(np.float32))
        group.create_dataset("image_size", data=np.array(image_size, np.int64))
