"""Geodesic distances: accuracy against analytic geodesics and exactness against dense Dijkstra.

Shapes are scaled to unit surface area, as the pipeline does, so distances are in units of
sqrt(area); accuracy is measured from a few edge lengths (0.05) up to 0.3.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh
from scipy.sparse.csgraph import connected_components, dijkstra

from intrinsym.geodesics.geodesics import (
    distances_from,
    distances_to,
    local_distances,
    mesh_edges,
    pair_distances,
    surface_graph,
    voronoi_adjacency,
)
from intrinsym.mesh.sampling import area_uniform_points, farthest_point_sampling

NEAR, FAR = 0.05, 0.3  # tested distance range, units of sqrt(area)


def unit_sphere(subdivisions: int = 4) -> tuple[np.ndarray, np.ndarray, float]:
    """Icosphere scaled to unit area: vertices, faces and radius."""
    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = np.asarray(s.vertices) / np.sqrt(s.area)
    return v, np.asarray(s.faces), float(np.linalg.norm(v[0]))


def great_circle(points: np.ndarray, sources: np.ndarray, radius: float) -> np.ndarray:
    """(len(sources), N) analytic geodesic distances on a sphere centred at the origin."""
    u = points / np.linalg.norm(points, axis=1, keepdims=True)
    return radius * np.arccos(np.clip(u[sources] @ u.T, -1.0, 1.0))


def open_cylinder(nt: int = 96, nz: int = 32) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Open cylinder (no caps), square grid cells split into right triangles, unit area.

    Returns vertices (N,3), faces (F,3) and the (N, 2) unrolled coordinates (theta, z),
    z in the scaled units (the radius is 1 / scale).
    """
    step = 2 * np.pi / nt
    theta, z = np.meshgrid(step * np.arange(nt), step * np.arange(nz), indexing="ij")
    v = np.stack([np.cos(theta).ravel(), np.sin(theta).ravel(), z.ravel()], axis=1)
    a = np.arange(nt * nz).reshape(nt, nz)
    b = np.roll(a, -1, axis=0)
    f = np.concatenate(
        [
            np.stack([a[:, :-1], b[:, :-1], b[:, 1:]], axis=-1).reshape(-1, 3),
            np.stack([a[:, :-1], b[:, 1:], a[:, 1:]], axis=-1).reshape(-1, 3),
        ]
    )
    scale = np.sqrt(2 * np.pi * z.max())  # area of the open cylinder r=1, height z.max()
    return v / scale, f, np.stack([theta.ravel(), z.ravel() / scale], axis=1)


def relative_errors(approx: np.ndarray, true: np.ndarray) -> np.ndarray:
    """|approx/true - 1| over the pairs with NEAR < true < FAR."""
    m = (true > NEAR) & (true < FAR)
    assert m.sum() > 1000
    return np.abs(approx[m] / true[m] - 1.0)


def test_sphere_mesh_error_below_3_percent() -> None:
    """Mesh graph distances on a unit-area icosphere match great-circle distances (mean, p95, max)."""
    v, f, r = unit_sphere()
    src = np.arange(0, len(v), 97)
    err = relative_errors(distances_from(surface_graph(v, f), src), great_circle(v, src, r))
    # measured: mean 0.41%, p95 1.14%, max 1.73%
    assert err.mean() < 0.01 and np.percentile(err, 95) < 0.03 and err.max() < 0.03


def test_open_cylinder_mesh_error_below_3_percent() -> None:
    """Mesh graph distances on an open cylinder match the unrolled distance sqrt((r dθ)^2 + dz^2)."""
    v, f, tz = open_cylinder()
    assert trimesh.Trimesh(v, f, process=False).area == pytest.approx(1.0, rel=0.01)
    scale = 1.0 / np.linalg.norm(v[0, :2])  # r = 1 before scaling
    src = np.arange(0, len(v), 37)
    dtheta = np.abs(tz[src, None, 0] - tz[None, :, 0])
    dtheta = np.minimum(dtheta, 2 * np.pi - dtheta)
    true = np.hypot(dtheta / scale, tz[src, None, 1] - tz[None, :, 1])
    err = relative_errors(distances_from(surface_graph(v, f), src), true)
    # measured: mean 0.90%, p95 2.65%, max 2.75%
    assert err.mean() < 0.015 and np.percentile(err, 95) < 0.03 and err.max() < 0.03


def test_point_cloud_knn_graph_error() -> None:
    """The k-NN graph (faces None) of an evenly spread sphere sample is within the stated error.

    Stated error (measured, 3000 points, unit area): k=8 mean 3.3%, p95 5.7%; k=12 mean
    1.8%, p95 3.3%. A straight-chord graph never undercuts the geodesic by more than the
    chord-vs-arc gap (< 0.1% at these distances).
    """
    v, f, r = unit_sphere()
    dense, _, _ = area_uniform_points(v, f, 20000, seed=1)
    dense *= r / np.linalg.norm(dense, axis=1, keepdims=True)
    p = dense[farthest_point_sampling(dense, n=3000, seed=0)]
    src = np.arange(0, len(p), 61)
    true = great_circle(p, src, r)
    for k, mean_bound, p95_bound in [(8, 0.04, 0.07), (12, 0.02, 0.04)]:
        d = distances_from(surface_graph(p, None, k=k), src)
        err = relative_errors(d, true)
        assert err.mean() < mean_bound and np.percentile(err, 95) < p95_bound
        m = true > NEAR
        assert (d[m] / true[m]).min() > 0.999


def reference_surface_graph(v: np.ndarray, f: np.ndarray, rings: int, tol: float) -> sp.csr_matrix:
    """surface_graph from its definition, pair by pair: mesh edges and shortcut chords
    always, other pairs within ``rings`` hops unless a common candidate neighbour lies
    within ``tol`` of the segment."""
    n = len(v)
    edges = mesh_edges(f)
    adjacency = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    hops = dijkstra(adjacency, directed=False, unweighted=True, limit=rings)
    base = set(map(tuple, edges.tolist()))
    faces_of: dict[tuple[int, int], list[int]] = {}
    for a, b, c in f.tolist():
        for x, y, z in ((a, b, c), (b, c, a), (c, a, b)):
            faces_of.setdefault((min(x, y), max(x, y)), []).append(z)
    for opposite in faces_of.values():
        for i in range(len(opposite) - 1):
            base.add((min(opposite[i], opposite[i + 1]), max(opposite[i], opposite[i + 1])))
    cand = [set(np.flatnonzero(np.isfinite(hops[u])).tolist()) - {u} for u in range(n)]
    for u, w in base:
        cand[u].add(w)
        cand[w].add(u)

    @functools.cache
    def dist(a: int, b: int) -> float:
        """``np.linalg.norm(v[a] - v[b])``, each pair's computed once (the pairs recur)."""
        return float(np.linalg.norm(v[a] - v[b]))

    rows, cols = [], []
    for u in range(n):
        for w in sorted(cand[u]):
            if (min(u, w), max(u, w)) not in base:
                bound = (1 + tol) * dist(u, w)
                common = (cand[u] & cand[w]) - {u, w}
                if any(dist(u, x) + dist(x, w) <= bound for x in common):
                    continue
            rows.append(u)
            cols.append(w)
    lengths = np.linalg.norm(v[rows] - v[cols], axis=1)
    return sp.csr_matrix((lengths, (rows, cols)), shape=(n, n))


@pytest.mark.parametrize("rings", [1, 2, 3])
def test_surface_graph_matches_its_definition(rings: int) -> None:
    """The threaded candidate rows and chord pruning give the graph the definition gives,
    on a bumpy sphere (pruning decides both ways) and an open strip (boundary edges)."""
    v, f, _ = unit_sphere(subdivisions=2)
    v = v * (1 + 0.1 * np.sin(5 * v[:, :1]) * np.cos(3 * v[:, 1:2]))
    strip_v, strip_f, _ = open_cylinder(nt=12, nz=5)
    for vertices, faces in ((v, f), (strip_v, strip_f)):
        got = surface_graph(vertices, faces, rings=rings)
        want = reference_surface_graph(vertices, faces, rings, 0.01)
        assert got.has_sorted_indices
        assert np.array_equal(got.indptr, want.indptr) and np.array_equal(got.indices, want.indices)
        assert np.allclose(got.data, want.data, rtol=0, atol=1e-15)


@pytest.fixture(scope="module")
def small_sphere() -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """Graph of a 642-vertex unit-area sphere, 150 FPS points, and dense Dijkstra among them."""
    v, f, _ = unit_sphere(subdivisions=3)
    g = surface_graph(v, f)
    pts = farthest_point_sampling(v, n=150, seed=0)
    return g, pts, dijkstra(g, directed=False, indices=pts)


def test_local_distances_match_dense_dijkstra(small_sphere) -> None:
    """local_distances rows: self first at 0, ascending, exactly symmetric, complete up to R, equal to dense."""
    g, pts, dense = small_sphere
    radius = 0.3
    ref = dense[:, pts]
    ld = local_distances(g, pts, radius)
    assert ld.n == len(pts) and ld.radius == radius
    table = {}
    for i in range(ld.n):
        cols, d = ld.row(i)
        assert cols[0] == i and d[0] == 0.0
        assert np.all(np.diff(d) >= 0)
        np.testing.assert_allclose(d, ref[i, cols], rtol=1e-12, atol=1e-12)
        assert np.all(d <= radius)
        inside = np.flatnonzero(ref[i] <= radius * (1 - 1e-9))
        assert set(inside) <= set(cols.tolist())
        table.update({(i, int(j)): dj for j, dj in zip(cols, d, strict=True)})
    assert all(table[(j, i)] == dij for (i, j), dij in table.items())


def test_pair_distances_and_limit_match_dense(small_sphere) -> None:
    """pair_distances equals dense Dijkstra; beyond ``limit`` both it and distances_from give inf."""
    g, pts, dense = small_sphere
    rng = np.random.default_rng(0)
    first = rng.integers(len(pts), size=400)
    second = rng.integers(g.shape[0], size=400)
    pairs = np.stack([pts[first], second], axis=1)
    ref = dense[first, second]
    np.testing.assert_allclose(pair_distances(g, pairs), ref, rtol=1e-12, atol=1e-12)
    limited = pair_distances(g, pairs, limit=0.2)
    near = ref <= 0.2 * (1 - 1e-9)
    np.testing.assert_allclose(limited[near], ref[near], rtol=1e-12)
    assert np.all(np.isinf(limited[ref > 0.2 * (1 + 1e-9)]))
    rows = distances_from(g, pts[:5], limit=0.2)
    assert np.all(np.isinf(rows[dense[:5] > 0.2 * (1 + 1e-9)]))
    inner = dense[:5] <= 0.2 * (1 - 1e-9)
    np.testing.assert_allclose(rows[inner], dense[:5][inner], rtol=1e-12)
    np.testing.assert_allclose(distances_from(g, pts[:5]), dense[:5], rtol=1e-12)
    # the threaded searches give SciPy's distances to the last bit, chunk by chunk
    for limit in (0.2, np.inf):
        ref = dijkstra(g, directed=True, indices=pts[:5], limit=limit)
        np.testing.assert_array_equal(distances_from(g, pts[:5], limit=limit, chunk=2), ref)


def test_distances_to_points_match_dense_dijkstra(small_sphere) -> None:
    """distances_to: SciPy's dense Dijkstra at the points within ``limit``, inf beyond."""
    g, pts, dense = small_sphere
    sources = np.arange(0, g.shape[0], 37)
    ref = dijkstra(g, directed=True, indices=sources)[:, pts]
    got = distances_to(g, sources, pts, 0.25)
    inner = ref <= 0.25 * (1 - 1e-9)
    np.testing.assert_allclose(got[inner], ref[inner], rtol=1e-12)
    assert np.all(np.isinf(got[ref > 0.25 * (1 + 1e-9)]))
    np.testing.assert_allclose(distances_to(g, sources, pts, np.inf), ref, rtol=1e-12)
    with pytest.raises(ValueError, match="distinct"):
        distances_to(g, sources, pts[[0, 0]], 0.25)


def grid_strip(nx: int = 40, ny: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Planar nx-by-ny vertex grid (unit spacing) triangulated; vertex (i, j) has index i*ny + j."""
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(nx * ny)], axis=1)
    a = np.arange(nx * ny).reshape(nx, ny)
    f = np.concatenate(
        [
            np.stack([a[:-1, :-1], a[1:, :-1], a[1:, 1:]], axis=-1).reshape(-1, 3),
            np.stack([a[:-1, :-1], a[1:, 1:], a[:-1, 1:]], axis=-1).reshape(-1, 3),
        ]
    )
    return v, f


def test_voronoi_adjacency_on_strip_is_a_chain() -> None:
    """Seeds spaced along a long strip: each region touches only the next one (hand-checked)."""
    v, f = grid_strip()
    seeds = np.array([0, 13, 26, 39]) * 4 + 1  # columns 0, 13, 26, 39, row 1
    expected = np.array([[0, 1], [1, 2], [2, 3]])
    g = surface_graph(v, f)
    assert np.array_equal(voronoi_adjacency(g, seeds), expected)
    assert np.array_equal(voronoi_adjacency(g, seeds, mesh_edges(f)), expected)
    # seed order is reflected in the indices: reversed seeds give the same chain
    assert np.array_equal(voronoi_adjacency(g, seeds[::-1]), expected)


def test_voronoi_adjacency_on_sphere_is_connected_triangulation_like() -> None:
    """Evenly spread seeds on a sphere: the region graph is connected with Delaunay-like degrees."""
    v, f, _ = unit_sphere()
    seeds = farthest_point_sampling(v, n=60, seed=0)
    pairs = voronoi_adjacency(surface_graph(v, f), seeds, mesh_edges(f))
    adj = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(60, 60))
    assert connected_components(adj, directed=False)[0] == 1
    degree = np.bincount(pairs.ravel(), minlength=60)
    # a triangulation of the sphere with s vertices has mean degree 6 - 12/s = 5.8
    assert degree.min() >= 3 and degree.max() <= 9
    assert 5.0 <= degree.mean() <= 6.5
