"""Tests of intrinsym.mesh.io: file formats and the one-line errors for bad files."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

import intrinsym
from conftest import PYRAMID_F, PYRAMID_V, mirror_shape, shared, sphere_points
from intrinsym.errors import InputError
from intrinsym.mesh.io import load
from intrinsym.mesh.shape import clean, surface_area


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def raises_one_line(path, match: str, **kwargs) -> InputError:
    """Load ``path`` expecting an InputError whose message is one line starting with the path."""
    with pytest.raises(InputError, match=match) as info:
        load(path, **kwargs)
    message = str(info.value)
    assert "\n" not in message and "\r" not in message
    assert message.startswith(str(path) + ": ")
    return info.value


# ---------------------------------------------------------------------------
# round trips
# ---------------------------------------------------------------------------


def test_off_round_trip_with_comments_quad_and_colours(tmp_path):
    text = (
        "# a pyramid\nOFF\n\n5 5 0   # counts\n"
        + "".join(f"{x} {y} {z}\n" for x, y, z in PYRAMID_V)
        + "4 0 3 2 1\n3 0 1 4 255 0 0\n3 1 2 4\n3 2 3 4\n3 3 0 4\n"
    )
    shape = load(write(tmp_path, "pyramid.off", text))
    np.testing.assert_array_equal(shape.vertices, PYRAMID_V)
    np.testing.assert_array_equal(shape.faces, PYRAMID_F)
    assert shape.vertices.dtype == np.float64 and shape.faces.dtype == np.int64
    assert not shape.is_cloud
    assert shape.path == str(tmp_path / "pyramid.off")


def test_off_counts_on_header_line_coff_and_uppercase_extension(tmp_path):
    text = (
        "COFF 5 6 0\n"
        + "".join(f"{x} {y} {z} 0.1 0.2 0.3 1.0\n" for x, y, z in PYRAMID_V)
        + "".join(f"3 {a} {b} {c}\n" for a, b, c in PYRAMID_F)
    )
    shape = load(write(tmp_path, "PYRAMID.OFF", text))
    np.testing.assert_array_equal(shape.vertices, PYRAMID_V)
    np.testing.assert_array_equal(shape.faces, PYRAMID_F)


def test_off_without_faces_is_a_point_cloud(tmp_path):
    text = "OFF\n5 0 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in PYRAMID_V)
    shape = load(write(tmp_path, "cloud.off", text))
    assert shape.is_cloud and shape.faces is None
    np.testing.assert_array_equal(shape.vertices, PYRAMID_V)


def test_obj_with_texture_normals_negative_indices_and_quads(tmp_path):
    text = """# exported
mtllib pyramid.mtl
o pyramid
v 0 0 0
v 1 0 0 0.5 0.5 0.5
v 1 1 0
v 0 1 0
v 0.5 0.5 1.0
vt 0 0
vt 1 0
vt 1 1
vn 0 0 1
g base
usemtl stone
s off
f 1/1/1 4/2/1 3/3/1 2/1/1
s 1
f 1//1 2//1 5//1
f -4/1 -3/2 -1/3
f 3 4 5
f -2/1/1 -5/2/1 -1/3/1
"""
    shape = load(write(tmp_path, "pyramid.obj", text))
    np.testing.assert_array_equal(shape.vertices, PYRAMID_V)
    np.testing.assert_array_equal(shape.faces, PYRAMID_F)


def test_obj_with_latin1_comment_and_names(tmp_path):
    text = (
        "# Würfel, exportiert für den Test\nmtllib würfel.mtl\no Würfel\ng Fläche\nusemtl Grün\n"
        + "".join(f"v {x} {y} {z}\n" for x, y, z in PYRAMID_V)
        + "f 1 4 3 2 # Böden\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n"
    )
    path = tmp_path / "würfel.obj"
    path.write_bytes(text.encode("latin-1"))
    shape = load(path)
    np.testing.assert_array_equal(shape.vertices, PYRAMID_V)
    np.testing.assert_array_equal(shape.faces, PYRAMID_F)
    # the same bytes where geometry is read are refused, naming the line
    path.write_bytes(text.replace("v 1.0 0.0 0.0", "v 1.0 0.0 0.0\xb0").encode("latin-1"))
    raises_one_line(path, "line 7: not a text file")
    path.write_bytes(("vé 0 0 0\n" + text).encode("latin-1"))
    raises_one_line(path, "line 1: not a text file")
    off = "OFF # Würfel\n5 5 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in PYRAMID_V)
    off += "4 0 3 2 1\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n"
    (tmp_path / "latin.off").write_bytes(off.encode("latin-1"))
    np.testing.assert_array_equal(load(tmp_path / "latin.off").faces, PYRAMID_F)
    (tmp_path / "latin.off").write_bytes(off.replace("1.0 0.0 0.0", "1.0 0.0 0.0°").encode("latin-1"))
    raises_one_line(tmp_path / "latin.off", "line 4: not a text file")


def test_latin1_comment_in_ascii_ply_and_solid_name_in_ascii_stl(tmp_path):
    box = trimesh.creation.box()
    ply = trimesh.exchange.ply.export_ply(box, encoding="ascii")
    ply = ply.replace(b"format ascii 1.0\n", "format ascii 1.0\ncomment Würfel\n".encode("latin-1"))
    (tmp_path / "box.ply").write_bytes(ply)
    np.testing.assert_array_equal(load(tmp_path / "box.ply").faces, box.faces)
    (tmp_path / "box.ply").write_bytes(ply.replace(b"end_header\n", b"end_header\n\xfc"))
    raises_one_line(tmp_path / "box.ply", "truncated or corrupt PLY file")  # not in a comment
    stl = trimesh.exchange.stl.export_stl_ascii(box).replace("solid", "solid Würfel", 1).encode("latin-1")
    (tmp_path / "box.stl").write_bytes(stl)
    assert load(tmp_path / "box.stl").faces.shape == (12, 3)


def test_obj_with_only_vertices_is_a_point_cloud(tmp_path):
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in PYRAMID_V)
    shape = load(write(tmp_path, "points.obj", text))
    assert shape.is_cloud
    np.testing.assert_array_equal(shape.vertices, PYRAMID_V)


@pytest.mark.parametrize("encoding", ["ascii", "binary"])
def test_ply_mesh_round_trip(tmp_path, encoding):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    path = tmp_path / "sphere.ply"
    sphere.export(path, encoding=encoding)
    shape = load(path)
    np.testing.assert_allclose(shape.vertices, sphere.vertices, atol=1e-6)  # PLY stores float32
    np.testing.assert_array_equal(shape.faces, sphere.faces)


@pytest.mark.parametrize("encoding", ["ascii", "binary"])
def test_ply_without_faces_is_a_point_cloud(tmp_path, encoding):
    points = sphere_points(50)
    path = tmp_path / "cloud.ply"
    trimesh.PointCloud(points).export(path, encoding=encoding)
    shape = load(path)
    assert shape.is_cloud
    np.testing.assert_allclose(shape.vertices, points, atol=1e-6)


@pytest.mark.parametrize("file_type", ["stl", "stl_ascii"])
def test_stl_round_trip_after_clean(tmp_path, file_type):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    path = tmp_path / "sphere.stl"
    sphere.export(path, file_type=file_type)
    shape = load(path)
    assert shape.faces.shape == sphere.faces.shape
    assert len(shape.vertices) == 3 * len(sphere.faces)  # STL corners are not shared
    cleaned, vertex_map = clean(shape)
    assert len(cleaned.vertices) == len(sphere.vertices)
    assert len(cleaned.faces) == len(sphere.faces)
    np.testing.assert_allclose(cleaned.vertices[vertex_map], shape.vertices)
    assert surface_area(cleaned) == pytest.approx(sphere.area, rel=1e-5)


def test_xyz_with_comments_and_extra_columns(tmp_path):
    points = sphere_points(20)
    lines = ["# x y z nx ny nz", ""] + [
        f"{float(x)!r} {float(y)!r} {float(z)!r}  {x:.3f} {y:.3f} {z:.3f}" for x, y, z in points
    ]
    shape = load(write(tmp_path, "points.xyz", "\n".join(lines) + "\n"))
    assert shape.is_cloud
    np.testing.assert_array_equal(shape.vertices, points)


@pytest.mark.parametrize("columns", [3, 6])
def test_npy_point_cloud(tmp_path, columns):
    data = np.random.default_rng(1).normal(size=(30, columns)).astype(np.float32)
    path = tmp_path / "points.npy"
    np.save(path, data)
    shape = load(path)
    assert shape.is_cloud and shape.vertices.dtype == np.float64
    np.testing.assert_array_equal(shape.vertices, data[:, :3].astype(np.float64))


# ---------------------------------------------------------------------------
# input errors
# ---------------------------------------------------------------------------


def test_unknown_extension(tmp_path):
    raises_one_line(
        tmp_path / "x.foo",
        r"unknown file type '\.foo' \(expected \.off, \.obj, \.ply, \.stl, \.xyz or \.npy\)",
    )


def test_missing_file_and_directory(tmp_path):
    raises_one_line(tmp_path / "missing.off", "no such file")
    folder = tmp_path / "folder.obj"
    folder.mkdir()
    raises_one_line(folder, "is a directory")


@pytest.mark.parametrize("ext", [".off", ".obj", ".ply", ".stl", ".xyz", ".npy"])
def test_empty_file(tmp_path, ext):
    path = tmp_path / f"empty{ext}"
    path.write_bytes(b"")
    raises_one_line(path, "empty file")


@pytest.mark.parametrize("name", ["comments.off", "comments.obj", "comments.xyz"])
def test_file_with_only_comments_is_empty(tmp_path, name):
    raises_one_line(write(tmp_path, name, "# nothing here\n\n   # still nothing\n"), "empty file")


@pytest.mark.parametrize(
    ("name", "text", "match"),
    [
        (
            "bad.off",
            "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 abc\n0 0 1\n3 0 1 2\n",
            r"line 5: non-numeric value 'abc'",
        ),
        (
            "bad.off",
            "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 x 2\n",
            r"line 7: non-integer value 'x'",
        ),
        ("bad.off", "OFF\nfour 1 0\n", r"line 2: expected vertex and face counts"),
        (
            "bad.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 zz\nv 0 0 1\nf 1 2 3\n",
            r"line 3: non-numeric value 'zz'",
        ),
        (
            "bad.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 q/1\n",
            r"line 5: non-integer value 'q'",
        ),
        ("bad.xyz", "0 0 0\n1 0 0\n# c\n0 1 0\n0 0 1,5\n", r"line 5: non-numeric value '1,5'"),
        ("bad.xyz", "0 0 0\n1 0 0\n0 1 0\n0 0 one\n", r"line 4: non-numeric value 'one'"),
    ],
)
def test_non_numeric_token_names_the_line(tmp_path, name, text, match):
    raises_one_line(write(tmp_path, name, text), match)


def test_non_numeric_in_ascii_ply_and_stl(tmp_path):
    box = trimesh.creation.box()
    ply = tmp_path / "box.ply"
    box.export(ply, encoding="ascii")
    lines = ply.read_text().splitlines()
    body = lines.index("end_header") + 1
    lines[body + 2] = "0.5 oops 0.5"
    ply.write_text("\n".join(lines) + "\n")
    raises_one_line(ply, rf"line {body + 3}: non-numeric value 'oops'")

    stl = tmp_path / "box.stl"
    box.export(stl, file_type="stl_ascii")
    lines = stl.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if line.strip().startswith("vertex"))
    lines[first] = "vertex 0.5 bad 0.5"
    stl.write_text("\n".join(lines) + "\n")
    raises_one_line(stl, rf"line {first + 1}: non-numeric value 'bad'")


@pytest.mark.parametrize(
    ("name", "text", "match"),
    [
        (
            "nan.off",
            "OFF\n4 1 0\n0 0 0\n1 nan 0\n0 1 0\n0 0 1\n3 0 1 2\n",
            "line 4: NaN or infinite",
        ),
        ("inf.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 -inf\nf 1 2 3\n", "line 4: NaN or infinite"),
        ("nan.xyz", "0 0 0\n1 0 0\nNaN 1 0\n0 0 1\n", "line 3: NaN or infinite"),
    ],
)
def test_nan_or_inf_coordinates_in_text(tmp_path, name, text, match):
    raises_one_line(write(tmp_path, name, text), match)


def test_nan_in_npy_and_ply(tmp_path):
    data = sphere_points(10)
    data[3, 1] = np.nan
    np.save(tmp_path / "nan.npy", data)
    raises_one_line(tmp_path / "nan.npy", "NaN or infinite coordinates")
    mesh = trimesh.creation.box()
    mesh.vertices[2, 0] = np.inf
    mesh.export(tmp_path / "inf.ply", encoding="binary")
    raises_one_line(tmp_path / "inf.ply", "NaN or infinite coordinates")


def test_truncated_off(tmp_path):
    vertices = "".join(f"{i} 0 {i * i}\n" for i in range(120))
    raises_one_line(
        write(tmp_path, "cat.off", "OFF\n27894 55712 0\n" + vertices),
        "truncated file: header declares 27894 vertices, found 120",
    )
    text = "OFF\n5 6 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in PYRAMID_V) + "3 0 1 4\n"
    raises_one_line(write(tmp_path, "short.off", text), "truncated file: header declares 6 faces, found 1")


@pytest.mark.parametrize("ext", [".ply", ".stl"])
def test_truncated_binary_ply_and_stl(tmp_path, ext):
    path = tmp_path / f"sphere{ext}"
    trimesh.creation.icosphere(subdivisions=2).export(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    raises_one_line(path, "truncated or corrupt")


def test_truncated_ascii_ply(tmp_path):
    path = tmp_path / "box.ply"
    trimesh.creation.box().export(path, encoding="ascii")
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[: lines.index("end_header") + 12]) + "\n")
    raises_one_line(path, "truncated or corrupt PLY file: header declares 12 faces, found 3")


def test_corrupt_npy(tmp_path):
    path = tmp_path / "points.npy"
    np.save(path, sphere_points(100))
    path.write_bytes(path.read_bytes()[:300])
    raises_one_line(path, "truncated or corrupt .npy file")
    np.save(path, np.zeros((50, 2)))
    raises_one_line(path, r"expected an \(N, 3\) array of points, found shape \(50, 2\)")
    np.save(path, np.zeros(12))
    raises_one_line(path, r"found shape \(12,\)")
    np.save(path, np.zeros((5, 3), dtype=complex))
    raises_one_line(path, "expected a real-valued array")


@pytest.mark.parametrize(
    ("name", "text", "match"),
    [
        (
            "oor.off",
            "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 4\n",
            "line 8: face index 4 out of range",
        ),
        (
            "neg.off",
            "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 -1 2\n",
            "line 7: face index -1 out of range",
        ),
        (
            "oor.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1/1 2/2 9/3\n",
            "line 6: face index 9 out of range",
        ),
        (
            "rel.obj",
            "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\nv 0 0 1\n",
            "line 3: relative face index points before the first vertex",
        ),
        (
            "zero.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 0 1 2\n",
            "line 5: face index 0 is invalid",
        ),
        (
            "two.off",
            "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n2 0 1\n",
            "line 7: a face needs at least 3 vertices",
        ),
        (  # beyond int64: parsed line by line, not by NumPy
            "huge.off",
            "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 100000000000000000000\n",
            "line 8: face index 100000000000000000000 out of range",
        ),
        (
            "huge.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 100000000000000000000\n",
            "line 6: face index 100000000000000000000 out of range",
        ),
        (
            "huge_relative.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 -100000000000000000000\n",
            "line 6: relative face index points before the first vertex",
        ),
    ],
)
def test_bad_face_indices(tmp_path, name, text, match):
    raises_one_line(write(tmp_path, name, text), match)


def test_face_index_out_of_range_in_ply(tmp_path):
    path = tmp_path / "box.ply"
    trimesh.creation.box().export(path, encoding="ascii")
    text = path.read_text()
    lines = text.splitlines()
    lines[-1] = "3 7 5 99"
    path.write_text("\n".join(lines) + "\n")
    raises_one_line(path, "face index 99 out of range")


def write_binary_ply(path: Path, vertices: np.ndarray, polygons: list, byte_order: str = "<") -> bytes:
    """Write a binary PLY as Blender does (float x y z, uchar r g b, one uint index list per
    face, whatever its number of corners); returns the data after the header."""
    endian = "little" if byte_order == "<" else "big"
    header = (
        f"ply\nformat binary_{endian}_endian 1.0\ncomment written by a test\nelement vertex {len(vertices)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        f"element face {len(polygons)}\nproperty list uchar uint vertex_indices\nend_header\n"
    )
    rows = np.zeros(len(vertices), dtype=[("xyz", f"{byte_order}f4", 3), ("rgb", "u1", 3)])
    rows["xyz"], rows["rgb"] = vertices, 200
    faces = b"".join(struct.pack(f"{byte_order}B{len(p)}I", len(p), *p) for p in polygons)
    data = rows.tobytes() + faces
    path.write_bytes(header.encode() + data)
    return data


@pytest.mark.parametrize("byte_order", ["<", ">"])
def test_binary_ply_with_quads_and_triangles(tmp_path, byte_order):
    polygons = [[0, 3, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]
    write_binary_ply(tmp_path / "pyramid.ply", PYRAMID_V, polygons, byte_order)
    shape = load(tmp_path / "pyramid.ply")
    np.testing.assert_array_equal(shape.vertices, PYRAMID_V)
    np.testing.assert_array_equal(shape.faces, PYRAMID_F)  # fan-triangulated in file order, as OFF and OBJ
    lines = [" ".join(map(str, v)) + " 200 200 200" for v in PYRAMID_V] + [
        f"{len(p)} " + " ".join(map(str, p)) for p in polygons
    ]
    ascii_header = (tmp_path / "pyramid.ply").read_bytes().split(b"end_header")[0].decode()
    ascii_header = ascii_header.replace(f"binary_{'little' if byte_order == '<' else 'big'}_endian", "ascii")
    ascii_shape = load(write(tmp_path, "ascii.ply", ascii_header + "end_header\n" + "\n".join(lines) + "\n"))
    assert sorted(map(sorted, shape.faces.tolist())) == sorted(map(sorted, ascii_shape.faces.tolist()))


def test_binary_ply_whose_face_sizes_add_up_is_read_row_by_row(tmp_path):
    # a quad, a triangle and a pentagon take as many bytes as three quads: trimesh read
    # such a file as three quads, with indices made of the neighbours' bytes
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0], [3, 0.5, 0]])
    write_binary_ply(tmp_path / "mixed.ply", vertices, [[0, 1, 2, 3], [1, 4, 2], [4, 6, 5, 2, 1]])
    faces = load(tmp_path / "mixed.ply").faces
    np.testing.assert_array_equal(faces, [[0, 1, 2], [0, 2, 3], [1, 4, 2], [4, 6, 5], [4, 5, 2], [4, 2, 1]])


def test_binary_ply_prism_with_255_gon_caps(tmp_path):
    n = 255
    angle = 2 * np.pi * np.arange(n) / n
    ring = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(n)])
    vertices = np.vstack([ring, ring + [0, 0, 1]])
    sides = [[i, (i + 1) % n, n + (i + 1) % n, n + i] for i in range(n)]
    caps = [list(range(n))[::-1], list(range(n, 2 * n))]
    data = write_binary_ply(tmp_path / "prism.ply", vertices, sides + caps)
    shape = load(tmp_path / "prism.ply")
    assert shape.faces.shape == (2 * n + 2 * (n - 2), 3)
    cleaned, _ = clean(shape)
    side = n * 2 * np.sin(np.pi / n)
    cap = n * np.sin(2 * np.pi / n) / 2
    assert surface_area(cleaned) == pytest.approx(side + 2 * cap, rel=1e-5)
    # cut inside a face's list, or with bytes to spare: a one-line error
    header = (tmp_path / "prism.ply").read_bytes()[: -len(data)]
    (tmp_path / "cut.ply").write_bytes(header + data[:-100])
    raises_one_line(tmp_path / "cut.ply", "truncated or corrupt PLY file")
    (tmp_path / "long.ply").write_bytes(header + data + b"\0\0\0")
    raises_one_line(tmp_path / "long.ply", "truncated or corrupt PLY file: 3 bytes after the data")


def test_fewer_than_four_points(tmp_path):
    raises_one_line(write(tmp_path, "three.xyz", "0 0 0\n1 0 0\n0 1 0\n"), "only 3 points; at least 4")
    raises_one_line(write(tmp_path, "tri.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"), "only 3 points")


def test_file_too_large(tmp_path):
    path = write(tmp_path, "big.xyz", "0 0 0\n" * 100)
    raises_one_line(path, "file is 600 bytes, too large for the available memory", max_bytes=100)
    assert len(load(path, max_bytes=600).vertices) == 100


def test_unsupported_or_wrong_content(tmp_path):
    raises_one_line(write(tmp_path, "notoff.off", "PLY\n1 2 3\n"), "not an OFF file")
    raises_one_line(write(tmp_path, "four.off", "4OFF\n"), "unsupported OFF variant")
    raises_one_line(write(tmp_path, "notply.ply", "hello\n"), "not a PLY file")
    (tmp_path / "binary.obj").write_bytes(b"\x80\x81\x82 v 1 2 3")
    raises_one_line(tmp_path / "binary.obj", "not a text file")
    (tmp_path / "junk.stl").write_bytes(bytes(range(200)))
    raises_one_line(tmp_path / "junk.stl", "truncated or corrupt binary STL file")


# ---------------------------------------------------------------------------
# the shipped example and the shared research data (optional)
# ---------------------------------------------------------------------------


def test_load_shipped_example():
    shape = load(intrinsym.example_path())
    assert shape.vertices.shape == (2930, 3) and shape.faces.shape == (5856, 3)
    cleaned, vertex_map = clean(shape)
    np.testing.assert_array_equal(vertex_map, np.arange(2930))


def test_load_wolf_off():
    shape = load(shared("tosca_sym/wolf0.off"))
    assert shape.vertices.shape == (4344, 3) and shape.faces.shape == (8684, 3)
    cleaned, _ = clean(shape)
    assert cleaned.faces.shape == (8684, 3)


def test_off_with_more_faces_than_its_header_declares_is_an_error(tmp_path):
    path = tmp_path / "extra.off"
    path.write_text("OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 2 3\n")
    with pytest.raises(
        InputError, match=r"extra\.off: line 8: header declares 4 vertices and 1 faces, the file holds 1 more"
    ):
        intrinsym.load(path)
    path.write_text("OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    with pytest.raises(InputError, match="header declares 3 vertices and 0 faces"):
        intrinsym.load(path)


# ---------------------------------------------------------------------------
# vertex order of the results
# ---------------------------------------------------------------------------


def test_a_result_indexes_the_vertices_in_file_order(tmp_path):
    # an OBJ whose every face corner has its own texture coordinate: trimesh splits such
    # vertices unless asked to keep the file's order, as with the shipped spot.obj
    v, f, sym = mirror_shape()
    corners = "".join(f"vt {i / (3 * len(f))} 0.5\n" for i in range(3 * len(f)))
    faces = "".join(f"f {a + 1}/{3 * i + 1} {b + 1}/{3 * i + 2} {c + 1}/{3 * i + 3}\n" for i, (a, b, c) in enumerate(f))
    path = write(tmp_path, "bent.obj", "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in v.tolist()) + corners + faces)
    out = tmp_path / "out"
    params = intrinsym.make_params(n_source=40, n_target=400, spin_cloud=6000, iterations=20)
    intrinsym.detect(path, params).save(out)
    image = np.load(out / "symmetry_map.npy")
    assert (image >= 0).all()
    for vertices in (
        np.asarray(trimesh.load(path, process=False, maintain_order=True).vertices),
        intrinsym.load(path).vertices,
    ):
        assert vertices.shape == v.shape
        np.testing.assert_allclose(vertices, v)
        # the map sends every vertex of the file to (near) its mirror image
        assert np.linalg.norm(vertices[image] - vertices * [-1, 1, 1], axis=1).mean() < 0.02
    assert np.mean(image == sym) > 0.9
    assert len(trimesh.load(path, process=False).vertices) != len(image)  # trimesh's default order differs
