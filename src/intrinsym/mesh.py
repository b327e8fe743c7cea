"""Loading, validating and cleaning triangle meshes and point clouds.

Everything that touches user files lives here. Every problem with user input
is reported as an :class:`InputError` whose message is a single line that
starts with the file name, so that command-line front ends can print it
verbatim instead of a traceback.

Supported formats
-----------------
``.off`` and ``.obj`` (own parsers, polygons fan-triangulated), ``.ply`` and
``.stl`` (ASCII and binary, read with trimesh and validated here; a PLY file
without faces is a point cloud), ``.xyz`` (one point per line) and ``.npy``
(an ``(N, >=3)`` float array, a point cloud).

Units are whatever the file uses; nothing is rescaled.
"""

from __future__ import annotations

import logging
import os
import re
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import (
    breadth_first_order,
    connected_components,
    minimum_spanning_tree,
)
from scipy.spatial import cKDTree

SUPPORTED_EXTENSIONS = (".off", ".obj", ".ply", ".stl", ".xyz", ".npy")
MERGE_TOLERANCE = 1e-9
"""Vertices closer than this fraction of the bounding-box diagonal are merged."""
MAX_COORDINATE = 1e50
"""Largest accepted coordinate magnitude (keeps squared areas far from overflow)."""
DEGENERATE_RATIO = 1e-12
"""Triangles whose height over their longest edge is below this fraction of
that edge's length are treated as having zero area."""


class InputError(ValueError):
    """A problem with user input.

    ``str(err)`` is one line naming the file and the problem, e.g.
    ``"cat.off: truncated file: header declares 27894 vertices, found 120"``.
    Line breaks in the message are replaced by spaces so the one-line promise
    holds whatever text is passed in.
    """

    def __init__(self, message: str) -> None:
        super().__init__(re.sub(r"\s*[\r\n]+\s*", " ", str(message)).strip())


@dataclass(frozen=True, eq=False)
class Shape:
    """A triangle mesh or a point cloud.

    Attributes
    ----------
    vertices : np.ndarray
        (N, 3) float64 vertex coordinates, in the file's units.
    faces : np.ndarray or None
        (F, 3) int64 vertex indices of the triangles, or None for a point
        cloud.
    path : str
        Where the shape came from ("" if it was built in memory).

    Notes
    -----
    Shapes built by :func:`from_arrays`, :func:`load` and :func:`clean` hold
    read-only copies of their arrays, so a shape cannot change after it has
    been validated. Equality and hashing are by identity.
    """

    vertices: np.ndarray
    faces: np.ndarray | None
    path: str = ""

    @property
    def is_cloud(self) -> bool:
        """True if the shape is a point cloud (has no faces)."""
        return self.faces is None


# ----------------------------------------------------------------------------
# construction and validation
# ----------------------------------------------------------------------------


def _label(path: str | os.PathLike) -> str:
    """The name used at the start of error messages (one line, never empty)."""
    text = os.fsdecode(path).replace("\r", "\\r").replace("\n", "\\n")
    return text if text else "<in-memory shape>"


def from_arrays(vertices, faces=None, path: str = "") -> Shape:
    """Build a validated :class:`Shape` from arrays.

    Parameters
    ----------
    vertices : array_like
        (N, 3) real coordinates; N >= 4, all finite.
    faces : array_like or None
        (F, 3) integer vertex indices in ``[0, N)`` with F >= 1, or None for a
        point cloud. Float arrays holding whole numbers are accepted.
    path : str
        Where the data came from; used in error messages and stored on the
        shape.

    Returns
    -------
    Shape
        A shape with read-only float64 vertices and int64 faces (copies of the
        inputs).

    Raises
    ------
    InputError
        If the arrays have the wrong shape or type, contain NaN/inf, have
        fewer than 4 points, or a face index is out of range.
    """
    label = _label(path)
    if np.iscomplexobj(vertices):
        raise InputError(f"{label}: vertex coordinates are complex numbers, expected real numbers")
    try:
        verts = np.array(vertices, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputError(f"{label}: vertices are not a numeric array ({err})") from None
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise InputError(f"{label}: vertices must be an (N, 3) array, got shape {verts.shape}")
    finite = np.isfinite(verts).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise InputError(
            f"{label}: {bad.size} vertices have NaN or infinite coordinates "
            f"(first: vertex {bad[0]})"
        )
    largest = float(np.abs(verts).max(initial=0.0))
    if largest > MAX_COORDINATE:
        raise InputError(
            f"{label}: coordinates as large as {largest:.3g} are out of range "
            f"(the limit is {MAX_COORDINATE:.0e}); rescale the shape"
        )
    n = verts.shape[0]
    if n < 4:
        raise InputError(f"{label}: only {n} points; at least 4 are needed")
    verts.setflags(write=False)
    if faces is None:
        return Shape(vertices=verts, faces=None, path=os.fsdecode(path))
    return Shape(vertices=verts, faces=_validated_faces(faces, n, label), path=os.fsdecode(path))


def _validated_faces(faces, n_vertices: int, label: str) -> np.ndarray:
    """Check an (F, 3) index array against N vertices; return a read-only int64 copy."""
    arr = np.asarray(faces)
    if arr.dtype.kind == "f":
        if not np.isfinite(arr).all() or not np.array_equal(arr, np.round(arr)):
            raise InputError(f"{label}: face indices must be whole numbers")
    elif arr.dtype.kind not in "iu":
        raise InputError(f"{label}: face indices must be integers, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(
            f"{label}: faces must be an (F, 3) array of triangles, got shape {arr.shape}"
        )
    if arr.shape[0] == 0:
        raise InputError(f"{label}: the mesh has no faces (use faces=None for a point cloud)")
    lo, hi = arr.min(), arr.max()
    if lo < 0 or hi >= n_vertices:
        bad = lo if lo < 0 else hi
        raise InputError(
            f"{label}: face index {int(bad)} out of range (the shape has {n_vertices} vertices)"
        )
    out = np.array(arr, dtype=np.int64)
    out.setflags(write=False)
    return out


# ----------------------------------------------------------------------------
# memory limits
# ----------------------------------------------------------------------------


def _available_memory() -> int | None:
    """Bytes of memory this process can still use, or None if unknown.

    Uses Linux's ``MemAvailable`` (free memory plus reclaimable cache), capped
    by a cgroup v2 memory limit when one is set, and falls back to
    ``os.sysconf`` (available, then total physical pages) elsewhere.
    """
    avail = None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        avail = None
    if avail is None:
        for name in ("SC_AVPHYS_PAGES", "SC_PHYS_PAGES"):
            try:
                pages, page_size = os.sysconf(name), os.sysconf("SC_PAGE_SIZE")
            except (ValueError, OSError, AttributeError):
                continue
            if pages > 0 and page_size > 0:
                avail = pages * page_size
                break
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text(encoding="ascii").strip()
        used = Path("/sys/fs/cgroup/memory.current").read_text(encoding="ascii").strip()
        if limit != "max":
            room = max(int(limit) - int(used), 0)
            avail = room if avail is None else min(avail, room)
    except (OSError, ValueError):
        pass
    return avail


def _format_bytes(nbytes: float) -> str:
    """Human-readable size: GB down to 0.1 GB, then MB, kB, bytes."""
    if nbytes >= 1e8:
        return f"{nbytes / 1e9:.1f} GB"
    if nbytes >= 1e5:
        return f"{nbytes / 1e6:.1f} MB"
    if nbytes >= 1e3:
        return f"{nbytes / 1e3:.1f} kB"
    return f"{int(nbytes)} bytes"


def check_memory(nbytes: int, what: str, path: str = "") -> None:
    """Refuse an allocation that would not fit in memory.

    Parameters
    ----------
    nbytes : int
        Size of the planned allocation, in bytes.
    what : str
        What the memory is for, e.g. ``"the 30000 x 30000 distance matrix"``.
    path : str
        The input file the work is for (starts the error message).

    Raises
    ------
    InputError
        If ``nbytes`` exceeds 80% of the memory currently available. The
        message reports the usable amount (80% of what is available). When
        the available memory cannot be determined nothing is checked.
    """
    avail = _available_memory()
    if avail is None:
        return
    usable = 0.8 * avail
    if nbytes > usable:
        raise InputError(
            f"{_label(path)}: {what} needs {nbytes / 1e9:.1f} GB, more than the "
            f"{usable / 1e9:.1f} GB of memory available"
        )


# ----------------------------------------------------------------------------
# file access and text parsing helpers
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
        avail = _available_memory()
        max_bytes = None if avail is None else avail // 4
    if max_bytes is not None and size > max_bytes:
        raise InputError(
            f"{label}: file is {_format_bytes(size)}, too large for the available memory "
            f"(limit {_format_bytes(max_bytes)})"
        )
    return size


def _read_bytes(path: str, label: str) -> bytes:
    """Read a whole file, converting OS errors to InputError."""
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except MemoryError:
        raise InputError(f"{label}: file is too large for the available memory") from None
    except OSError as err:
        raise InputError(f"{label}: cannot read file ({err.strerror or err})") from None


def _decode(data: bytes, label: str) -> str:
    """Decode file contents as UTF-8 text (BOM allowed), rejecting binary data."""
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise InputError(
            f"{label}: not a text file (undecodable byte at offset {err.start})"
        ) from None
    if "\x00" in text:
        raise InputError(f"{label}: not a text file (contains NUL bytes)")
    return text


def _content_lines(text: str) -> tuple[list[int], list[str]]:
    """Lines that hold data, with ``#`` comments removed.

    Returns
    -------
    numbers : list of int
        1-based line number of each kept line.
    lines : list of str
        The kept lines (comment-free, not empty after stripping).
    """
    has_comments = "#" in text
    numbers, lines = [], []
    for number, line in enumerate(text.splitlines(), start=1):
        if has_comments and "#" in line:
            line = line.split("#", 1)[0]
        if line.strip():
            numbers.append(number)
            lines.append(line)
    return numbers, lines


def _short(token: str) -> str:
    """Quote a token for an error message, shortened to 30 characters."""
    return repr(token if len(token) <= 30 else token[:27] + "...")


def _fast_table(lines: list[str], dtype: type) -> np.ndarray | None:
    """Parse whitespace-separated lines with the same number of columns in C.

    Returns an (n, c) array, or None when the lines are not such a table (the
    caller then parses line by line to report the exact problem).
    """
    try:
        table = np.loadtxt(lines, dtype=dtype, comments=None, ndmin=2)
    except ValueError:
        return None
    return table if len(table) == len(lines) else None  # loadtxt skips blank lines


def _parse_points(numbers: list[int], lines: list[str], label: str, what: str) -> np.ndarray:
    """Parse the first 3 numbers of every line into an (n, 3) float64 array.

    Extra columns (w, colours, normals) are ignored. Errors name the line.
    """
    table = _fast_table(lines, np.float64)
    if table is not None and table.shape[1] >= 3:
        out = np.ascontiguousarray(table[:, :3])
    else:
        out = np.empty((len(lines), 3))
        for i, (number, line) in enumerate(zip(numbers, lines, strict=True)):
            values = line.split()[:3]
            if len(values) < 3:
                raise InputError(
                    f"{label}: line {number}: {what} needs 3 coordinates, found {len(values)}"
                )
            try:
                out[i] = [float(t) for t in values]
            except ValueError:
                bad = next(t for t in values if not _is_float(t))
                raise InputError(
                    f"{label}: line {number}: non-numeric value {_short(bad)} where a "
                    f"{what} coordinate is expected"
                ) from None
    finite = np.isfinite(out).all(axis=1)
    if not finite.all():
        first = int(np.flatnonzero(~finite)[0])
        raise InputError(
            f"{label}: line {numbers[first]}: NaN or infinite {what} coordinate "
            f"({int((~finite).sum())} such lines in the file)"
        )
    return out


def _is_float(token: str) -> bool:
    """True if ``float(token)`` succeeds."""
    try:
        float(token)
    except ValueError:
        return False
    return True


def _fan_triangulate(polygons: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate polygons of 3 or more vertices.

    Parameters
    ----------
    polygons : list of list of int
        P polygons given as vertex index lists.

    Returns
    -------
    triangles : np.ndarray
        (T, 3) int64; polygon ``[a, b, c, d]`` becomes ``(a, b, c), (a, c, d)``.
    source : np.ndarray
        (T,) int64 index of the polygon each triangle came from.
    """
    lengths = np.fromiter((len(p) for p in polygons), dtype=np.int64, count=len(polygons))
    flat = np.fromiter((i for p in polygons for i in p), dtype=np.int64, count=int(lengths.sum()))
    starts = np.cumsum(lengths) - lengths
    n_tris = lengths - 2
    source = np.repeat(np.arange(len(polygons), dtype=np.int64), n_tris)
    first_tri = np.cumsum(n_tris) - n_tris
    j = np.arange(source.size, dtype=np.int64) - first_tri[source] + 1
    base = starts[source]
    triangles = np.stack([flat[base], flat[base + j], flat[base + j + 1]], axis=1)
    return triangles, source


def _fan_table(polygons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate P polygons that all have k >= 3 vertices.

    Parameters
    ----------
    polygons : np.ndarray
        (P, k) int64 vertex indices.

    Returns
    -------
    triangles : np.ndarray
        (P * (k - 2), 3) int64, the triangles of polygon p at rows
        ``p * (k - 2) ... (p + 1) * (k - 2) - 1``.
    source : np.ndarray
        (P * (k - 2),) int64 index of the polygon each triangle came from.
    """
    n, k = polygons.shape
    j = np.arange(1, k - 1)
    triangles = np.stack(
        [np.repeat(polygons[:, :1], k - 2, axis=1), polygons[:, j], polygons[:, j + 1]], axis=2
    ).reshape(-1, 3)
    return triangles, np.repeat(np.arange(n, dtype=np.int64), k - 2)


def _check_indices(
    triangles: np.ndarray,
    source: np.ndarray,
    numbers: list[int],
    n_vertices: int,
    label: str,
    one_based: bool,
) -> None:
    """Raise InputError naming the line of the first face index outside [0, n_vertices).

    ``triangles`` are 0-based; with ``one_based`` (OBJ) the index is reported
    as written in the file, and a negative result means a relative index that
    reached before the first vertex.
    """
    bad = (triangles < 0) | (triangles >= n_vertices)
    if not bad.any():
        return
    t, c = np.argwhere(bad)[0]
    index, line = int(triangles[t, c]), numbers[source[t]]
    if one_based and index < 0:
        raise InputError(
            f"{label}: line {line}: relative face index points before the first vertex"
        )
    shown = index + 1 if one_based else index
    raise InputError(
        f"{label}: line {line}: face index {shown} out "
        f"of range (the file has {n_vertices} vertices)"
    )


def _non_integer_face(label: str, number: int, token: str) -> InputError:
    """The error for a face entry that is not an integer."""
    return InputError(
        f"{label}: line {number}: non-integer value {_short(token)} where a face index is expected"
    )


def _off_faces(numbers: list[int], lines: list[str], label: str) -> tuple[np.ndarray, np.ndarray]:
    """Parse OFF face lines ``k i_1 ... i_k [colour]`` into fan-triangulated (T, 3) faces.

    Also returns the (T,) index of the line each triangle came from.
    """
    table = _fast_table(lines, np.int64)
    if table is not None and table.shape[1] >= 4:
        k = int(table[0, 0])
        if k >= 3 and table.shape[1] >= k + 1 and (table[:, 0] == k).all():
            return _fan_table(table[:, 1 : k + 1])
    polygons = []
    for number, line in zip(numbers, lines, strict=True):
        tokens = line.split()
        try:
            k = int(tokens[0])
        except ValueError:
            raise _non_integer_face(label, number, tokens[0]) from None
        if k < 3:
            raise InputError(f"{label}: line {number}: a face needs at least 3 vertices, found {k}")
        if len(tokens) < k + 1:
            raise InputError(
                f"{label}: line {number}: face declares {k} vertices but lists {len(tokens) - 1}"
            )
        polygon = []
        for token in tokens[1 : k + 1]:
            try:
                polygon.append(int(token))
            except ValueError:
                raise _non_integer_face(label, number, token) from None
        polygons.append(polygon)
    return _fan_triangulate(polygons)


def _read_off(path: str, label: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Parse an ASCII OFF file (also COFF, NOFF, STOFF...; colours and normals ignored)."""
    numbers, lines = _content_lines(_decode(_read_bytes(path, label), label))
    if not lines:
        raise InputError(f"{label}: empty file (no data lines)")
    tokens = lines[0].split()
    match = re.fullmatch(r"(ST)?C?N?(4?n?)OFF(\d*)", tokens[0])
    if match is None:
        raise InputError(
            f"{label}: not an OFF file: line {numbers[0]} "
            f"starts with {_short(tokens[0])}, expected 'OFF'"
        )
    if match.group(2):
        raise InputError(
            f"{label}: unsupported OFF variant {_short(tokens[0])} (only 3D OFF is supported)"
        )
    counts = ([match.group(3)] if match.group(3) else []) + tokens[1:]
    if counts and counts[0].upper() == "BINARY":
        raise InputError(f"{label}: binary OFF is not supported")
    body, number = 1, numbers[0]
    if not counts:
        if len(lines) < 2:
            raise InputError(f"{label}: truncated file: no vertex/face counts after the OFF header")
        body, number, counts = 2, numbers[1], lines[1].split()
    if len(counts) < 2 or not all(t.isdecimal() for t in counts[:2]):
        raise InputError(
            f"{label}: line {number}: expected vertex and "
            f"face counts, found {_short(' '.join(counts))}"
        )
    n_vertices, n_faces = int(counts[0]), int(counts[1])
    if n_vertices == 0:
        raise InputError(f"{label}: the header declares 0 vertices")
    stop = body + n_vertices
    if len(lines) < stop:
        raise InputError(
            f"{label}: truncated file: header declares "
            f"{n_vertices} vertices, found {len(lines) - body}"
        )
    vertices = _parse_points(numbers[body:stop], lines[body:stop], label, "vertex")
    if n_faces == 0:
        return vertices, None
    if len(lines) < stop + n_faces:
        raise InputError(
            f"{label}: truncated file: header declares {n_faces} faces, found {len(lines) - stop}"
        )
    face_numbers = numbers[stop : stop + n_faces]
    triangles, source = _off_faces(face_numbers, lines[stop : stop + n_faces], label)
    _check_indices(triangles, source, face_numbers, n_vertices, label, one_based=False)
    return vertices, triangles


def _obj_faces(
    numbers: list[int], lines: list[str], n_before: np.ndarray, label: str
) -> tuple[np.ndarray, np.ndarray]:
    """Parse OBJ ``f`` records (keyword removed) into fan-triangulated 0-based (T, 3) faces.

    ``n_before[i]`` is the number of vertices defined before face line i (for
    negative, relative indices). Also returns the (T,) face-line index of each
    triangle.
    """
    stripped = re.sub(r"/\S*", "", "\n".join(lines)).split("\n")
    table = _fast_table(stripped, np.int64)
    if table is not None and table.shape[1] >= 3 and (table != 0).all():
        return _fan_table(np.where(table > 0, table - 1, n_before[:, None] + table))
    polygons = []
    for number, line, n_so_far in zip(numbers, lines, n_before.tolist(), strict=True):
        polygon = []
        for corner in line.split():
            head = corner.split("/", 1)[0]
            try:
                index = int(head)
            except ValueError:
                raise _non_integer_face(label, number, head) from None
            if index == 0:
                raise InputError(
                    f"{label}: line {number}: face index 0 is invalid (OBJ indices start at 1)"
                )
            polygon.append(index - 1 if index > 0 else n_so_far + index)
        if len(polygon) < 3:
            raise InputError(
                f"{label}: line {number}: a face needs at least 3 vertices, found {len(polygon)}"
            )
        polygons.append(polygon)
    return _fan_triangulate(polygons)


def _read_obj(path: str, label: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Parse a Wavefront OBJ file: ``v`` and ``f`` records; other records ignored.

    Face corners may be ``i``, ``i/t``, ``i/t/n`` or ``i//n``; negative indices
    are relative to the vertices read so far. Polygons are fan-triangulated.
    """
    numbers, lines = _content_lines(_decode(_read_bytes(path, label), label))
    if not lines:
        raise InputError(f"{label}: empty file (no data lines)")
    stripped = [line.lstrip() for line in lines]
    keys = [line.split(None, 1)[0] for line in stripped]
    v_rows = [i for i, key in enumerate(keys) if key == "v"]
    f_rows = [i for i, key in enumerate(keys) if key == "f"]
    if not v_rows:
        raise InputError(f"{label}: no vertices ('v' lines) found")
    vertices = _parse_points(
        [numbers[i] for i in v_rows], [stripped[i][1:] for i in v_rows], label, "vertex"
    )
    if not f_rows:
        return vertices, None
    face_numbers = [numbers[i] for i in f_rows]
    n_before = np.searchsorted(np.asarray(v_rows), np.asarray(f_rows))
    triangles, source = _obj_faces(face_numbers, [stripped[i][1:] for i in f_rows], n_before, label)
    _check_indices(triangles, source, face_numbers, len(vertices), label, one_based=True)
    return vertices, triangles


def _read_xyz(path: str, label: str) -> tuple[np.ndarray, None]:
    """Parse an XYZ point file: ``x y z`` per line, extra columns (normals...) ignored."""
    numbers, lines = _content_lines(_decode(_read_bytes(path, label), label))
    if not lines:
        raise InputError(f"{label}: empty file (no data lines)")
    return _parse_points(numbers, lines, label, "point"), None


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


def _ply_header(path: str, label: str) -> tuple[str, dict[str, int], int]:
    """Read a PLY header.

    Returns
    -------
    format : str
        ``"ascii"``, ``"binary_little_endian"`` or ``"binary_big_endian"``.
    counts : dict
        Declared element counts, e.g. ``{"vertex": 8, "face": 12}``.
    header_lines : int
        Number of lines up to and including ``end_header``.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 20)
    except OSError as err:
        raise InputError(f"{label}: cannot read file ({err.strerror or err})") from None
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise InputError(f"{label}: not a PLY file (missing 'ply' magic or 'end_header')")
    lines = head[:end].decode("ascii", errors="replace").splitlines()
    fmt = ""
    counts: dict[str, int] = {}
    for line in lines:
        tokens = line.split()
        if len(tokens) >= 2 and tokens[0] == "format":
            fmt = tokens[1]
        elif len(tokens) >= 3 and tokens[0] == "element":
            if not tokens[2].isdigit():
                raise InputError(
                    f"{label}: corrupt PLY header: bad element count {_short(tokens[2])}"
                )
            counts[tokens[1]] = int(tokens[2])
    return fmt, counts, len(lines) + 1


def _first_non_numeric(
    text_lines: list[str], start: int, keyword: str | None
) -> tuple[int, str] | None:
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
            if not _is_float(token):
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
    if text is not None:
        found = _first_non_numeric(text.splitlines(), ascii_start, keyword)
        if found is not None:
            return InputError(
                f"{label}: line {found[0]}: non-numeric value "
                f"{_short(found[1])} where a number is expected"
            )
    # an ImportError means trimesh tried an optional decoder: its text would mislead
    detail = "" if isinstance(err, ImportError) else f" ({_one_line(err)})"
    return InputError(f"{label}: truncated or corrupt {kind} file{detail}")


def _trimesh_arrays(loaded, label: str, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) and faces (F, 3) of what ``trimesh.load`` returned (F may be 0)."""
    if isinstance(loaded, trimesh.Scene):
        if not loaded.geometry:
            raise InputError(f"{label}: truncated or corrupt {kind} file: no geometry found")
        try:
            loaded = loaded.to_geometry()
        except Exception as err:  # mixed geometry types cannot be concatenated
            raise InputError(
                f"{label}: cannot combine the parts of the {kind} file ({_one_line(err)})"
            ) from None
    if isinstance(loaded, trimesh.Trimesh):
        return np.asarray(loaded.vertices), np.asarray(loaded.faces).reshape(-1, 3)
    if isinstance(loaded, trimesh.PointCloud):
        return np.asarray(loaded.vertices), np.empty((0, 3), dtype=np.int64)
    raise InputError(f"{label}: the {kind} file holds no triangle mesh or point cloud")


@contextmanager
def _quiet_trimesh() -> Iterator[None]:
    """Silence trimesh's log (it prints tracebacks for recoverable problems) while reading."""
    logger = logging.getLogger("trimesh")
    previous = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(previous)


def _read_ply(path: str, label: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a PLY file (ASCII or binary) with trimesh; no faces means a point cloud."""
    fmt, counts, header_lines = _ply_header(path, label)
    try:
        with _quiet_trimesh():
            loaded = trimesh.load(path, file_type="ply", process=False)
    except Exception as err:  # trimesh raises many types on malformed input
        ascii_start = header_lines if fmt == "ascii" else None
        raise _trimesh_failure(path, label, "PLY", err, ascii_start) from None
    vertices, faces = _trimesh_arrays(loaded, label, "PLY")
    declared_v, declared_f = counts.get("vertex", 0), counts.get("face", 0)
    if len(vertices) != declared_v:
        raise InputError(
            f"{label}: truncated or corrupt PLY file: header declares {declared_v} vertices, "
            f"found {len(vertices)}"
        )
    if len(faces) < declared_f:
        raise InputError(
            f"{label}: truncated or corrupt PLY file: header declares {declared_f} faces, "
            f"found {len(faces)}"
        )
    return vertices, (faces if len(faces) else None)


def _read_stl(path: str, label: str, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Read an STL file (ASCII or binary) with trimesh.

    STL stores every triangle with its own three corners, so the vertices are
    not shared between faces; :func:`clean` merges them.
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
            f"header declares {declared} triangles "
            f"({84 + 50 * declared} bytes), file has {size} bytes"
            if declared >= 0
            else f"file has only {size} bytes"
        )
        raise InputError(f"{label}: truncated or corrupt binary STL file: {detail}")
    try:
        with _quiet_trimesh():
            loaded = trimesh.load(path, file_type="stl", process=False)
    except Exception as err:  # trimesh raises many types on malformed input
        raise _trimesh_failure(
            path, label, "STL", err, None if is_binary else 0, "vertex"
        ) from None
    vertices, faces = _trimesh_arrays(loaded, label, "STL")
    if len(faces) == 0:
        raise InputError(f"{label}: truncated or corrupt STL file: no triangles found")
    return vertices, faces


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
        kept); call :func:`clean` before processing.

    Raises
    ------
    InputError
        For any problem with the file (unknown type, missing, empty, too
        large, non-numeric data, NaN/inf, truncated, index out of range,
        fewer than 4 points...). The message is one line starting with the
        path as given.
    """
    label = _label(path)
    filename = os.fsdecode(path)
    ext = os.path.splitext(filename)[1].lower()
    if ext not in SUPPORTED_EXTENSIONS:
        shown = f"'{ext}'" if ext else "(no extension)"
        raise InputError(
            f"{label}: unknown file type {shown} (expected .off, .obj, .ply, .stl, .xyz or .npy)"
        )
    size = _check_file(filename, label, max_bytes)
    if ext == ".off":
        vertices, faces = _read_off(filename, label)
    elif ext == ".obj":
        vertices, faces = _read_obj(filename, label)
    elif ext == ".ply":
        vertices, faces = _read_ply(filename, label)
    elif ext == ".stl":
        vertices, faces = _read_stl(filename, label, size)
    elif ext == ".xyz":
        vertices, faces = _read_xyz(filename, label)
    else:
        vertices, faces = _read_npy(filename, label)
    return from_arrays(vertices, faces, path=filename)


# ----------------------------------------------------------------------------
# cleaning
# ----------------------------------------------------------------------------


def _unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group equal rows of an (n, c) array (a faster ``np.unique(axis=0)``).

    Returns
    -------
    first : np.ndarray
        (u,) int64 index of the first occurrence of every distinct row, in
        lexicographic order of the rows.
    inverse : np.ndarray
        (n,) int64 group of every row, indexing ``first``.
    """
    order = np.lexsort(rows.T[::-1])  # stable: equal rows keep their input order
    ordered = rows[order]
    starts = np.ones(len(rows), dtype=bool)
    starts[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    inverse = np.empty(len(rows), dtype=np.int64)
    inverse[order] = np.cumsum(starts) - 1
    return order[starts], inverse


def _merge_vertices(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge exact duplicates and vertices within MERGE_TOLERANCE x bbox diagonal.

    Returns
    -------
    merged : np.ndarray
        (M, 3) coordinates; each group is represented by its lowest-index
        member, and groups keep the order of their first member.
    vertex_map : np.ndarray
        (N,) int64 index into ``merged`` for every input vertex.
    """
    first_copy, inverse = _unique_rows(vertices)  # -0.0 == 0.0 here, as wanted
    unique = vertices[first_copy]
    diagonal = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    pairs = cKDTree(unique).query_pairs(MERGE_TOLERANCE * diagonal, output_type="ndarray")
    if len(pairs):
        graph = coo_matrix(
            (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(unique), len(unique))
        )
        _, group_of_unique = connected_components(graph, directed=False)
    else:
        group_of_unique = np.arange(len(unique))
    group = group_of_unique[inverse]
    _, first = np.unique(group, return_index=True)  # lowest input index of every group
    n_groups = len(first)
    order = np.argsort(first, kind="stable")
    rank = np.empty(n_groups, dtype=np.int64)
    rank[order] = np.arange(n_groups, dtype=np.int64)
    return vertices[first[order]], rank[group]


def clean(shape: Shape) -> tuple[Shape, np.ndarray]:
    """Repair a shape so that downstream geometry is well defined.

    Merges exactly duplicate vertices and near-duplicates (closer than 1e-9
    of the bounding-box diagonal). For meshes it then drops degenerate faces
    (a repeated vertex, or zero area: height over the longest edge below
    1e-12 of its length),
    duplicate faces (same vertex set, whatever the order or orientation;
    the first is kept) and vertices referenced by no face. Several connected
    components are kept. Surviving vertices and faces keep their relative
    order, so a clean input comes back unchanged.

    Parameters
    ----------
    shape : Shape
        Mesh or point cloud.

    Returns
    -------
    cleaned : Shape
        The repaired shape (same ``path``).
    vertex_map : np.ndarray
        (N_input,) int64: for every input vertex, the index of the cleaned
        vertex that represents it. A dropped unreferenced vertex maps to the
        nearest kept vertex.

    Raises
    ------
    InputError
        If nothing usable is left (no valid face, or fewer than 4 vertices).
    """
    label = _label(shape.path)
    merged, vertex_map = _merge_vertices(np.asarray(shape.vertices, dtype=np.float64))
    if shape.faces is None:
        if len(merged) < 4:
            raise InputError(
                f"{label}: only {len(merged)} distinct points "
                "after merging duplicates; at least 4 are needed"
            )
        return from_arrays(merged, None, shape.path), vertex_map

    faces = vertex_map[np.asarray(shape.faces)]
    distinct = (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    corners = merged[faces]
    edges = corners[:, [1, 2, 0]] - corners
    twice_area = np.linalg.norm(np.cross(edges[:, 0], edges[:, 2]), axis=1)
    longest_sq = (edges**2).sum(axis=2).max(axis=1)
    valid = distinct & (twice_area > DEGENERATE_RATIO * longest_sq)  # 2A / L^2 = height / L
    faces = faces[valid]
    if len(faces) == 0:
        raise InputError(
            f"{label}: no usable faces: all {len(shape.faces)} "
            "faces are degenerate (zero area or repeated vertices)"
        )
    first, _ = _unique_rows(np.sort(faces, axis=1))
    faces = faces[np.sort(first)]

    used = np.zeros(len(merged), dtype=bool)
    used[faces.ravel()] = True
    if used.sum() < 4:
        raise InputError(
            f"{label}: only {int(used.sum())} distinct vertices "
            "left after cleaning; at least 4 are needed"
        )
    new_index = np.cumsum(used) - 1
    if not used.all():
        kept = np.flatnonzero(used)
        _, nearest = cKDTree(merged[kept]).query(merged[~used])
        new_index[~used] = new_index[kept[nearest]]
    cleaned = from_arrays(merged[used], new_index[faces], shape.path)
    return cleaned, new_index[vertex_map]


# ----------------------------------------------------------------------------
# geometry
# ----------------------------------------------------------------------------


def surface_area(shape: Shape) -> float:
    """Total surface area, in squared file units.

    Parameters
    ----------
    shape : Shape
        Mesh or point cloud.

    Returns
    -------
    float
        For a mesh, the sum of the triangle areas. For a point cloud an
        *estimate*: the sum over points of ``pi * r6**2 / 6``, where ``r6`` is
        the distance to the 6th nearest other point. This is unbiased for
        uniformly random (Poisson) sampling of a smooth surface; it
        underestimates regular grids (by up to ~40% on a hexagonal lattice)
        and is skewed by duplicate points, so call it on a cleaned cloud.
    """
    vertices = np.asarray(shape.vertices, dtype=np.float64)
    if shape.faces is None:
        k = min(7, len(vertices))
        distances, _ = cKDTree(vertices).query(vertices, k=k)
        return float(np.pi * np.sum(distances[:, -1] ** 2) / 6.0)
    corners = vertices[np.asarray(shape.faces)]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return float(0.5 * np.linalg.norm(cross, axis=1).sum())


def vertex_normals(shape: Shape, k: int = 12) -> np.ndarray:
    """Unit normal at every vertex.

    Parameters
    ----------
    shape : Shape
        Mesh or point cloud with N vertices.
    k : int
        Point clouds only: number of nearest neighbours used to fit the
        tangent plane (clipped to N - 1); must be >= 2.

    Returns
    -------
    np.ndarray
        (N, 3) float64 unit vectors.

    Notes
    -----
    Meshes: area-weighted face normals summed at the vertices, so the
    orientation follows the face winding. A vertex whose sum vanishes (e.g.
    unreferenced) takes the normal of the nearest vertex with a valid one,
    or (0, 0, 1) if there is none.

    Point clouds (Hoppe et al. 1992): the normal is the smallest principal
    direction of the point and its k nearest neighbours. Orientation is made
    consistent by propagation along a minimum spanning tree of the kNN graph
    with edge weights ``1 - |n_i . n_j|``; each connected component is then
    flipped so that most of its normals point away from its centroid.
    """
    if k < 2:
        raise ValueError(f"k must be at least 2, got {k}")
    vertices = np.asarray(shape.vertices, dtype=np.float64)
    if shape.faces is None:
        return _cloud_normals(vertices, k)
    return _mesh_normals(vertices, np.asarray(shape.faces))


def _mesh_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (N, 3) of a triangle mesh."""
    n = len(vertices)
    corners = vertices[faces]
    face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    flat = faces.ravel()
    sums = np.stack(
        [
            np.bincount(flat, weights=np.repeat(face_normals[:, c], 3), minlength=n)
            for c in range(3)
        ],
        axis=1,
    )
    length = np.linalg.norm(sums, axis=1)
    valid = length > 0
    normals = np.zeros_like(sums)
    normals[valid] = sums[valid] / length[valid, None]
    if not valid.all():
        if valid.any():
            _, nearest = cKDTree(vertices[valid]).query(vertices[~valid])
            normals[~valid] = normals[np.flatnonzero(valid)[nearest]]
        else:
            normals[:] = (0.0, 0.0, 1.0)
    return normals


def _cloud_normals(points: np.ndarray, k: int) -> np.ndarray:
    """PCA normals (N, 3) of a point cloud, consistently oriented (see vertex_normals)."""
    n = len(points)
    k = min(k, n - 1)
    _, neighbours = cKDTree(points).query(points, k=k + 1)
    patches = points[neighbours]
    patches = patches - patches.mean(axis=1, keepdims=True)
    covariance = np.einsum("nki,nkj->nij", patches, patches)
    _, eigenvectors = np.linalg.eigh(covariance)
    normals = eigenvectors[:, :, 0]

    # kNN graph; weights 2 - |n_i.n_j| give the same spanning tree as 1 - |n_i.n_j|
    # but are never zero, which sparse graphs would read as a missing edge.
    rows = np.repeat(np.arange(n), k + 1)
    cols = neighbours.ravel()
    keep = rows != cols
    rows, cols = rows[keep], cols[keep]
    weights = 2.0 - np.abs(np.einsum("ij,ij->i", normals[rows], normals[cols]))
    tree = minimum_spanning_tree(coo_matrix((weights, (rows, cols)), shape=(n, n)).tocsr())
    n_components, component = connected_components(tree, directed=False)

    # Root every component's tree at a virtual node n, so one BFS gives all parents.
    _, roots = np.unique(component, return_index=True)
    tree = tree.tocoo()
    forest = coo_matrix(
        (
            np.concatenate([tree.data, np.ones(n_components)]),
            (
                np.concatenate([tree.row, np.full(n_components, n)]),
                np.concatenate([tree.col, roots]),
            ),
        ),
        shape=(n + 1, n + 1),
    ).tocsr()
    _, predecessors = breadth_first_order(forest, n, directed=False, return_predecessors=True)
    parent = predecessors[:n].copy()
    parent[roots] = roots

    # sign[i]: flip of i relative to parent[i]; pointer jumping turns it into the
    # flip relative to the component root in O(log depth) vectorised steps.
    sign = np.where(np.einsum("ij,ij->i", normals, normals[parent]) < 0, -1.0, 1.0)
    while not np.array_equal(parent, parent[parent]):
        sign = sign * sign[parent]
        parent = parent[parent]
    normals = normals * sign[:, None]

    counts = np.bincount(component, minlength=n_components)
    centroids = (
        np.stack(
            [
                np.bincount(component, weights=points[:, c], minlength=n_components)
                for c in range(3)
            ],
            axis=1,
        )
        / counts[:, None]
    )
    outward = np.einsum("ij,ij->i", normals, points - centroids[component]) > 0
    votes = np.bincount(component, weights=np.where(outward, 1.0, -1.0), minlength=n_components)
    return normals * np.where(votes < 0, -1.0, 1.0)[component, None]
