"""intrinsym: partial intrinsic symmetries of 3D shapes.

The model of Lasowski et al., "A Probabilistic Framework for Partial Intrinsic Symmetries
in Geometric Data" (ICCV 2009): an MRF over correspondences with a spin-image NMI unary
and a truncated geodesic pairwise term, whose marginals are computed by loopy
sum-product belief propagation with an exact sparse message.

>>> import intrinsym
>>> result = intrinsym.detect(intrinsym.example_path(), n_source=60, n_target=600)
>>> result.marginals.shape
(60, 600)
"""

from __future__ import annotations

import atexit
import importlib.resources
import logging
import os
import shutil
import stat
import sys
import tempfile
from pathlib import Path

from ._version import __version__


def _writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (created when missing), as Numba tests it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def _own(path: str | Path, uid: int) -> bool:
    """Whether ``path`` is this user's and no one else's to change: owned by ``uid``, not
    group- or world-writable, not a symbolic link."""
    info = os.lstat(path)
    return not stat.S_ISLNK(info.st_mode) and info.st_uid == uid and not info.st_mode & 0o022


def _private_folder(folder: Path) -> bool:
    """Whether ``folder`` is a private folder of this user, creating it (mode 0700) when
    missing: it and every folder and file below it owned by the user, none of them
    group- or world-writable or a symbolic link, and a file can be created in it.

    A cache of pickles in a shared temporary folder is code: another user who made the
    folder first, or can write in it, could make this user's process run anything.
    """
    uid = os.getuid() if hasattr(os, "getuid") else None
    try:
        folder.mkdir(mode=0o700)
    except FileExistsError:
        pass
    except OSError:
        return False
    if uid is None:  # no owners to compare (Windows: the temporary folder is the user's own)
        return _writable(folder)
    try:
        if not _own(folder, uid):
            return False
        for root, folders, files in os.walk(folder):
            if not all(_own(os.path.join(root, name), uid) for name in (*folders, *files)):
                return False
    except OSError:
        return False
    return _writable(folder)


def numba_cache_dir(package: Path, environ: dict | os._Environ = os.environ) -> str | None:
    """Where Numba should cache the compiled kernels when it cannot by itself: None when
    ``NUMBA_CACHE_DIR`` is set or the package's ``__pycache__`` or the user's cache
    folder (``$XDG_CACHE_HOME`` or ``~/.cache``) is writable, else the user's private
    folder ``intrinsym-numba-cache-UID`` in the system's temporary folder (a read-only
    install run by a user without a writable home, as in containers and service
    accounts). When that name is taken by a folder that is not private
    (:func:`_private_folder`), a new private folder of this process's own, removed at
    exit: the kernels compile again on every run, and a warning says why."""
    if environ.get("NUMBA_CACHE_DIR") or _writable(package / "__pycache__"):
        return None
    home = environ.get("HOME")
    user_cache = environ.get("XDG_CACHE_HOME") or (str(Path(home) / ".cache") if home else None)
    if user_cache and _writable(Path(user_cache) / "numba"):
        return None
    uid = os.getuid() if hasattr(os, "getuid") else 0
    shared = Path(tempfile.gettempdir()) / f"intrinsym-numba-cache-{uid}"
    if _private_folder(shared):
        return str(shared)
    try:
        own = tempfile.mkdtemp(prefix=f"intrinsym-numba-cache-{uid}-")
    except OSError:
        return None
    atexit.register(shutil.rmtree, own, ignore_errors=True)
    logging.getLogger("intrinsym").warning(
        "intrinsym: %s is not private to this user (another user's, or writable by others): "
        "compiling into %s, removed at exit",
        shared,
        own,
    )
    return own


def _set_numba_cache() -> None:
    """Point Numba's cache (``cache=True`` kernels) at :func:`numba_cache_dir` when needed,
    before Numba reads its configuration."""
    folder = numba_cache_dir(Path(__file__).parent)
    if folder is None:
        return
    os.environ["NUMBA_CACHE_DIR"] = folder
    if "numba" in sys.modules:
        sys.modules["numba"].config.CACHE_DIR = folder


_set_numba_cache()


def example_path() -> Path:
    """Path of the shipped example mesh (Keenan Crane's spot, public domain)."""
    return Path(str(importlib.resources.files("intrinsym") / "data" / "spot.obj"))


from .errors import (  # noqa: E402
    InputError,
    IntrinsymError,
    MissingExtraError,
    OutputError,
    ParameterError,
    ResourceError,
    ResultError,
)
from .evaluation import MapScores, MarginalScores, load_symmetry_map, score_map, score_marginals  # noqa: E402
from .extract import Extraction, ExtractParams, Symmetry  # noqa: E402
from .globalmap import DistortionScores, map_distortion  # noqa: E402
from .mesh import Shape, load  # noqa: E402
from .params import Params, make_params  # noqa: E402
from .pipeline import detect, match, prepare  # noqa: E402
from .progress import BPIteration, StageDone  # noqa: E402
from .result import Result, RunInfo  # noqa: E402
from .surface import Surface  # noqa: E402


def __getattr__(name: str):
    """``intrinsym.batch`` (:func:`intrinsym.app.batching.batch`), imported on first use: it
    brings Dask and pandas."""
    if name == "batch":
        from .app.batching import batch

        return batch
    raise AttributeError(f"module 'intrinsym' has no attribute {name!r}")


__all__ = [
    "BPIteration",
    "DistortionScores",
    "ExtractParams",
    "Extraction",
    "InputError",
    "IntrinsymError",
    "MapScores",
    "MarginalScores",
    "MissingExtraError",
    "OutputError",
    "ParameterError",
    "Params",
    "ResourceError",
    "Result",
    "ResultError",
    "RunInfo",
    "Shape",
    "StageDone",
    "Surface",
    "Symmetry",
    "__version__",
    "batch",
    "detect",
    "example_path",
    "load",
    "load_symmetry_map",
    "make_params",
    "map_distortion",
    "match",
    "prepare",
    "score_map",
    "score_marginals",
]
