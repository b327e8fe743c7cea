"""Tests of intrinsym.mesh.shape: validation of arrays, cleaning and basic geometry."""

from __future__ import annotations

import time

import numpy as np
import pytest
import trimesh

import intrinsym
from conftest import PYRAMID_F, PYRAMID_V, mirror_shape, sphere_points
from intrinsym.errors import InputError
from intrinsym.mesh.shape import Shape, clean, from_arrays, orient_faces, surface_area, vertex_areas, vertex_normals

# ---------------------------------------------------------------------------
# construction and validation
# ---------------------------------------------------------------------------


def test_shape_arrays_are_read_only():
    shape = from_arrays(PYRAMID_V, PYRAMID_F)
    with pytest.raises(ValueError):
        shape.vertices[0, 0] = 5.0
    with pytest.raises(ValueError):
        shape.faces[0, 0] = 1
    assert isinstance(shape, Shape) and shape.path == ""


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
            [1, 7, 3],  # kept, becomes (1, 2, 3), wound as (3, 2, 1) like its neighbours
            [0, 0, 1],  # repeated index
            [0, 5, 1],  # zero area
            [2, 1, 0],  # duplicate of face 0 (reversed)
            [4, 1, 7],  # duplicate of face 0 after merging
        ]
    )
    cleaned, vertex_map = clean(from_arrays(vertices, faces, "hand.off"))
    np.testing.assert_array_equal(cleaned.vertices, vertices[:4])
    np.testing.assert_array_equal(cleaned.faces, [[0, 1, 2], [0, 3, 1], [0, 2, 3], [3, 2, 1]])
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


def _reversed(faces: np.ndarray, share: float, seed: int = 0) -> np.ndarray:
    """``faces`` with a random ``share`` of them wound the other way."""
    turn = np.random.default_rng(seed).random(len(faces)) < share
    out = np.array(faces)
    out[turn] = out[turn][:, ::-1]
    return out


def _consistent(vertices: np.ndarray, faces: np.ndarray) -> bool:
    return bool(trimesh.Trimesh(vertices, faces, process=False).is_winding_consistent)


def test_orient_faces_by_hand():
    # two triangles on the edge 1-2: (0, 1, 2) runs it 1 -> 2, so the other must run 2 -> 1
    np.testing.assert_array_equal(orient_faces(np.array([[0, 1, 2], [3, 1, 2]])), [[0, 1, 2], [2, 1, 3]])
    consistent = np.array([[0, 1, 2], [2, 1, 3]])
    assert orient_faces(consistent) is consistent


@pytest.mark.parametrize("share", [0.1, 0.4])
def test_orient_faces_restores_closed_and_open_meshes(share):
    sphere = trimesh.creation.icosphere(subdivisions=3)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    cap = f[(v[f][:, :, 2] > -0.3).all(axis=1)]  # open: a boundary loop
    for faces in (f, cap):
        mixed = _reversed(faces, share)
        assert not _consistent(v, mixed)
        oriented = orient_faces(mixed)
        assert _consistent(v, oriented)  # trimesh's own check of every shared edge
        np.testing.assert_array_equal(oriented, faces)  # the majority's winding: the original


def test_orient_faces_each_part_keeps_its_majority():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    f = np.asarray(sphere.faces)
    n = len(sphere.vertices)
    faces = np.vstack([f[:, ::-1], _reversed(f, 0.3) + n])  # part 1 all inward, part 2 mostly outward
    oriented = orient_faces(faces)
    np.testing.assert_array_equal(oriented[: len(f)], f[:, ::-1])
    np.testing.assert_array_equal(oriented[len(f) :], f + n)


def test_orient_faces_leaves_one_seam_on_a_moebius_strip_and_skips_non_manifold_edges():
    n = 12
    strip = []
    for i in range(n):  # quads between two rails, the last one joined with a half twist
        a, b = i, i + n
        c, d = (i + 1, i + 1 + n) if i < n - 1 else (n, 0)
        strip += [[a, b, c], [b, d, c]]
    oriented = orient_faces(_reversed(np.array(strip), 0.5))
    directed = np.stack([oriented.ravel(), oriented[:, [1, 2, 0]].ravel()], axis=1)
    assert len(directed) - len(np.unique(directed, axis=0)) == 1  # one edge run twice the same way
    book = np.array([[0, 1, 2], [0, 1, 3], [1, 0, 4]])  # three faces on the edge 0-1: no pair to agree
    assert orient_faces(book) is book


def test_clean_winds_faces_so_normals_come_back():
    v, f, _ = mirror_shape()
    cleaned, vertex_map = clean(from_arrays(v, _reversed(f, 0.3)))
    np.testing.assert_array_equal(vertex_map, np.arange(len(v)))
    np.testing.assert_array_equal(cleaned.faces, f)
    np.testing.assert_allclose(vertex_normals(cleaned), vertex_normals(from_arrays(v, f)))


def test_clean_point_cloud_merges_duplicates_only():
    points = sphere_points(10)
    cloud = from_arrays(np.vstack([points, points[[2, 7]]]))
    cleaned, vertex_map = clean(cloud)
    assert cleaned.is_cloud
    np.testing.assert_array_equal(cleaned.vertices, points)
    np.testing.assert_array_equal(vertex_map, list(range(10)) + [2, 7])


def test_clean_errors_when_nothing_is_left():
    collinear = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], dtype=float)
    with pytest.raises(InputError, match=r"^line\.off: no usable faces: all 2 faces are degenerate"):
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
    assert surface_area(from_arrays(sphere.vertices, sphere.faces)) == pytest.approx(16 * np.pi, rel=0.01)


def test_surface_area_estimate_of_point_cloud():
    cloud = from_arrays(sphere_points(20000, seed=3, radius=2.0))
    assert surface_area(cloud) == pytest.approx(16 * np.pi, rel=0.10)


def test_vertex_areas_by_hand_and_summing_to_the_surface_area():
    # the unit square as triangles (0, 1, 2) and (0, 2, 3), and a vertex no triangle uses
    square = from_arrays(
        np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [5, 5, 5]], dtype=float),
        np.array([[0, 1, 2], [0, 2, 3]]),
    )
    np.testing.assert_allclose(vertex_areas(square), [1 / 3, 1 / 6, 1 / 3, 1 / 6, 0.0])
    sphere = trimesh.creation.icosphere(subdivisions=3)
    mesh = from_arrays(sphere.vertices, sphere.faces)
    assert vertex_areas(mesh).sum() == pytest.approx(surface_area(mesh), rel=1e-12)
    # trimesh: a third of each incident face's area, through its vertex-face incidence
    np.testing.assert_allclose(vertex_areas(mesh), sphere.faces_sparse @ sphere.area_faces / 3, rtol=1e-12)
    cloud = from_arrays(sphere_points(2000, seed=3))
    assert vertex_areas(cloud).sum() == pytest.approx(surface_area(cloud), rel=1e-12)


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
# speed
# ---------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------
# arrays as input
# ---------------------------------------------------------------------------


def test_detect_reads_an_n_by_3_array_as_a_point_cloud():
    v, _, sym = mirror_shape()
    result = intrinsym.detect(v, intrinsym.make_params(n_source=30, n_target=300, spin_cloud=5000, iterations=5))
    image = result.symmetry_map()
    assert image.shape == (len(v),)  # in the array's row order
    assert np.mean(image == sym) > 0.9


@pytest.mark.parametrize(
    ("array", "match"),
    [
        (np.zeros((10, 2)), r"must be an \(N, 3\) array, got shape \(10, 2\)"),
        (np.zeros((2, 5, 3)), r"must be an \(N, 3\) array, got shape \(2, 5, 3\)"),
        (np.where(np.eye(6, 3) > 0, np.inf, 0.0), "3 vertices have NaN or infinite coordinates"),
        (np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, np.nan]]), "NaN or infinite"),
        (np.zeros((3, 3)), "only 3 points; at least 4"),
    ],
)
def test_a_bad_array_is_a_one_line_input_error(array, match):
    with pytest.raises(InputError, match=match) as info:
        intrinsym.detect(array)
    assert "\n" not in str(info.value)
