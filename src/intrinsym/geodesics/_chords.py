"""Numba kernels of :func:`intrinsym.geodesics.geodesics.surface_graph`: the candidate edges of every
vertex (mesh edges, shortcut chords and the chords within a few edge hops), and which
chords to keep. Each runs over a range of vertices, so that
:func:`intrinsym._threads.map_ranges` splits the rows over the worker threads."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, nogil=True)
def _candidates(
    u: int,
    adj_ptr: np.ndarray,
    adj_idx: np.ndarray,
    base_ptr: np.ndarray,
    base_idx: np.ndarray,
    rings: int,
    depth: np.ndarray,
    queue: np.ndarray,
) -> int:
    """Every vertex within ``rings`` edge hops of u, then u's base neighbours not among
    them, into ``queue[1:tail]`` (``queue[0]`` is u, the order is that of the search);
    returns tail. ``depth`` (all -1) is marked for ``queue[:tail]``."""
    depth[u] = 0
    queue[0] = u
    head = 0
    tail = 1
    while head < tail:
        v = queue[head]
        head += 1
        if depth[v] == rings:
            continue
        for e in range(adj_ptr[v], adj_ptr[v + 1]):
            w = adj_idx[e]
            if depth[w] < 0:
                depth[w] = depth[v] + 1
                queue[tail] = w
                tail += 1
    for e in range(base_ptr[u], base_ptr[u + 1]):
        w = base_idx[e]
        if depth[w] < 0:
            depth[w] = rings + 1
            queue[tail] = w
            tail += 1
    return tail


@nb.njit(cache=True, nogil=True)
def candidate_rows(
    lo: int,
    hi: int,
    adj_ptr: np.ndarray,
    adj_idx: np.ndarray,
    base_ptr: np.ndarray,
    base_idx: np.ndarray,
    rings: int,
    fill: bool,
    ptr: np.ndarray,
    idx: np.ndarray,
    is_base: np.ndarray,
) -> None:  # pragma: no cover
    """Rows ``lo:hi`` of the candidate pattern: u's candidate edges are the vertices
    within ``rings`` edge hops of u and u's base neighbours.

    Run twice: without ``fill``, ``ptr[u + 1]`` receives the number of u's candidates;
    with it (``ptr`` their running sum), ``idx[ptr[u]:ptr[u+1]]`` receives them in
    ascending order and ``is_base`` whether each is a base edge.

    Parameters
    ----------
    lo, hi : int
    adj_ptr, adj_idx : CSR adjacency of the mesh edges, (N+1,), (2M,) int64
    base_ptr, base_idx : symmetric CSR of the edges always kept, (N+1,), (B,) int64
    rings : int
    fill : bool
    ptr : (N+1,) int64
    idx : (E,) int64
    is_base : (E,) bool
    """
    n = len(adj_ptr) - 1
    depth = np.full(n, -1, dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    for u in range(lo, hi):
        tail = _candidates(u, adj_ptr, adj_idx, base_ptr, base_idx, rings, depth, queue)
        for t in range(tail):
            depth[queue[t]] = -1
        if not fill:
            ptr[u + 1] = tail - 1
            continue
        # an insertion sort: rows hold a few dozen vertices, and np.sort would add a
        # second to the first run's compilation
        row = idx[ptr[u] : ptr[u + 1]]
        for i in range(tail - 1):
            w = queue[i + 1]
            j = i
            while j > 0 and row[j - 1] > w:
                row[j] = row[j - 1]
                j -= 1
            row[j] = w
        for e in range(base_ptr[u], base_ptr[u + 1]):
            depth[base_idx[e]] = 0
        for i in range(len(row)):
            is_base[ptr[u] + i] = depth[row[i]] == 0
        for e in range(base_ptr[u], base_ptr[u + 1]):
            depth[base_idx[e]] = -1


@nb.njit(cache=True, nogil=True)
def keep_chords(
    lo: int,
    hi: int,
    vertices: np.ndarray,
    ptr: np.ndarray,
    idx: np.ndarray,
    is_base: np.ndarray,
    tol: float,
    keep: np.ndarray,
) -> None:  # pragma: no cover
    """Which candidate edges of the vertices ``lo:hi`` to keep, into ``keep``: base
    edges, and chords no 2-path nearly matches.

    A chord (u, w) is dropped when some common neighbour x has
    ``|ux| + |xw| <= (1 + tol) |uw|``: x lies almost on the segment, so the chord would
    shorten no path by more than ``tol``. The test is symmetric in u and w.

    Parameters
    ----------
    lo, hi : int
        The vertices whose rows are decided.
    vertices : (N, 3) float64
    ptr, idx : symmetric CSR pattern of all candidate edges, (N+1,), (E,) int64
    is_base : (E,) bool
        Entries that are kept unconditionally.
    tol : float
    keep : (E,) bool
        Receives the decision of every entry of the rows ``lo:hi``.
    """
    n = len(ptr) - 1
    len_u = np.full(n, np.inf)
    for u in range(lo, hi):
        for e in range(ptr[u], ptr[u + 1]):
            w = idx[e]
            len_u[w] = np.sqrt(
                (vertices[u, 0] - vertices[w, 0]) ** 2
                + (vertices[u, 1] - vertices[w, 1]) ** 2
                + (vertices[u, 2] - vertices[w, 2]) ** 2
            )
        for e in range(ptr[u], ptr[u + 1]):
            if is_base[e]:
                keep[e] = True
                continue
            w = idx[e]
            bound = (1.0 + tol) * len_u[w]
            keep[e] = True
            for f in range(ptr[w], ptr[w + 1]):
                x = idx[f]
                if x != u and len_u[x] < bound:
                    via = len_u[x] + np.sqrt(
                        (vertices[x, 0] - vertices[w, 0]) ** 2
                        + (vertices[x, 1] - vertices[w, 1]) ** 2
                        + (vertices[x, 2] - vertices[w, 2]) ** 2
                    )
                    if via <= bound:
                        keep[e] = False
                        break
        for e in range(ptr[u], ptr[u + 1]):
            len_u[idx[e]] = np.inf
