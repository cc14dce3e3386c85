"""Optional dependencies, imported when first used.

``pip install lburst`` gives feature extraction (numpy, torch, opencv, scipy, h5py,
tqdm, scikit-image, openvino). The rest comes with extras: ``lburst[sfm]`` (pycolmap,
scikit-image), ``lburst[onnx]`` (onnx, onnxruntime, onnxscript), ``lburst[openvino]``
(nncf), ``lburst[viz]`` (matplotlib), ``lburst[tensorboard]``, ``lburst[video]`` (PyAV:
reading and writing recordings' videos), ``lburst[raw]`` (rawpy, tifffile: DNG frames)
``lburst[evo]`` (evo, to compare trajectories; lburst's own ATE needs none),
``lburst[cluster]`` (Dask's ``distributed``: extraction and matching on a cluster) and
``lburst[geo]`` (pyproj, piexif, laspy, rosbags: GNSS from EXIF, DJI subtitles and ROS bags,
ROS bags as input, georeferenced outputs). A module
that needs one calls :func:`require`, or holds a :class:`LazyModule`, so that importing it
costs nothing and a missing package gives a one-line message naming the extra.
"""

from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType

from lburst.errors import LBurstError

# importable module -> (pip package, extra)
EXTRAS: dict[str, tuple[str, str]] = {
    "pycolmap": ("pycolmap", "sfm"),
    "skimage": ("scikit-image", "sfm"),
    "onnx": ("onnx", "onnx"),
    "onnxruntime": ("onnxruntime", "onnx"),
    "onnxscript": ("onnxscript", "onnx"),
    "matplotlib": ("matplotlib", "viz"),
    "tensorboard": ("tensorboard", "tensorboard"),
    "openvino": ("openvino", "openvino"),
    "nncf": ("nncf", "openvino"),
    "av": ("av", "video"),
    "rawpy": ("rawpy", "raw"),
    "tifffile": ("tifffile", "raw"),
    "evo": ("evo", "evo"),
    "distributed": ("dask[distributed]", "cluster"),
    "dask": ("dask[distributed]", "cluster"),
    "pyproj": ("pyproj", "geo"),
    "piexif": ("piexif", "geo"),
    "laspy": ("laspy", "geo"),
    "rosbags": ("rosbags", "geo"),
}


class MissingExtra(LBurstError, ImportError):
    """An optional dependency is not installed; the message says which extra has it."""


def require(module: str, what: str | None = None) -> ModuleType:
    """Import ``module`` (e.g. ``'pycolmap'`` or ``'matplotlib.pyplot'``), or raise
    :class:`MissingExtra` with the ``pip install 'lburst[EXTRA]'`` line that provides it."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        top = module.split(".")[0]
        if exc.name is None or exc.name.split(".")[0] != top or top not in EXTRAS:
            raise
        package, extra = EXTRAS[top]
        need = f"{what} needs {package}" if what else f"{package} is not installed"
        raise MissingExtra(f"{need}: pip install 'lburst[{extra}]'", name=module) from exc


def check_installed(module: str, what: str | None = None) -> None:
    """Raise :class:`MissingExtra` (the ``pip install 'lburst[EXTRA]'`` line) when ``module`` is not
    installed, without importing it: a command that needs it later stops before any work."""
    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package missing, or a module blocked in sys.modules
        found = False
    if not found:
        require(module, what)  # the MissingExtra, or the import error of a module that is not an extra


class LazyModule:
    """A module imported on first attribute access (through :func:`require`).

    ``before`` names modules to import first when they are installed (pycolmap must
    come after cv2: see :mod:`lburst.sfm.colmap`).
    """

    def __init__(self, module: str, what: str | None = None, before: tuple[str, ...] = ()) -> None:
        self._module_name = module
        self._what = what
        self._before = before
        self._module: ModuleType | None = None

    def _load(self) -> ModuleType:
        if self._module is None:
            for name in self._before:
                try:
                    importlib.import_module(name)
                except ImportError:
                    pass
            self._module = require(self._module_name, self._what)
        return self._module

    def __getattr__(self, attr: str):
        if attr.startswith("_"):
            raise AttributeError(attr)
        return getattr(self._load(), attr)

    def __repr__(self) -> str:
        state = "loaded" if self._module is not None else "not loaded"
        return f"<lazy module {self._module_name!r} ({state})>"


# pycolmap for every module that needs it, imported on first use after cv2 (their bundled
# zlib/libpng clash; see lburst.sfm.colmap), so importing a module loads neither.
pycolmap = LazyModule("pycolmap", "reconstruction", before=("cv2",))
