"""Numba kernels of the graph geodesics: a bounded Dijkstra with an indexed binary heap,
run from many sources in parallel threads (used by :mod:`intrinsym.geodesics.geodesics`)."""

from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp

from .._threads import map_ranges


def csr_arrays(graph: sp.spmatrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(indptr, indices, weights) of a symmetric graph as int64/int64/float64 arrays."""
    g = sp.csr_matrix(graph)
    if g.shape[0] != g.shape[1]:
        raise ValueError(f"graph must be square, got shape {g.shape}")
    if g.nnz and abs(g - g.T).max() > 0:
        raise ValueError("graph must be symmetric")
    if g.nnz and g.data.min() < 0:
        raise ValueError("graph has negative edge lengths")
    return (
        g.indptr.astype(np.int64),
        g.indices.astype(np.int64),
        g.data.astype(np.float64),
    )


# --------------------------------------------------------------------------- Dijkstra


@nb.njit(cache=True, nogil=True)
def sift_up(hd: np.ndarray, hv: np.ndarray, pos: np.ndarray, i: int, d: float, v: int) -> None:
    """Place (d, v) at slot i or above in the indexed min-heap hd/hv, keeping pos."""
    while i > 0:
        parent = (i - 1) >> 1
        if hd[parent] <= d:
            break
        hd[i] = hd[parent]
        hv[i] = hv[parent]
        pos[hv[i]] = i
        i = parent
    hd[i] = d
    hv[i] = v
    pos[v] = i


@nb.njit(cache=True, nogil=True)
def heap_set(hd: np.ndarray, hv: np.ndarray, pos: np.ndarray, size: int, d: float, v: int) -> int:
    """Insert v with key d, or lower its key to d; return the new heap size.

    An indexed heap (``pos[v]`` is v's slot, -1 when absent) holds every vertex at most
    once, so the heap stays as small as the search front: on a surface graph with 25
    edges per vertex this made radius-limited Dijkstra about twice as fast as pushing
    duplicates and skipping stale entries.
    """
    if pos[v] < 0:
        sift_up(hd, hv, pos, size, d, v)
        return size + 1
    sift_up(hd, hv, pos, pos[v], d, v)
    return size


@nb.njit(cache=True, nogil=True)
def heap_pop(hd: np.ndarray, hv: np.ndarray, pos: np.ndarray, size: int) -> tuple[float, int]:
    """Remove and return the minimum of the indexed heap hd/hv[:size] (size > 0)."""
    d0 = hd[0]
    v0 = hv[0]
    pos[v0] = -1
    size -= 1
    if size == 0:
        return d0, v0
    d = hd[size]
    v = hv[size]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= size:
            break
        if c + 1 < size and hd[c + 1] < hd[c]:
            c += 1
        if hd[c] >= d:
            break
        hd[i] = hd[c]
        hv[i] = hv[c]
        pos[hv[i]] = i
        i = c
    hd[i] = d
    hv[i] = v
    pos[v] = i
    return d0, v0


@nb.njit(cache=True, nogil=True)
def grow_float(a: np.ndarray, used: int) -> np.ndarray:
    b = np.empty(2 * len(a), dtype=a.dtype)
    for i in range(used):  # a loop: slice assignment compiles its shape check slowly
        b[i] = a[i]
    return b


@nb.njit(cache=True, nogil=True)
def grow_int(a: np.ndarray, used: int) -> np.ndarray:
    b = np.empty(2 * len(a), dtype=a.dtype)
    for i in range(used):  # a loop: slice assignment compiles its shape check slowly
        b[i] = a[i]
    return b


@nb.njit(cache=True, nogil=True)
def ball_rows(
    indptr: np.ndarray,
    indices: np.ndarray,
    weights: np.ndarray,
    sources: np.ndarray,
    label: np.ndarray,
    limit: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Radius-limited Dijkstra from each source, recording labelled vertices.

    Parameters
    ----------
    indptr, indices, weights : CSR arrays of the graph, (N+1,), (E,), (E,)
    sources : (m,) int64 vertex indices
    label : (N,) int64
        Point index of each vertex, -1 for vertices that are not points.
    limit : float
        Search radius; vertices farther than ``limit`` are not reached.

    Returns
    -------
    counts : (m,) int64
        Number of points found from each source.
    cols : (sum(counts),) int64
        Point indices, grouped by source, ascending distance within a group.
    dists : (sum(counts),) float64
    """
    n = len(indptr) - 1
    dist = np.full(n, np.inf)
    touched = np.empty(n, dtype=np.int64)
    hd = np.empty(n, dtype=np.float64)
    hv = np.empty(n, dtype=np.int64)
    pos = np.full(n, -1, dtype=np.int64)
    out_c = np.empty(1024, dtype=np.int64)
    out_d = np.empty(1024, dtype=np.float64)
    counts = np.zeros(len(sources), dtype=np.int64)
    total = np.int64(0)  # not a literal 0: grow_* would compile a second signature for it
    for k in range(len(sources)):
        s = sources[k]
        dist[s] = 0.0
        touched[0] = s
        n_touched = 1
        size = heap_set(hd, hv, pos, np.int64(0), 0.0, s)  # a literal 0 compiles a second signature
        while size > 0:
            d, u = heap_pop(hd, hv, pos, size)
            size -= 1
            if label[u] >= 0:
                if total == len(out_c):
                    out_c = grow_int(out_c, total)
                    out_d = grow_float(out_d, total)
                out_c[total] = label[u]
                out_d[total] = d
                total += 1
                counts[k] += 1
            for e in range(indptr[u], indptr[u + 1]):
                w = indices[e]
                nd = d + weights[e]
                if nd <= limit and nd < dist[w]:
                    if dist[w] == np.inf:
                        touched[n_touched] = w
                        n_touched += 1
                    dist[w] = nd
                    size = heap_set(hd, hv, pos, size, nd, w)
        for t in range(n_touched):
            dist[touched[t]] = np.inf
    return counts, out_c[:total], out_d[:total]


@nb.njit(cache=True, nogil=True)
def symmetrize_rows(
    indptr: np.ndarray, indices: np.ndarray, dist: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Symmetric union of a row-sorted sparse distance matrix, min of both directions.

    Row i of the result holds every j listed in row i or with i listed in row j, at the
    smaller of the two distances, sorted ascending (stable: the diagonal stays first).

    Parameters
    ----------
    indptr : (n+1,) int64
    indices : (nnz,) int64
    dist : (nnz,) float64

    Returns
    -------
    indptr, indices, dist of the symmetric matrix.
    """
    n = len(indptr) - 1
    nnz = len(indices)
    # transpose by counting sort: row j of the transpose lists i with j in row i
    t_ptr = np.zeros(n + 1, dtype=np.int64)
    for e in range(nnz):
        t_ptr[indices[e] + 1] += 1
    for j in range(n):
        t_ptr[j + 1] += t_ptr[j]
    fill = t_ptr[:-1].copy()
    t_col = np.empty(nnz, dtype=np.int64)
    t_dist = np.empty(nnz, dtype=np.float64)
    for i in range(n):
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            t_col[fill[j]] = i
            t_dist[fill[j]] = dist[e]
            fill[j] += 1
    # pass 1: row sizes of the union
    pos = np.full(n, -1, dtype=np.int64)
    out_ptr = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        for e in range(indptr[i], indptr[i + 1]):
            pos[indices[e]] = 0
        extra = 0
        for e in range(t_ptr[i], t_ptr[i + 1]):
            if pos[t_col[e]] < 0:
                extra += 1
        for e in range(indptr[i], indptr[i + 1]):
            pos[indices[e]] = -1
        out_ptr[i + 1] = out_ptr[i] + indptr[i + 1] - indptr[i] + extra
    # pass 2: fill, min of both directions, restore ascending order by insertion sort
    out_col = np.empty(out_ptr[n], dtype=np.int64)
    out_dist = np.empty(out_ptr[n], dtype=np.float64)
    for i in range(n):
        o = out_ptr[i]
        m = 0
        for e in range(indptr[i], indptr[i + 1]):
            out_col[o + m] = indices[e]
            out_dist[o + m] = dist[e]
            pos[indices[e]] = o + m
            m += 1
        for e in range(t_ptr[i], t_ptr[i + 1]):
            j = t_col[e]
            if pos[j] >= 0:
                if t_dist[e] < out_dist[pos[j]]:
                    out_dist[pos[j]] = t_dist[e]
            else:
                out_col[o + m] = j
                out_dist[o + m] = t_dist[e]
                pos[j] = o + m
                m += 1
        for a in range(o, o + m):
            pos[out_col[a]] = -1
        for a in range(o + 1, o + m):
            c = out_col[a]
            d = out_dist[a]
            b = a - 1
            while b >= o and out_dist[b] > d:
                out_col[b + 1] = out_col[b]
                out_dist[b + 1] = out_dist[b]
                b -= 1
            out_col[b + 1] = c
            out_dist[b + 1] = d
    return out_ptr, out_col, out_dist


@nb.njit(cache=True, nogil=True)
def pair_block(
    indptr: np.ndarray,
    indices: np.ndarray,
    weights: np.ndarray,
    group_source: np.ndarray,
    group_ptr: np.ndarray,
    targets: np.ndarray,
    limit: float,
) -> np.ndarray:
    """Dijkstra from each group source until all of its targets are settled.

    Parameters
    ----------
    indptr, indices, weights : CSR arrays of the graph
    group_source : (g,) int64 source vertex of each group
    group_ptr : (g+1,) int64
        Group ``k`` owns ``targets[group_ptr[k]:group_ptr[k+1]]``.
    targets : (P,) int64 target vertices
    limit : float
        Search radius.

    Returns
    -------
    (P,) float64
        Distance to each target, inf beyond ``limit`` or unreachable.
    """
    n = len(indptr) - 1
    dist = np.full(n, np.inf)
    done = np.zeros(n, dtype=np.bool_)
    wanted = np.zeros(n, dtype=np.bool_)
    touched = np.empty(n, dtype=np.int64)
    hd = np.empty(n, dtype=np.float64)
    hv = np.empty(n, dtype=np.int64)
    pos = np.full(n, -1, dtype=np.int64)
    out = np.full(len(targets), np.inf)
    for k in range(len(group_source)):
        lo, hi = group_ptr[k], group_ptr[k + 1]
        remaining = 0
        for p in range(lo, hi):
            if not wanted[targets[p]]:
                wanted[targets[p]] = True
                remaining += 1
        s = group_source[k]
        dist[s] = 0.0
        touched[0] = s
        n_touched = 1
        size = heap_set(hd, hv, pos, np.int64(0), 0.0, s)  # a literal 0 compiles a second signature
        while size > 0 and remaining > 0:
            d, u = heap_pop(hd, hv, pos, size)
            size -= 1
            done[u] = True
            if wanted[u]:
                remaining -= 1
            for e in range(indptr[u], indptr[u + 1]):
                w = indices[e]
                nd = d + weights[e]
                if nd <= limit and nd < dist[w]:
                    if dist[w] == np.inf:
                        touched[n_touched] = w
                        n_touched += 1
                    dist[w] = nd
                    size = heap_set(hd, hv, pos, size, nd, w)
        for i in range(size):  # stopped early: clear what is still queued
            pos[hv[i]] = -1
        for p in range(lo, hi):
            t = targets[p]
            if done[t]:
                out[p] = dist[t]
            wanted[t] = False
        for t in range(n_touched):
            dist[touched[t]] = np.inf
            done[touched[t]] = False
    return out


def balls(
    indptr: np.ndarray, indices: np.ndarray, weights: np.ndarray, sources: np.ndarray, label: np.ndarray, limit: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`ball_rows` from every source, the sources split over the worker threads
    (:func:`intrinsym._threads.map_ranges`).

    Returns
    -------
    counts, cols, dists
        As :func:`ball_rows` returns them for all of ``sources`` in order.
    """
    parts = map_ranges(lambda lo, hi: ball_rows(indptr, indices, weights, sources[lo:hi], label, limit), len(sources))
    if not parts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float64)
    counts, cols, dists = zip(*parts, strict=True)
    return np.concatenate(counts), np.concatenate(cols), np.concatenate(dists)


def ball_pairs(
    graph: tuple[np.ndarray, np.ndarray, np.ndarray], sources: np.ndarray, limit: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Graph-geodesic distances from ``sources`` to every vertex within ``limit``, as
    sparse triples (:func:`balls` on the worker threads; SciPy's ``dijkstra`` holds the GIL
    and fills every row to the graph's size).

    Parameters
    ----------
    graph : (indptr, indices, weights)
        The graph as :func:`csr_arrays` returns it.
    sources : (m,) int64
    limit : float

    Returns
    -------
    rows, cols, dists : (nnz,) int64, int64, float64
        Source index (into ``sources``), vertex and distance of every vertex within
        ``limit`` of a source.
    """
    counts, cols, dists = balls(*graph, sources, np.arange(len(graph[0]) - 1, dtype=np.int64), limit)
    return np.repeat(np.arange(len(sources)), counts), cols, dists
