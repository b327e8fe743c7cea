"""Reading triangle meshes and point clouds from files.

:func:`load` reads a file into a validated :class:`~intrinsym.mesh.shape.Shape`. Every
problem with the file is reported as an :class:`~intrinsym.errors.InputError` whose
message is a single line that starts with the file name, so that command-line front
ends can print it verbatim instead of a traceback.

Supported formats
-----------------
``.off`` and ``.obj`` (own parsers in :mod:`intrinsym.mesh.io_text`, polygons
fan-triangulated), ``.ply`` and ``.stl`` (ASCII and binary, read with trimesh and
validated here, binary PLY by :mod:`intrinsym.mesh.io_ply`; a PLY file without faces is a
point cloud), ``.xyz`` (one point per line) and ``.npy`` (an ``(N, >=3)`` float array,
a point cloud).

Units are whatever the file uses; nothing is rescaled.
"""

from __future__ import annotations

import logging
import os
import re
import stat
import warnings
from io import BytesIO

import numpy as np

from ..errors import InputError, path_label
from ..resources import available_memory, format_bytes
from . import io_ply
from .io_text import is_float, quote_token, read_obj, read_off, read_xyz
from .shape import Shape, from_arrays

SUPPORTED_EXTENSIONS = (".off", ".obj", ".ply", ".stl", ".xyz", ".npy")


# ----------------------------------------------------------------------------
# file access
# ----------------------------------------------------------------------------


def _check_file(path: str, label: str, max_bytes: int | None) -> int:
    """Check that ``path`` is a readable, non-empty file within the size limit; return its size."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise InputError(f"{label}: no such file") from None
    except OSError as err:
        raise InputError(f"{label}: cannot access file ({err.strerror or err})") from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError(f"{label}: is a directory, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise InputError(f"{label}: not a regular file")
    size = info.st_size
    if size == 0:
        raise InputError(f"{label}: empty file")
    if max_bytes is None:
        avail = available_memory()
        max_bytes = None if avail is None else avail // 4
    if max_bytes is not None and size > max_bytes:
        raise InputError(
            f"{label}: file is {format_bytes(size)}, too large for the available memory "
            f"(limit {format_bytes(max_bytes)})"
        )
    return size


# ----------------------------------------------------------------------------
# NumPy arrays
# ----------------------------------------------------------------------------


def _read_npy(path: str, label: str) -> tuple[np.ndarray, None]:
    """Read an (N, >=3) real array from a .npy file; columns beyond the third are ignored."""
    try:
        arr = np.load(path, allow_pickle=False)
    except MemoryError:
        raise InputError(f"{label}: file is too large for the available memory") from None
    except Exception as err:  # numpy raises ValueError, OSError, EOFError, ... for bad files
        raise InputError(f"{label}: truncated or corrupt .npy file ({_one_line(err)})") from None
    if not isinstance(arr, np.ndarray):
        raise InputError(f"{label}: expected a single .npy array, found an .npz archive")
    if arr.dtype.kind not in "iuf":
        raise InputError(f"{label}: expected a real-valued array, found dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] < 3:
        raise InputError(f"{label}: expected an (N, 3) array of points, found shape {arr.shape}")
    return arr[:, :3].astype(np.float64), None


def _one_line(err: BaseException) -> str:
    """An exception as a short one-line text."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= 160 else text[:157] + "..."


# ----------------------------------------------------------------------------
# PLY and STL, read with trimesh (imported where used: it costs 0.2 s, which an OFF or OBJ
# input need not pay)
# ----------------------------------------------------------------------------


def _first_non_numeric(text_lines: list[str], start: int, keyword: str | None) -> tuple[int, str] | None:
    """Find the first non-numeric token in text lines (diagnostics only).

    Scans ``text_lines[start:]``; when ``keyword`` is given only lines starting
    with it are checked, and the keyword itself is skipped. Returns the 1-based
    line number and the token, or None.
    """
    for number, line in enumerate(text_lines[start:], start=start + 1):
        tokens = line.split()
        if keyword is not None:
            if not tokens or tokens[0] != keyword:
                continue
            tokens = tokens[1:]
        for token in tokens:
            if not is_float(token):
                return number, token
    return None


def _trimesh_failure(
    path: str,
    label: str,
    kind: str,
    err: Exception,
    ascii_start: int | None,
    keyword: str | None = None,
) -> InputError:
    """Turn a trimesh exception into an InputError.

    For ASCII files (``ascii_start`` is the 0-based line where numeric data
    begin) the message names the first line with a non-numeric token.
    """
    text = None
    if ascii_start is not None:
        try:
            with open(path, "rb") as fh:
                text = fh.read().decode("utf-8", errors="strict")
        except (OSError, UnicodeDecodeError, MemoryError):
            text = None
    if text is not None and ascii_start is not None:  # text is only read for ASCII files
        found = _first_non_numeric(text.splitlines(), ascii_start, keyword)
        if found is not None:
            return InputError(
                f"{label}: line {found[0]}: non-numeric value {quote_token(found[1])} where a number is expected"
            )
    # an ImportError means trimesh tried an optional decoder: its text would mislead
    detail = "" if isinstance(err, ImportError) else f" ({_one_line(err)})"
    return InputError(f"{label}: truncated or corrupt {kind} file{detail}")


def _trimesh_arrays(loaded, label: str, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) and faces (F, 3) of what ``trimesh.load`` returned (F may be 0)."""
    import trimesh

    if isinstance(loaded, trimesh.Scene):
        if not loaded.geometry:
            raise InputError(f"{label}: truncated or corrupt {kind} file: no geometry found")
        try:
            loaded = loaded.to_geometry()
        except Exception as err:  # mixed geometry types cannot be concatenated
            raise InputError(f"{label}: cannot combine the parts of the {kind} file ({_one_line(err)})") from None
    if isinstance(loaded, trimesh.Trimesh):
        return np.asarray(loaded.vertices), np.asarray(loaded.faces).reshape(-1, 3)
    if isinstance(loaded, trimesh.PointCloud):
        return np.asarray(loaded.vertices), np.empty((0, 3), dtype=np.int64)
    raise InputError(f"{label}: the {kind} file holds no triangle mesh or point cloud")


#: The lines of ASCII PLY and STL that hold only comments and names.
NAME_LINES = {"ply": (b"comment", b"obj_info"), "stl": (b"solid", b"endsolid")}


def _readable_names(data: bytes, file_type: str) -> bytes:
    """``data``, with the bytes that are not ASCII in its comment and name lines
    (:data:`NAME_LINES`) replaced by ``?`` when it is not UTF-8 text: trimesh decodes
    ASCII PLY and STL as UTF-8, and would refuse a Latin-1 comment or solid name, which
    carries no geometry. Other such bytes are left for trimesh to refuse."""
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        keys = NAME_LINES[file_type]
        lines = data.split(b"\n")
        return b"\n".join(re.sub(rb"[\x80-\xff]", b"?", ln) if ln.lstrip().startswith(keys) else ln for ln in lines)
    return data


def _trimesh_load(path: str, file_type: str, text: bool) -> object:
    """``trimesh.load`` without processing, its log (it prints tracebacks for recoverable
    problems) and its numeric warnings on corrupt values (checked after reading) silenced.
    A ``text`` file is given to trimesh with :func:`_readable_names`."""
    import trimesh

    logger = logging.getLogger("trimesh")
    previous = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            if not text:
                return trimesh.load(path, file_type=file_type, process=False)
            with open(path, "rb") as fh:
                source = BytesIO(_readable_names(fh.read(), file_type))
            return trimesh.load(source, file_type=file_type, process=False)
    finally:
        logger.setLevel(previous)


def _read_ply(path: str, label: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a PLY file; no faces means a point cloud.

    ASCII with trimesh, binary with :func:`intrinsym.mesh.io_ply.read_binary` (trimesh's
    binary reader needs all faces to have as many corners as the first).
    """
    header = io_ply.read_header(path, label)
    if header.format.startswith("binary"):
        return io_ply.read_binary(path, label, header)
    try:
        loaded = _trimesh_load(path, "ply", text=True)
    except Exception as err:  # trimesh raises many types on malformed input
        ascii_start = header.lines if header.format == "ascii" else None
        raise _trimesh_failure(path, label, "PLY", err, ascii_start) from None
    vertices, faces = _trimesh_arrays(loaded, label, "PLY")
    declared_v, declared_f = header.count("vertex"), header.count("face")
    if len(vertices) != declared_v:
        raise InputError(
            f"{label}: truncated or corrupt PLY file: header declares {declared_v} vertices, found {len(vertices)}"
        )
    if len(faces) < declared_f:
        raise InputError(
            f"{label}: truncated or corrupt PLY file: header declares {declared_f} faces, found {len(faces)}"
        )
    return vertices, (faces if len(faces) else None)


def _read_stl(path: str, label: str, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Read an STL file (ASCII or binary) with trimesh.

    STL stores every triangle with its own three corners, so the vertices are
    not shared between faces; :func:`~intrinsym.mesh.shape.clean` merges them.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(84)
    except OSError as err:
        raise InputError(f"{label}: cannot read file ({err.strerror or err})") from None
    declared = int(np.frombuffer(head[80:84], dtype="<u4")[0]) if len(head) == 84 else -1
    is_binary = declared >= 0 and 84 + 50 * declared == size
    if not is_binary and not head.lstrip().lower().startswith(b"solid"):
        detail = (
            f"header declares {declared} triangles ({84 + 50 * declared} bytes), file has {size} bytes"
            if declared >= 0
            else f"file has only {size} bytes"
        )
        raise InputError(f"{label}: truncated or corrupt binary STL file: {detail}")
    try:
        loaded = _trimesh_load(path, "stl", text=not is_binary)
    except Exception as err:  # trimesh raises many types on malformed input
        raise _trimesh_failure(path, label, "STL", err, None if is_binary else 0, "vertex") from None
    vertices, faces = _trimesh_arrays(loaded, label, "STL")
    if len(faces) == 0:
        raise InputError(f"{label}: truncated or corrupt STL file: no triangles found")
    return vertices, faces


# ----------------------------------------------------------------------------
# entry point
# ----------------------------------------------------------------------------


def load(path: str | os.PathLike, max_bytes: int | None = None) -> Shape:
    """Load a triangle mesh or point cloud from a file.

    Parameters
    ----------
    path : str or os.PathLike
        File to read; the type comes from the extension (case-insensitive):
        ``.off``, ``.obj``, ``.ply``, ``.stl`` (meshes; ``.off``/``.obj``/
        ``.ply`` without faces give a point cloud), ``.xyz`` or ``.npy``
        (point clouds).
    max_bytes : int or None
        Largest file size accepted, in bytes. None: a quarter of the memory
        currently available.

    Returns
    -------
    Shape
        The validated shape with ``path`` set to the path as given. The data
        are as stored in the file (STL corners are not merged, duplicates are
        kept); call :func:`~intrinsym.mesh.shape.clean` before processing. The
        vertices are in file order, the order a result's vertex indices refer
        to; ``trimesh.load(path, process=False, maintain_order=True)`` gives the
        same order (without ``maintain_order`` trimesh splits the vertices of an
        OBJ with per-corner texture coordinates or normals and renumbers them).

    Raises
    ------
    InputError
        For any problem with the file (unknown type, missing, empty, too
        large, non-numeric data, NaN/inf, truncated, index out of range,
        fewer than 4 points...). The message is one line starting with the
        path as given.
    """
    label = path_label(path)
    filename = os.fsdecode(path)
    ext = os.path.splitext(filename)[1].lower()
    if ext not in SUPPORTED_EXTENSIONS:
        shown = f"'{ext}'" if ext else "(no extension)"
        raise InputError(f"{label}: unknown file type {shown} (expected .off, .obj, .ply, .stl, .xyz or .npy)")
    size = _check_file(filename, label, max_bytes)
    if ext == ".off":
        vertices, faces = read_off(filename, label)
    elif ext == ".obj":
        vertices, faces = read_obj(filename, label)
    elif ext == ".ply":
        vertices, faces = _read_ply(filename, label)
    elif ext == ".stl":
        vertices, faces = _read_stl(filename, label, size)
    elif ext == ".xyz":
        vertices, faces = read_xyz(filename, label)
    else:
        vertices, faces = _read_npy(filename, label)
    return from_arrays(vertices, faces, path=filename)
