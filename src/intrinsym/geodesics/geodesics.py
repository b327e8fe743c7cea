"""Approximate geodesic distances on meshes and point clouds by shortest paths in a graph.

The graph (:func:`surface_graph`) has straight-line (Euclidean) edge lengths; graph
shortest paths approximate geodesics. On mesh edges alone Dijkstra overestimates
geodesics by several percent ("metrication"), so the graph adds shortcut chords (see
:func:`surface_graph` for the construction and its measured error).

Every function takes the graph as a symmetric ``scipy.sparse`` matrix of shape (N, N)
whose entries are edge lengths; vertex indices refer to its rows. Distances are in the
units of the vertex coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from .._threads import map_ranges
from ..mesh.shape import Shape, clean, surface_area
from ._chords import candidate_rows, keep_chords
from ._dijkstra import balls, csr_arrays, pair_block, symmetrize_rows

__all__ = [
    "SparseDistances",
    "distances_from",
    "distances_to",
    "local_distances",
    "mesh_edges",
    "pair_distances",
    "surface_graph",
    "voronoi_adjacency",
    "voronoi_cells",
]


@dataclass(frozen=True)
class SparseDistances:
    """Row-sorted sparse geodesic distances between the points of a set, up to a radius.

    Row i lists every j with d(i,j) <= radius, INCLUDING i itself at distance 0, sorted by
    ascending distance.

    Attributes
    ----------
    indptr : (n+1,) int64
        Row ``i`` occupies ``indices[indptr[i]:indptr[i+1]]``.
    indices : (nnz,) int64
        Indices into the point set (not mesh vertices).
    dist : (nnz,) float64
        Distances, ascending within each row; ``d(i, j) == d(j, i)``.
    radius : float
        The cut-off radius (length units).
    """

    indptr: np.ndarray
    indices: np.ndarray
    dist: np.ndarray
    radius: float

    @property
    def n(self) -> int:
        """Number of points (rows)."""
        return len(self.indptr) - 1

    def row(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Point indices (k,) and distances (k,) of row ``i``, ascending by distance."""
        lo, hi = self.indptr[i], self.indptr[i + 1]
        return self.indices[lo:hi], self.dist[lo:hi]


# --------------------------------------------------------------------------- graph


def mesh_edges(faces: np.ndarray) -> np.ndarray:
    """Unique undirected edges of a triangle mesh.

    Parameters
    ----------
    faces : (F, 3) int array

    Returns
    -------
    (M, 2) int64
        Vertex pairs with ``u < v``, sorted lexicographically.
    """
    f = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    return _unique_pairs(e)


def _unique_pairs(pairs: np.ndarray) -> np.ndarray:
    """Sort each pair, drop self-pairs and duplicates; (K, 2) int64 rows, lexicographic."""
    p = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    p = p[p[:, 0] != p[:, 1]]
    if len(p) == 0:
        return p
    base = p[:, 1].max() + 1
    key = np.sort(p[:, 0] * base + p[:, 1])
    key = key[np.r_[True, key[1:] != key[:-1]]]
    return np.stack([key // base, key % base], axis=1)


def _opposite_pairs(faces: np.ndarray) -> np.ndarray:
    """For every edge shared by two triangles, the two vertices opposite to it.

    Parameters
    ----------
    faces : (F, 3) int64

    Returns
    -------
    (K, 2) int64
        One pair per interior edge. A non-manifold edge with k > 2 triangles yields the
        k - 1 pairs of triangles adjacent in sorted order.
    """
    he = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    opp = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
    he.sort(axis=1)
    key = he[:, 0] * (he[:, 1].max() + 1) + he[:, 1]
    order = np.argsort(key, kind="stable")
    key, opp = key[order], opp[order]
    same = key[1:] == key[:-1]
    return np.stack([opp[:-1][same], opp[1:][same]], axis=1)


def _symmetric_csr(n: int, pairs: np.ndarray, weights: np.ndarray) -> sp.csr_matrix:
    """(n, n) symmetric CSR with ``weights`` on unique pairs (u < v) and their mirrors."""
    rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
    g = sp.csr_matrix((np.concatenate([weights, weights]), (rows, cols)), shape=(n, n))
    g.sort_indices()
    return g


def surface_graph(
    vertices: np.ndarray,
    faces: np.ndarray | None,
    k: int = 8,
    *,
    rings: int = 3,
    tol: float = 0.01,
) -> sp.csr_matrix:
    """Graph whose shortest paths approximate geodesics on a surface.

    Triangle mesh: all mesh edges; across each interior edge shared by triangles
    (a, b, c) and (b, a, d), the shortcut chord c-d; and chords from every vertex to the
    vertices within ``rings`` edge hops, except chords that pass within ``tol`` of
    another vertex (some common neighbour x with ``|ux| + |xw| <= (1 + tol) |uw|``:
    these cannot shorten a path by more than ``tol`` and only cost time). The extra
    chords give Dijkstra more directions to move in, which is what cuts metrication
    error. Point cloud (``faces`` None): the symmetric k-nearest-neighbour graph. All
    edge weights are straight-line lengths.

    Mean relative error against analytic geodesics (pairs 0.1-0.6 apart, 300 sources,
    about 10k vertices, see tests/test_geodesics.py):

    ========================  ============  =================  =========
    graph                     icosphere r=1  grid cylinder r=1  grid plane
    ========================  ============  =================  =========
    mesh edges                +9%           over +10%          over +10%
    + shortcut chords         +1.9%         +3.4%              +3.4%
    + 3-ring chords (default) +0.5%         +0.9%              +0.9%
    ========================  ============  =================  =========

    The default has about 25 neighbours per vertex (12 with shortcuts only) and makes a
    radius-limited Dijkstra about 1.3x slower. Chords are straight lines, so where the
    surface bends strongly within 3 hops (a finger a few edges thick) they can cut
    short a geodesic; ``rings=1`` keeps only mesh edges and shortcut chords.

    Parameters
    ----------
    vertices : (N, 3) float array
    faces : (F, 3) int array or None
    k : int
        Neighbours per point for a point cloud (ignored for a mesh).
    rings : int
        Hop radius of the extra chords on a mesh (1: mesh edges and shortcuts only).
    tol : float
        Relative tolerance of the chord pruning.

    Returns
    -------
    (N, N) scipy.sparse.csr_matrix, float64
        Symmetric, one entry per undirected edge and direction, lengths in the units
        of ``vertices``; duplicate edges merged.
    """
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be (N, 3), got shape {v.shape}")
    n = len(v)
    if faces is None:
        if k < 1:
            raise ValueError(f"k must be >= 1, got {k}")
        kk = min(k + 1, n)
        _, nbr = cKDTree(v).query(v, k=kk)
        pairs = _unique_pairs(np.stack([np.repeat(np.arange(n), kk), nbr.reshape(n, kk).ravel()], axis=1))
        return _symmetric_csr(n, pairs, np.linalg.norm(v[pairs[:, 0]] - v[pairs[:, 1]], axis=1))
    f = np.asarray(faces, dtype=np.int64)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must be (F, 3), got shape {f.shape}")
    if len(f) and (f.min() < 0 or f.max() >= n):
        raise ValueError(f"faces index vertices outside 0..{n - 1}")
    if rings < 1:
        raise ValueError(f"rings must be >= 1, got {rings}")
    edges = mesh_edges(f)
    base = _unique_pairs(np.concatenate([edges, _opposite_pairs(f)]))
    if len(base) == 0:
        return sp.csr_matrix((n, n), dtype=np.float64)
    adj = _symmetric_csr(n, edges, np.ones(len(edges)))
    base_csr = _symmetric_csr(n, base, np.ones(len(base)))
    # rows of the symmetric candidate pattern, each sorted, built on the worker threads
    rows_of = (
        adj.indptr.astype(np.int64),
        adj.indices.astype(np.int64),
        base_csr.indptr.astype(np.int64),
        base_csr.indices.astype(np.int64),
        rings,
    )
    ptr = np.zeros(n + 1, dtype=np.int64)
    map_ranges(candidate_rows, n, *rows_of, False, ptr, ptr[:0], np.empty(0, np.bool_))
    np.cumsum(ptr, out=ptr)
    idx = np.empty(ptr[-1], dtype=np.int64)
    is_base = np.empty(ptr[-1], dtype=np.bool_)
    map_ranges(candidate_rows, n, *rows_of, True, ptr, idx, is_base)
    keep = np.empty(len(idx), dtype=np.bool_)
    map_ranges(keep_chords, n, v, ptr, idx, is_base, float(tol), keep)
    kept_ptr = np.concatenate([[0], np.cumsum(keep)])[ptr]
    cols = idx[keep]
    rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(kept_ptr))
    lengths = np.linalg.norm(v[rows] - v[cols], axis=1)
    return sp.csr_matrix((lengths, cols, kept_ptr), shape=(n, n))


# --------------------------------------------------------------------------- public


def unit_area_graph(shape: Shape) -> tuple[Shape, np.ndarray, sp.csr_matrix]:
    """The shape cleaned (:func:`intrinsym.mesh.shape.clean`) and its geodesic graph
    (:func:`surface_graph`) scaled to unit area: what every score measures distances on.

    Returns
    -------
    cleaned : Shape
    vertex_map : (N_in,) int64
        The cleaned vertex of every input vertex.
    graph : (N, N) sparse
        Edge lengths in units of sqrt(area).
    """
    cleaned, vertex_map = clean(shape)
    graph = surface_graph(cleaned.vertices / np.sqrt(surface_area(cleaned)), cleaned.faces)
    return cleaned, vertex_map, graph


def distances_from(graph: sp.spmatrix, sources: np.ndarray, limit: float = np.inf, chunk: int = 256) -> np.ndarray:
    """Graph-geodesic distances from a few sources to every vertex.

    The searches of :func:`distances_to`, to every vertex, the graph's arrays built once
    for all chunks: SciPy's ``dijkstra`` gives the same distances to the last bit
    (tests/test_geodesics.py) but holds the GIL, so its searches ran one at a time.

    Parameters
    ----------
    graph : (N, N) sparse, symmetric
        Edge lengths, e.g. from :func:`surface_graph`.
    sources : (m,) int array
        Source vertices.
    limit : float
        Distances beyond ``limit`` are not computed and come back as ``inf``.
    chunk : int
        Sources per batch of searches (bounds temporary memory to ``chunk x N``).

    Returns
    -------
    (m, N) float64
        Distances in length units; ``inf`` beyond ``limit`` or where unreachable.
    """
    arrays = csr_arrays(graph)
    every = np.arange(len(arrays[0]) - 1, dtype=np.int64)
    src = np.asarray(sources, dtype=np.int64).ravel()
    out = np.empty((len(src), len(every)), dtype=np.float64)
    for lo in range(0, len(src), max(1, chunk)):
        part = src[lo : lo + chunk]
        out[lo : lo + len(part)] = _settled(arrays, part, every, len(every), limit)
    return out


def distances_to(graph: sp.spmatrix, sources: np.ndarray, points: np.ndarray, limit: float) -> np.ndarray:
    """Graph-geodesic distances from a few sources to a point set, up to ``limit``.

    One radius-limited Dijkstra per source on the worker threads
    (:func:`intrinsym.geodesics._dijkstra.balls`), keeping only the points it settles.

    Parameters
    ----------
    graph : (N, N) sparse, symmetric
    sources : (m,) int array
        Source vertices.
    points : (n,) int array
        Distinct vertices the distances are wanted to.
    limit : float
        Search radius (length units).

    Returns
    -------
    (m, n) float64
        ``inf`` beyond ``limit`` or where unreachable.
    """
    indptr, indices, weights = csr_arrays(graph)
    pts = np.asarray(points, dtype=np.int64).ravel()
    label = np.full(len(indptr) - 1, -1, dtype=np.int64)
    label[pts] = np.arange(len(pts))
    if len(np.unique(pts)) != len(pts):
        raise ValueError("points must be distinct vertices")
    return _settled((indptr, indices, weights), np.asarray(sources, dtype=np.int64).ravel(), label, len(pts), limit)


def _settled(
    arrays: tuple[np.ndarray, np.ndarray, np.ndarray], sources: np.ndarray, label: np.ndarray, n: int, limit: float
) -> np.ndarray:
    """(m, n) distances from ``sources`` to the ``n`` labelled vertices (``label``: -1
    for none) within ``limit`` (:func:`~intrinsym.geodesics._dijkstra.balls`), inf elsewhere."""
    counts, cols, dists = balls(*arrays, sources, label, float(limit))
    out = np.full((len(sources), n), np.inf)
    out[np.repeat(np.arange(len(sources)), counts), cols] = dists
    return out


def local_distances(graph: sp.spmatrix, points: np.ndarray, radius: float) -> SparseDistances:
    """Sparse graph-geodesic distances among a point set, up to a radius.

    One radius-limited Dijkstra per point (Numba, on as many threads as Numba uses),
    then symmetrised: ``d(i, j) = min`` of the two directions, so that the result is
    exactly symmetric. Memory is O(nnz + N) per thread, never ``n x N``.

    Parameters
    ----------
    graph : (N, N) sparse, symmetric
        Edge lengths, e.g. from :func:`surface_graph`.
    points : (n,) int array
        Distinct vertex indices: the point set.
    radius : float
        Cut-off (length units, >= 0).

    Returns
    -------
    SparseDistances
        ``n`` rows over point indices ``0..n-1``; row ``i`` starts with ``i`` at 0.
    """
    indptr, indices, weights = csr_arrays(graph)
    n_vert = len(indptr) - 1
    pts = np.asarray(points, dtype=np.int64).ravel()
    if not radius >= 0:
        raise ValueError(f"radius must be >= 0, got {radius}")
    if len(pts) and (pts.min() < 0 or pts.max() >= n_vert):
        raise ValueError("points out of range of the graph's vertices")
    label = np.full(n_vert, -1, dtype=np.int64)
    label[pts] = np.arange(len(pts))
    if len(np.unique(pts)) != len(pts):
        raise ValueError("points must be distinct vertices")
    counts, cols, dists = balls(indptr, indices, weights, pts, label, float(radius))
    row_ptr = np.zeros(len(pts) + 1, dtype=np.int64)
    np.cumsum(counts, out=row_ptr[1:])
    row_ptr, cols, dists = symmetrize_rows(row_ptr, cols, dists)
    return SparseDistances(row_ptr, cols, dists, float(radius))


def pair_distances(graph: sp.spmatrix, pairs: np.ndarray, limit: float = np.inf) -> np.ndarray:
    """Graph-geodesic distance for each vertex pair.

    One Dijkstra per distinct first vertex, stopped once all of its partners are
    settled (or at ``limit``).

    Parameters
    ----------
    graph : (N, N) sparse, symmetric
    pairs : (E, 2) int array
        Vertex index pairs.
    limit : float
        Search radius; farther pairs get ``inf``.

    Returns
    -------
    (E,) float64
        Distances in length units (``inf`` if beyond ``limit`` or unreachable).
    """
    indptr, indices, weights = csr_arrays(graph)
    p = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if len(p) and (p.min() < 0 or p.max() >= len(indptr) - 1):
        raise ValueError("pairs out of range of the graph's vertices")
    order = np.argsort(p[:, 0], kind="stable")
    first = p[order, 0]
    starts = np.flatnonzero(np.r_[True, first[1:] != first[:-1]]) if len(p) else np.zeros(0, np.int64)
    group_ptr = np.r_[starts, len(p)].astype(np.int64)
    group_source = first[starts]
    targets = p[order, 1]
    parts = map_ranges(
        lambda lo, hi: pair_block(
            indptr,
            indices,
            weights,
            group_source[lo:hi],
            group_ptr[lo : hi + 1] - group_ptr[lo],
            targets[group_ptr[lo] : group_ptr[hi]],
            float(limit),
        ),
        len(group_source),
    )
    out_sorted = np.concatenate([np.zeros(0), *parts])
    out = np.empty(len(p), dtype=np.float64)
    out[order] = out_sorted
    return out


def voronoi_cells(graph: sp.spmatrix, seeds: np.ndarray) -> np.ndarray:
    """Geodesic Voronoi partition: the nearest seed of every vertex (multi-source Dijkstra).

    Parameters
    ----------
    graph : (N, N) sparse, symmetric
        Edge lengths, e.g. from :func:`surface_graph`.
    seeds : (s,) int array
        Distinct seed vertices.

    Returns
    -------
    (N,) int64
        Index into ``seeds`` of the nearest seed, -1 for vertices no seed reaches.
    """
    g = sp.csr_matrix(graph)
    s = np.asarray(seeds, dtype=np.int64).ravel()
    if len(np.unique(s)) != len(s):
        raise ValueError("seeds must be distinct vertices")
    if len(s) == 0:
        return np.full(g.shape[0], -1, dtype=np.int64)
    _, _, owner_vertex = dijkstra(g, directed=True, indices=s, min_only=True, return_predecessors=True)
    seed_index = np.full(g.shape[0], -1, dtype=np.int64)
    seed_index[s] = np.arange(len(s))
    return np.where(owner_vertex >= 0, seed_index[np.maximum(owner_vertex, 0)], -1)


def voronoi_adjacency(graph: sp.spmatrix, seeds: np.ndarray, edges: np.ndarray | None = None) -> np.ndarray:
    """Seeds whose geodesic Voronoi regions touch (the paper's source neighbourhood).

    Every vertex belongs to its nearest seed (multi-source Dijkstra on ``graph``); two
    seeds are neighbours when some edge joins a vertex of one region to a vertex of the
    other. Vertices not reachable from any seed are ignored.

    Parameters
    ----------
    graph : (N, N) sparse, symmetric
        Edge lengths used for the partition, e.g. from :func:`surface_graph`.
    seeds : (s,) int array
        Distinct seed vertices.
    edges : (M, 2) int array, optional
        Vertex pairs across which regions touch. Default: every edge of ``graph``. Pass
        ``mesh_edges(faces)`` to count only contacts across mesh edges (the paper's
        "regions meet" on the mesh; shortcut chords can also join regions that touch
        only at a corner).

    Returns
    -------
    (K, 2) int64
        Unique pairs ``(i, j)``, ``i < j``, of indices into ``seeds``, sorted
        lexicographically.
    """
    g = sp.csr_matrix(graph)
    if len(np.asarray(seeds).ravel()) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    owner = voronoi_cells(g, seeds)
    if edges is None:
        coo = sp.triu(g, k=1).tocoo()
        e = np.stack([coo.row, coo.col], axis=1).astype(np.int64)
    else:
        e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    a, b = owner[e[:, 0]], owner[e[:, 1]]
    touching = (a >= 0) & (b >= 0) & (a != b)
    return _unique_pairs(np.stack([a[touching], b[touching]], axis=1)).reshape(-1, 2)
