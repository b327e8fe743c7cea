"""Sampling: Poisson-disc farthest-point sets, area-uniform points, subdivision, spacing."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist

from intrinsym.mesh.sampling import area_uniform_points, farthest_point_sampling, spacing_for_count, subdivide_to


def cloud() -> np.ndarray:
    """2000 points of a bumpy sphere (fixed seed)."""
    p = np.random.default_rng(3).normal(size=(2000, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True) * (1 + 0.2 * np.sin(3 * p[:, :1]))


def test_fps_count_mode_is_a_poisson_disc_set() -> None:
    """n chosen points are distinct, pairwise >= the final covering radius, which covers every point."""
    p = cloud()
    idx = farthest_point_sampling(p, n=120, seed=1)
    assert len(idx) == 120 and len(np.unique(idx)) == 120
    cover = cKDTree(p[idx]).query(p)[0].max()
    assert pdist(p[idx]).min() >= cover
    # covering radius of a 120-point set on a roughly unit sphere: neither tiny nor huge
    assert 0.1 < cover < 0.4


def test_fps_spacing_mode_respects_spacing_and_is_prefix_of_count_mode() -> None:
    """Spacing mode: points >= spacing apart, all points within spacing; same as the count run's prefix."""
    p = cloud()
    spacing = 0.25
    idx = farthest_point_sampling(p, spacing=spacing, seed=4)
    assert pdist(p[idx]).min() >= spacing
    assert cKDTree(p[idx]).query(p)[0].max() < spacing
    longer = farthest_point_sampling(p, n=len(idx) + 5, seed=4)
    assert np.array_equal(longer[: len(idx)], idx)
    # adding the next point would have violated the spacing
    assert cKDTree(p[idx]).query(p[longer[len(idx)]])[0] < spacing


def test_fps_deterministic_per_seed() -> None:
    """Same seed, same sample; another seed starts elsewhere."""
    p = cloud()
    a = farthest_point_sampling(p, n=50, seed=7)
    assert np.array_equal(a, farthest_point_sampling(p, n=50, seed=7))
    assert not np.array_equal(a, farthest_point_sampling(p, n=50, seed=8))


def test_fps_rejects_bad_requests() -> None:
    """Both/neither of n and spacing, n beyond the distinct positions, non-positive spacing raise."""
    p = np.repeat(np.eye(3), 4, axis=0)  # 12 points at 3 distinct positions
    assert {tuple(q) for q in p[farthest_point_sampling(p, n=3)]} == {tuple(q) for q in np.eye(3)}
    for kwargs in [{}, {"n": 2, "spacing": 0.1}, {"n": 4}, {"n": 13}, {"spacing": 0.0}]:
        with pytest.raises(ValueError):
            farthest_point_sampling(p, **kwargs)


def test_spacing_for_count_hand_checked() -> None:
    """100 hexagons of side-to-side spacing 1 cover 100 * sqrt(3)/2; spacing scales as 1/sqrt(n)."""
    assert spacing_for_count(100 * np.sqrt(3) / 2, 100) == pytest.approx(1.0)
    assert spacing_for_count(1.0, 400) == pytest.approx(spacing_for_count(1.0, 100) / 2)
    with pytest.raises(ValueError):
        spacing_for_count(1.0, 0)


def two_triangles() -> tuple[np.ndarray, np.ndarray]:
    """Triangles of area 0.5 and 1.5 (ratio 1:3) in the plane z=0."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [5, 0, 0], [2, 1, 0]], dtype=float)
    return v, np.array([[0, 1, 2], [3, 4, 5]])


def test_area_uniform_points_follow_area() -> None:
    """Face counts follow the 1:3 area ratio; points are inside their faces, uniform within them."""
    v, f = two_triangles()
    n = 40000
    pts, face, bary = area_uniform_points(v, f, n, seed=0)
    assert pts.shape == (n, 3) and face.shape == (n,) and bary.shape == (n, 3)
    frac = np.mean(face == 1)
    assert abs(frac - 0.75) < 4 * np.sqrt(0.75 * 0.25 / n)
    np.testing.assert_allclose(bary.sum(axis=1), 1.0, atol=1e-12)
    assert bary.min() >= 0.0
    np.testing.assert_allclose(pts, np.einsum("nk,nkd->nd", bary, v[f[face]]), atol=1e-12)
    # uniform inside a triangle: mean at the centroid; the corner region bary[:, 0] > 1/2
    # (a similar triangle of half the side) holds a quarter of the points
    sigma = np.sqrt(0.25 * 0.75 / n)
    assert abs(np.mean(bary[:, 0] > 0.5) - 0.25) < 4 * sigma
    in_first = pts[face == 0]
    np.testing.assert_allclose(in_first.mean(axis=0), v[f[0]].mean(axis=0), atol=0.01)
    again = area_uniform_points(v, f, n, seed=0)
    assert all(np.array_equal(a, b) for a, b in zip(again, (pts, face, bary), strict=True))


def on_some_face(points: np.ndarray, v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(n,) bool: each point lies inside (plane and barycentric range) some triangle of (v, f)."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    normal = np.cross(b - a, c - a)
    rel = points[:, None] - a[None]  # (n, F, 3)
    in_plane = np.abs(np.einsum("nfk,fk->nf", rel, normal)) < 1e-12
    # barycentric weights of b and c by Cramer's rule in the face's own frame
    e1, e2 = b - a, c - a
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    r1, r2 = np.einsum("nfk,fk->nf", rel, e1), np.einsum("nfk,fk->nf", rel, e2)
    det = d11 * d22 - d12**2
    wb, wc = (d22 * r1 - d12 * r2) / det, (d11 * r2 - d12 * r1) / det
    inside = (wb >= -1e-12) & (wc >= -1e-12) & (wb + wc <= 1 + 1e-12)
    return (in_plane & inside).any(axis=1)


def test_subdivide_to_keeps_geometry_and_vertex_indices() -> None:
    """Subdivision reaches the vertex count, keeps vertices 0..V-1, area, and every new vertex on the surface."""
    ico = trimesh.creation.icosahedron()
    v0, f0 = np.asarray(ico.vertices), np.asarray(ico.faces)
    v, f = subdivide_to(v0, f0, 100)
    assert len(v) >= 100 and len(f) == len(f0) * 16  # two rounds: 12 -> 42 -> 162 vertices
    assert np.array_equal(v[: len(v0)], v0)
    assert trimesh.Trimesh(v, f, process=False).area == pytest.approx(ico.area, rel=1e-12)
    assert on_some_face(v[len(v0) :], v0, f0).all()
    same_v, same_f = subdivide_to(v0, f0, 12)
    assert np.array_equal(same_v, v0) and np.array_equal(same_f, f0)
