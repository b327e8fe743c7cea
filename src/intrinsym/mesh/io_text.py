"""Parsers of the text formats: OFF, OBJ and XYZ.

Each reader returns the vertices (N, 3) float64 and the fan-triangulated faces
(F, 3) int64, or None for a point cloud, exactly as stored in the file; the shape is
validated by :func:`intrinsym.mesh.io.load`. Every problem is an
:class:`~intrinsym.errors.InputError` naming the file and, where there is one, the
line. Lines are parsed in C when they form a regular table, and line by line only
to report the exact problem otherwise. Text is UTF-8; other bytes are accepted in
comments (and in OBJ's names of objects, groups and materials), which carry no geometry.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import InputError


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
    """Decode file contents as UTF-8 text (BOM allowed), rejecting binary data.

    Bytes that are not UTF-8 become U+FFFD rather than an error: the formats declare no
    encoding, and a Latin-1 comment or object name carries no geometry. The parsers
    refuse them only where they would be data (:func:`_check_decoded`).
    """
    if b"\x00" in data:
        raise InputError(f"{label}: not a text file (contains NUL bytes)")
    return data.decode("utf-8-sig", errors="replace")


def _check_decoded(numbers: list[int], lines: list[str], label: str) -> None:
    """Raise InputError naming the first of ``lines`` (data, comments removed) that holds
    a byte that is not UTF-8 (U+FFFD after :func:`_decode`)."""
    for number, line in zip(numbers, lines, strict=True):
        if "\ufffd" in line:
            raise InputError(f"{label}: line {number}: not a text file (bytes that are not UTF-8 in the data)")


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


def _data_lines(path: str, label: str, all_data: bool = True) -> tuple[list[int], list[str], bool]:
    """:func:`_content_lines` of a text file; an :class:`InputError` when it has none.

    With ``all_data`` every line but comments is data, and one that holds a byte that
    is not UTF-8 is an error. Also returns whether the file holds such bytes (for the
    caller to check the lines it parses with :func:`_check_decoded` otherwise).
    """
    text = _decode(_read_bytes(path, label), label)
    numbers, lines = _content_lines(text)
    if not lines:
        raise InputError(f"{label}: empty file (no data lines)")
    undecodable = "\ufffd" in text
    if undecodable and all_data:
        _check_decoded(numbers, lines, label)
    return numbers, lines, undecodable


def quote_token(token: str) -> str:
    """Quote a token for an error message, shortened to 30 characters."""
    return repr(token if len(token) <= 30 else token[:27] + "...")


def _fast_table(lines: list[str], dtype: type) -> np.ndarray | None:
    """Parse whitespace-separated lines with the same number of columns in C.

    Returns an (n, c) array, or None when the lines are not such a table (the
    caller then parses line by line to report the exact problem).
    """
    if not all(line.strip() for line in lines):
        return None  # loadtxt skips blank lines (and warns when all are)
    try:
        table: np.ndarray = np.loadtxt(lines, dtype=dtype, comments=None, ndmin=2)
    except ValueError:
        return None
    return table


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
                raise InputError(f"{label}: line {number}: {what} needs 3 coordinates, found {len(values)}")
            try:
                out[i] = [float(t) for t in values]
            except ValueError:
                bad = next(t for t in values if not is_float(t))
                raise InputError(
                    f"{label}: line {number}: non-numeric value {quote_token(bad)} where a "
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


def is_float(token: str) -> bool:
    """True if ``float(token)`` succeeds."""
    try:
        float(token)
    except ValueError:
        return False
    return True


def _fan_triangulate(polygons: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fan_triangulate` of polygons given as vertex index lists."""
    lengths = np.fromiter((len(p) for p in polygons), dtype=np.int64, count=len(polygons))
    flat = np.fromiter((i for p in polygons for i in p), dtype=np.int64, count=int(lengths.sum()))
    return fan_triangulate(flat, lengths)


def fan_triangulate(flat: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate polygons of 3 or more vertices.

    Parameters
    ----------
    flat : np.ndarray
        (K,) int64 vertex indices of P polygons, one after the other.
    lengths : np.ndarray
        (P,) int64 number of vertices of each polygon, >= 3, summing to K.

    Returns
    -------
    triangles : np.ndarray
        (T, 3) int64; polygon ``[a, b, c, d]`` becomes ``(a, b, c), (a, c, d)``.
    source : np.ndarray
        (T,) int64 index of the polygon each triangle came from.
    """
    starts = np.cumsum(lengths) - lengths
    n_tris = lengths - 2
    source = np.repeat(np.arange(len(lengths), dtype=np.int64), n_tris)
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
    raise _index_error(label, numbers[source[t]], int(triangles[t, c]), n_vertices, one_based)


def _index_error(label: str, line: int, index: int, n_vertices: int, one_based: bool) -> InputError:
    """The error for the 0-based face ``index`` outside [0, n_vertices) on ``line``
    (see :func:`_check_indices`)."""
    if one_based and index < 0:
        return InputError(f"{label}: line {line}: relative face index points before the first vertex")
    shown = index + 1 if one_based else index
    return InputError(f"{label}: line {line}: face index {shown} out of range (the file has {n_vertices} vertices)")


def _non_integer_face(label: str, number: int, token: str) -> InputError:
    """The error for a face entry that is not an integer."""
    return InputError(f"{label}: line {number}: non-integer value {quote_token(token)} where a face index is expected")


def _off_faces(numbers: list[int], lines: list[str], n_vertices: int, label: str) -> tuple[np.ndarray, np.ndarray]:
    """Parse OFF face lines ``k i_1 ... i_k [colour]`` into fan-triangulated (T, 3) faces.

    Also returns the (T,) index of the line each triangle came from. Indices outside
    [0, n_vertices) are errors here when the lines are parsed one by one (they may
    not fit in int64), else by :func:`_check_indices`.
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
            raise InputError(f"{label}: line {number}: face declares {k} vertices but lists {len(tokens) - 1}")
        polygon = []
        for token in tokens[1 : k + 1]:
            try:
                index = int(token)
            except ValueError:
                raise _non_integer_face(label, number, token) from None
            if not 0 <= index < n_vertices:
                raise _index_error(label, number, index, n_vertices, one_based=False)
            polygon.append(index)
        polygons.append(polygon)
    return _fan_triangulate(polygons)


def read_off(path: str, label: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Parse an ASCII OFF file (also COFF, NOFF, STOFF...; colours and normals ignored).

    Parameters
    ----------
    path : str
        File to read.
    label : str
        The name that starts every error message (see
        :func:`~intrinsym.errors.path_label`).

    Returns
    -------
    vertices : np.ndarray
        (N, 3) float64 coordinates.
    faces : np.ndarray or None
        (F, 3) int64 0-based triangles, or None when the file has no faces.

    Raises
    ------
    InputError
        For any problem with the file, naming the line where there is one.
    """
    numbers, lines, _ = _data_lines(path, label)
    tokens = lines[0].split()
    match = re.fullmatch(r"(ST)?C?N?(4?n?)OFF(\d*)", tokens[0])
    if match is None:
        raise InputError(
            f"{label}: not an OFF file: line {numbers[0]} starts with {quote_token(tokens[0])}, expected 'OFF'"
        )
    if match.group(2):
        raise InputError(f"{label}: unsupported OFF variant {quote_token(tokens[0])} (only 3D OFF is supported)")
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
            f"{label}: line {number}: expected vertex and face counts, found {quote_token(' '.join(counts))}"
        )
    n_vertices, n_faces = int(counts[0]), int(counts[1])
    if n_vertices == 0:
        raise InputError(f"{label}: the header declares 0 vertices")
    stop = body + n_vertices
    if len(lines) < stop:
        raise InputError(f"{label}: truncated file: header declares {n_vertices} vertices, found {len(lines) - body}")
    vertices = _parse_points(numbers[body:stop], lines[body:stop], label, "vertex")
    if len(lines) > stop + n_faces:
        extra = len(lines) - stop - n_faces
        raise InputError(
            f"{label}: line {numbers[stop + n_faces]}: header declares {n_vertices} vertices and {n_faces} faces, "
            f"the file holds {extra} more line(s)"
        )
    if n_faces == 0:
        return vertices, None
    if len(lines) < stop + n_faces:
        raise InputError(f"{label}: truncated file: header declares {n_faces} faces, found {len(lines) - stop}")
    face_numbers = numbers[stop : stop + n_faces]
    triangles, source = _off_faces(face_numbers, lines[stop : stop + n_faces], n_vertices, label)
    _check_indices(triangles, source, face_numbers, n_vertices, label, one_based=False)
    return vertices, triangles


def _obj_faces(
    numbers: list[int], lines: list[str], n_before: np.ndarray, n_vertices: int, label: str
) -> tuple[np.ndarray, np.ndarray]:
    """Parse OBJ ``f`` records (keyword removed) into fan-triangulated 0-based (T, 3) faces.

    ``n_before[i]`` is the number of vertices defined before face line i (for
    negative, relative indices). Also returns the (T,) face-line index of each
    triangle. Indices outside the ``n_vertices`` are errors as in :func:`_off_faces`.
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
                raise InputError(f"{label}: line {number}: face index 0 is invalid (OBJ indices start at 1)")
            index = index - 1 if index > 0 else n_so_far + index
            if not 0 <= index < n_vertices:
                raise _index_error(label, number, index, n_vertices, one_based=True)
            polygon.append(index)
        if len(polygon) < 3:
            raise InputError(f"{label}: line {number}: a face needs at least 3 vertices, found {len(polygon)}")
        polygons.append(polygon)
    return _fan_triangulate(polygons)


def read_obj(path: str, label: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Parse a Wavefront OBJ file: ``v`` and ``f`` records; other records ignored.

    Face corners may be ``i``, ``i/t``, ``i/t/n`` or ``i//n``; negative indices
    are relative to the vertices read so far. Polygons are fan-triangulated.
    OBJ declares no encoding: bytes that are not UTF-8 (a Latin-1 comment or object
    name) are accepted outside the keywords and the ``v`` and ``f`` records.

    Parameters
    ----------
    path : str
        File to read.
    label : str
        The name that starts every error message (see
        :func:`~intrinsym.errors.path_label`).

    Returns
    -------
    vertices : np.ndarray
        (N, 3) float64 coordinates.
    faces : np.ndarray or None
        (F, 3) int64 0-based triangles, or None when the file has no faces.

    Raises
    ------
    InputError
        For any problem with the file, naming the line where there is one.
    """
    numbers, lines, undecodable = _data_lines(path, label, all_data=False)
    stripped = [line.lstrip() for line in lines]
    keys = [line.split(None, 1)[0] for line in stripped]
    v_rows = [i for i, key in enumerate(keys) if key == "v"]
    f_rows = [i for i, key in enumerate(keys) if key == "f"]
    if undecodable:  # allowed in the names of objects, groups, materials..., not in keys or data
        _check_decoded(numbers, [line if key in ("v", "f") else key for line, key in zip(stripped, keys)], label)
    if not v_rows:
        raise InputError(f"{label}: no vertices ('v' lines) found")
    vertices = _parse_points([numbers[i] for i in v_rows], [stripped[i][1:] for i in v_rows], label, "vertex")
    if not f_rows:
        return vertices, None
    face_numbers = [numbers[i] for i in f_rows]
    n_before = np.searchsorted(np.asarray(v_rows), np.asarray(f_rows))
    triangles, source = _obj_faces(face_numbers, [stripped[i][1:] for i in f_rows], n_before, len(vertices), label)
    _check_indices(triangles, source, face_numbers, len(vertices), label, one_based=True)
    return vertices, triangles


def read_xyz(path: str, label: str) -> tuple[np.ndarray, None]:
    """Parse an XYZ point file: ``x y z`` per line, extra columns (normals...) ignored.

    Parameters
    ----------
    path : str
        File to read.
    label : str
        The name that starts every error message (see
        :func:`~intrinsym.errors.path_label`).

    Returns
    -------
    vertices : np.ndarray
        (N, 3) float64 coordinates.
    faces : None
        Always None (a point cloud).

    Raises
    ------
    InputError
        For any problem with the file, naming the line where there is one.
    """
    numbers, lines, _ = _data_lines(path, label)
    return _parse_points(numbers, lines, label, "point"), None
