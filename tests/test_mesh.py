"""Tests of intrinsym.mesh: file formats, input errors, cleaning and basic geometry."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

from intrinsym.mesh import (
    InputError,
    Shape,
    check_memory,
    clean,
    from_arrays,
    load,
    surface_area,
    vertex_normals,
)

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"

# A square pyramid: quad base (0, 1, 2, 3) and apex 4.
PYRAMID_V = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1.0]], dtype=np.float64
)
PYRAMID_F = np.array(  # the quad fan-triangulated from its first corner, then the sides
    [[0, 3, 2], [0, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]], dtype=np.int64
)


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


def sphere_points(n: int, seed: int = 0, radius: float = 1.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    return radius * p / np.linalg.norm(p, axis=1, keepdims=True)


def shared(relative: str) -> Path:
    path = DATA / relative
    if not path.exists():
        pytest.skip(f"research data not available: {path} (the shared data folder is absent)")
    return path


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


def test_shape_arrays_are_read_only():
    shape = from_arrays(PYRAMID_V, PYRAMID_F)
    with pytest.raises(ValueError):
        shape.vertices[0, 0] = 5.0
    with pytest.raises(ValueError):
        shape.faces[0, 0] = 1
    assert isinstance(shape, Shape) and shape.path == ""


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
    raises_one_line(
        write(tmp_path, "short.off", text), "truncated file: header declares 6 faces, found 1"
    )


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


def test_fewer_than_four_points(tmp_path):
    raises_one_line(
        write(tmp_path, "three.xyz", "0 0 0\n1 0 0\n0 1 0\n"), "only 3 points; at least 4"
    )
    raises_one_line(
        write(tmp_path, "tri.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"), "only 3 points"
    )


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


@pytest.mark.parametrize(
    ("vertices", "faces", "match"),
    [
        (np.zeros((5, 2)), None, r"vertices must be an \(N, 3\) array"),
        ([["a", "b", "c"]] * 4, None, "not a numeric array"),
        (PYRAMID_V * 1j, None, "complex"),
        (
            np.vstack([PYRAMID_V, [[np.inf, 0, 0]]]),
            None,
            "1 vertices have NaN or infinite coordinates",
        ),
        (PYRAMID_V[:3], None, "only 3 points"),
        (PYRAMID_V, PYRAMID_F + 0.5, "whole numbers"),
        (PYRAMID_V, PYRAMID_F[:, :2], r"faces must be an \(F, 3\) array"),
        (PYRAMID_V, np.zeros((0, 3), dtype=int), "no faces"),
        (PYRAMID_V, PYRAMID_F + 1, "face index 5 out of range"),
        (PYRAMID_V, PYRAMID_F.astype(str), "must be integers"),
    ],
)
def test_from_arrays_validation(vertices, faces, match):
    with pytest.raises(InputError, match=match) as info:
        from_arrays(vertices, faces, path="mem.off")
    assert str(info.value).startswith("mem.off: ") and "\n" not in str(info.value)


def test_from_arrays_accepts_integral_float_faces_and_copies():
    vertices = PYRAMID_V.copy()
    shape = from_arrays(vertices, PYRAMID_F.astype(np.float64))
    assert shape.faces.dtype == np.int64
    vertices[0, 0] = 7.0
    assert shape.vertices[0, 0] == 0.0


def test_check_memory():
    check_memory(1, "a tiny buffer", "x.off")
    with pytest.raises(
        InputError,
        match=r"^x\.off: the distance matrix needs 1000000\.0 GB, "
        r"more than the .* GB of memory available$",
    ):
        check_memory(10**15, "the distance matrix", "x.off")


# ---------------------------------------------------------------------------
# clean
# ---------------------------------------------------------------------------


def test_clean_merges_and_drops_by_hand():
    vertices = np.array(
        [
            [0, 0, 0],  # 0
            [1, 0, 0],  # 1
            [0, 1, 0],  # 2
            [0, 0, 1],  # 3
            [0, 0, 0],  # 4: exact duplicate of 0
            [0.25, 0, 0],  # 5: only in a zero-area face -> dropped, nearest kept is 0
            [0, 0, 1.2],  # 6: unreferenced -> dropped, nearest kept is 3
            [0, 1 + 1e-13, 0],  # 7: near-duplicate of 2
        ]
    )
    faces = np.array(
        [
            [0, 1, 2],  # kept
            [0, 3, 1],  # kept
            [4, 2, 3],  # kept, becomes (0, 2, 3)
            [1, 7, 3],  # kept, becomes (1, 2, 3)
            [0, 0, 1],  # repeated index
            [0, 5, 1],  # zero area
            [2, 1, 0],  # duplicate of face 0 (reversed)
            [4, 1, 7],  # duplicate of face 0 after merging
        ]
    )
    cleaned, vertex_map = clean(from_arrays(vertices, faces, "hand.off"))
    np.testing.assert_array_equal(cleaned.vertices, vertices[:4])
    np.testing.assert_array_equal(cleaned.faces, [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 2, 3]])
    np.testing.assert_array_equal(vertex_map, [0, 1, 2, 3, 0, 0, 3, 2])
    assert vertex_map.dtype == np.int64
    assert cleaned.path == "hand.off"
    again, identity = clean(cleaned)
    np.testing.assert_array_equal(identity, np.arange(4))
    np.testing.assert_array_equal(again.faces, cleaned.faces)


def test_clean_keeps_components_and_clean_input_unchanged():
    a = trimesh.creation.icosphere(subdivisions=1)
    b = a.copy()
    b.apply_translation([5, 0, 0])
    both = trimesh.util.concatenate([a, b])
    cleaned, vertex_map = clean(from_arrays(both.vertices, both.faces))
    np.testing.assert_array_equal(cleaned.vertices, both.vertices)
    np.testing.assert_array_equal(cleaned.faces, both.faces)
    np.testing.assert_array_equal(vertex_map, np.arange(len(both.vertices)))


def test_clean_point_cloud_merges_duplicates_only():
    points = sphere_points(10)
    cloud = from_arrays(np.vstack([points, points[[2, 7]]]))
    cleaned, vertex_map = clean(cloud)
    assert cleaned.is_cloud
    np.testing.assert_array_equal(cleaned.vertices, points)
    np.testing.assert_array_equal(vertex_map, list(range(10)) + [2, 7])


def test_clean_errors_when_nothing_is_left():
    collinear = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], dtype=float)
    with pytest.raises(
        InputError, match=r"^line\.off: no usable faces: all 2 faces are degenerate"
    ):
        clean(from_arrays(collinear, [[0, 1, 2], [1, 2, 3]], "line.off"))
    with pytest.raises(InputError, match="only 1 distinct points"):
        clean(from_arrays(np.ones((6, 3))))


# ---------------------------------------------------------------------------
# geometry
# ---------------------------------------------------------------------------


def test_surface_area_of_cube_and_icosphere():
    box = trimesh.creation.box()
    assert surface_area(from_arrays(box.vertices, box.faces)) == pytest.approx(6.0, abs=1e-12)
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    assert surface_area(from_arrays(sphere.vertices, sphere.faces)) == pytest.approx(
        16 * np.pi, rel=0.01
    )


def test_surface_area_estimate_of_point_cloud():
    cloud = from_arrays(sphere_points(20000, seed=3, radius=2.0))
    assert surface_area(cloud) == pytest.approx(16 * np.pi, rel=0.10)


def test_mesh_vertex_normals_point_outward():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    normals = vertex_normals(from_arrays(sphere.vertices, sphere.faces))
    radial = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    assert np.einsum("ij,ij->i", normals, radial).min() > 0.99


def test_mesh_vertex_normals_for_unreferenced_vertex():
    box = trimesh.creation.box()
    vertices = np.vstack([box.vertices, [[0.6, 0.6, 0.6]]])  # near corner (0.5, 0.5, 0.5)
    normals = vertex_normals(from_arrays(vertices, box.faces))
    corner = np.flatnonzero((box.vertices == 0.5).all(axis=1))[0]
    np.testing.assert_allclose(normals[-1], normals[corner])
    assert np.all(normals[corner] > 0)


def test_point_cloud_normals_point_outward_on_sphere():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    radial = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    normals = vertex_normals(from_arrays(sphere.vertices))
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    assert np.einsum("ij,ij->i", normals, radial).min() > 0.99


def test_point_cloud_normals_two_components_and_torus():
    points = sphere_points(1500, seed=5)
    two = np.vstack([points, 0.5 * points + [10, 0, 0]])
    normals = vertex_normals(from_arrays(two))
    radial = np.vstack([points, points])
    assert np.einsum("ij,ij->i", normals, radial).min() > 0.9

    u, v = np.meshgrid(
        np.linspace(0, 2 * np.pi, 120, endpoint=False),
        np.linspace(0, 2 * np.pi, 40, endpoint=False),
    )
    u, v = u.ravel(), v.ravel()
    torus = np.stack(
        [(1 + 0.3 * np.cos(v)) * np.cos(u), (1 + 0.3 * np.cos(v)) * np.sin(u), 0.3 * np.sin(v)],
        axis=1,
    )
    truth = np.stack([np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), np.sin(v)], axis=1)
    normals = vertex_normals(from_arrays(torus), k=10)
    assert np.einsum("ij,ij->i", normals, truth).min() > 0.9


# ---------------------------------------------------------------------------
# shared research data (optional)
# ---------------------------------------------------------------------------


def test_load_spot_obj():
    shape = load(shared("static/spot.obj"))
    assert shape.vertices.shape == (2930, 3) and shape.faces.shape == (5856, 3)
    cleaned, vertex_map = clean(shape)
    np.testing.assert_array_equal(vertex_map, np.arange(2930))


def test_load_wolf_off():
    shape = load(shared("tosca_sym/wolf0.off"))
    assert shape.vertices.shape == (4344, 3) and shape.faces.shape == (8684, 3)
    cleaned, _ = clean(shape)
    assert cleaned.faces.shape == (8684, 3)


@pytest.mark.slow
def test_speed_of_normals_and_clean():
    cloud = from_arrays(sphere_points(50000, seed=9))
    start = time.perf_counter()
    vertex_normals(cloud)
    assert time.perf_counter() - start < 2.0
    sphere = trimesh.creation.icosphere(subdivisions=6)  # 40962 vertices
    soup = from_arrays(
        sphere.vertices[sphere.faces].reshape(-1, 3),
        np.arange(3 * len(sphere.faces)).reshape(-1, 3),
    )
    start = time.perf_counter()
    cleaned, _ = clean(soup)
    assert time.perf_counter() - start < 2.0
    assert len(cleaned.vertices) == len(sphere.vertices)
