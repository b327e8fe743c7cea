"""The PLY header, and binary PLY (:func:`read_binary`).

trimesh reads ASCII PLY (:func:`intrinsym.mesh.io.load`), but its binary reader takes every
list of an element to be as long as the first one: it refuses a file whose faces mix
triangles, quads and n-gons, as Blender's PLY export writes them, and misreads one
whose sizes happen to add up. :func:`read_binary` reads binary PLY here: in one NumPy
view when every face has as many corners as the first (checked), else row by row (a
row's length is known only once its counts are read), in a plain loop of a few
microseconds a row.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .io_text import fan_triangulate, quote_token

#: PLY's scalar type names (both spellings of the standard) and their NumPy kinds.
PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}

#: struct's codes of the integer kinds of :data:`PLY_TYPES`, for a list's count.
STRUCT_CODES = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I"}

#: Names of the face element's list of vertex indices, as exporters write them.
INDEX_LISTS = ("vertex_indices", "vertex_index")


@dataclass(frozen=True)
class Property:
    """One property of a PLY element: ``kind`` is a NumPy type code without byte order
    (None for a type this module does not know), ``count_kind`` that of a list's count
    (None for a scalar)."""

    name: str
    kind: str | None
    count_kind: str | None = None


@dataclass(frozen=True)
class Element:
    """One element of a PLY header: its name, number of rows and properties."""

    name: str
    count: int
    properties: tuple[Property, ...]


@dataclass(frozen=True)
class Header:
    """A PLY header.

    Attributes
    ----------
    format : str
        ``"ascii"``, ``"binary_little_endian"`` or ``"binary_big_endian"``.
    elements : tuple of Element
        In file order.
    lines : int
        Number of lines up to and including ``end_header``.
    data_start : int
        Byte offset of the data after the header.
    """

    format: str
    elements: tuple[Element, ...]
    lines: int
    data_start: int

    def count(self, name: str) -> int:
        """Declared number of rows of element ``name`` (0 when there is none)."""
        return next((e.count for e in self.elements if e.name == name), 0)


def read_header(path: str, label: str) -> Header:
    """Read the header of the PLY file ``path``; :class:`InputError` when it is not one."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 20)
    except OSError as err:
        raise InputError(f"{label}: cannot read file ({err.strerror or err})") from None
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise InputError(f"{label}: not a PLY file (missing 'ply' magic or 'end_header')")
    newline = head.find(b"\n", end)
    data_start = len(head) if newline < 0 else newline + 1
    lines = head[:end].decode("ascii", errors="replace").splitlines()
    fmt = ""
    elements: list[Element] = []
    for line in lines:
        tokens = line.split()
        if len(tokens) >= 2 and tokens[0] == "format":
            fmt = tokens[1]
        elif len(tokens) >= 3 and tokens[0] == "element":
            if not tokens[2].isdigit():
                raise InputError(f"{label}: corrupt PLY header: bad element count {quote_token(tokens[2])}")
            elements.append(Element(tokens[1], int(tokens[2]), ()))
        elif len(tokens) >= 3 and tokens[0] == "property" and elements:
            if tokens[1] == "list" and len(tokens) >= 5:
                count_kind = PLY_TYPES.get(tokens[2])
                integral = count_kind is not None and count_kind[0] in "iu"
                prop = Property(tokens[4], PLY_TYPES.get(tokens[3]) if integral else None, count_kind)
            else:
                prop = Property(tokens[-1], PLY_TYPES.get(tokens[1]))
            last = elements[-1]
            elements[-1] = Element(last.name, last.count, (*last.properties, prop))
    return Header(fmt, tuple(elements), len(lines) + 1, data_start)


def read_binary(path: str, label: str, header: Header) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a binary PLY file whose lists may differ in length from row to row.

    Parameters
    ----------
    path : str
        File to read.
    label : str
        The name that starts every error message.
    header : Header
        Its header (:func:`read_header`), of a binary format.

    Returns
    -------
    vertices : np.ndarray
        (N, 3) float64 ``x``, ``y``, ``z`` of the vertex element.
    faces : np.ndarray or None
        (F, 3) int64 triangles, every polygon fan-triangulated from its first corner in
        file order, as the OFF and OBJ readers do; None without faces.

    Raises
    ------
    InputError
        When the data do not match the header (truncated, a list running past the end,
        bytes left over) or a property type is unknown.
    """
    order = "<" if header.format == "binary_little_endian" else ">"
    try:
        with open(path, "rb") as fh:
            fh.seek(header.data_start)
            data = fh.read()
    except OSError as err:
        raise InputError(f"{label}: cannot read file ({err.strerror or err})") from None
    vertices = None
    polygons = None
    position = 0
    for element in header.elements:
        kinds = [p.kind for p in element.properties]
        if None in kinds:
            raise InputError(f"{label}: unsupported PLY property type in element {quote_token(element.name)}")
        if all(p.count_kind is None for p in element.properties):
            dtype = np.dtype([(f"p{i}", f"{order}{kind}") for i, kind in enumerate(kinds)])
            end = position + element.count * dtype.itemsize
            if end > len(data):
                raise _truncated(label, element)
            rows = np.frombuffer(data, dtype=dtype, count=element.count, offset=position)
            if element.name == "vertex":
                names = [p.name for p in element.properties]
                if not {"x", "y", "z"} <= set(names):
                    raise InputError(f"{label}: the PLY vertex element has no x, y and z")
                with np.errstate(invalid="ignore"):  # NaN are refused with their count by from_arrays
                    vertices = np.column_stack([rows[f"p{names.index(c)}"].astype(np.float64) for c in "xyz"])
            position = end
        else:
            position, found = _list_rows(data, position, element, order, label)
            if element.name == "face":
                polygons = found
    if position != len(data):
        raise InputError(
            f"{label}: truncated or corrupt PLY file: {len(data) - position} bytes after the data the header declares"
        )
    if vertices is None:
        raise InputError(f"{label}: the PLY file has no vertex element")
    if polygons is None or len(polygons[1]) == 0:
        return vertices, None
    flat, lengths = polygons
    if (lengths < 3).any():
        row = int(np.flatnonzero(lengths < 3)[0])
        raise InputError(f"{label}: PLY face {row} has {int(lengths[row])} corners, at least 3 are needed")
    triangles, _ = fan_triangulate(flat, lengths)
    return vertices, triangles


def _truncated(label: str, element: Element) -> InputError:
    """The error for data that end inside ``element``."""
    return InputError(
        f"{label}: truncated or corrupt PLY file: the data end before the {element.count} rows of "
        f"element {quote_token(element.name)} the header declares"
    )


def _list_rows(
    data: bytes, position: int, element: Element, order: str, label: str
) -> tuple[int, tuple[np.ndarray, np.ndarray] | None]:
    """Walk the rows of an element with list properties from byte ``position``.

    Returns the position after its last row and, when the element has a list of vertex
    indices (:data:`INDEX_LISTS`), that list's indices of all rows in one (K,) int64
    array and the (rows,) int64 length of each.
    """
    steps = []  # per property: the reader of a list's count (None for a scalar), the item size
    for p in element.properties:
        count = None if p.count_kind is None else struct.Struct(order + STRUCT_CODES[p.count_kind])
        steps.append((count, np.dtype(p.kind).itemsize))
    if element.count * sum(size if count is None else count.size for count, size in steps) > len(data) - position:
        raise _truncated(label, element)  # before allocating for a count a corrupt header may inflate
    wanted = next((i for i, p in enumerate(element.properties) if p.name in INDEX_LISTS), None)
    rows = _uniform_rows(data, position, element, order)
    if rows is not None:
        position += rows.nbytes
        if wanted is None:
            return position, None
        indices = rows[f"p{wanted}"].reshape(element.count, -1)
        return position, (indices.astype(np.int64).ravel(), np.full(element.count, indices.shape[1], dtype=np.int64))
    starts = np.zeros(element.count, dtype=np.int64)
    lengths = np.zeros(element.count, dtype=np.int64)
    end = len(data)
    try:
        for row in range(element.count):
            for i, (count, size) in enumerate(steps):
                if count is None:
                    position += size
                    continue
                (n,) = count.unpack_from(data, position)
                position += count.size
                if i == wanted:
                    starts[row], lengths[row] = position, n
                position += n * size
            if position > end:
                raise _truncated(label, element)
    except struct.error:  # a count past the end
        raise _truncated(label, element) from None
    if wanted is None:
        return position, None
    dtype = np.dtype(f"{order}{element.properties[wanted].kind}")
    first = np.cumsum(lengths) - lengths
    row_of = np.repeat(np.arange(element.count), lengths)
    byte = starts[row_of] + (np.arange(len(row_of)) - first[row_of]) * dtype.itemsize
    raw = np.frombuffer(data, dtype=np.uint8)[byte[:, None] + np.arange(dtype.itemsize)]
    return position, (raw.view(dtype).ravel().astype(np.int64), lengths)


def _uniform_rows(data: bytes, position: int, element: Element, order: str) -> np.ndarray | None:
    """The rows of ``element`` from byte ``position`` as one structured array (fields
    ``p0, p1...`` the properties, ``n<i>`` the count of list ``p<i>``) when every list
    has the length it has in the first row, as in most files; else None."""
    fields: list[tuple] = []
    offset = position
    for i, p in enumerate(element.properties):
        kind = np.dtype(f"{order}{p.kind}")
        if p.count_kind is None:
            fields.append((f"p{i}", kind))
            offset += kind.itemsize
            continue
        count = np.dtype(f"{order}{p.count_kind}")
        if offset + count.itemsize > len(data):
            return None
        n = int(np.frombuffer(data, dtype=count, count=1, offset=offset)[0])
        fields += [(f"n{i}", count), (f"p{i}", kind, (n,))]
        offset += count.itemsize + n * kind.itemsize
    dtype = np.dtype(fields)
    if position + element.count * dtype.itemsize > len(data):
        return None
    rows = np.frombuffer(data, dtype=dtype, count=element.count, offset=position)
    for name in dtype.names or ():
        if name.startswith("n") and (rows[name] != rows[name][:1]).any():
            return None
    return rows
