"""Exact nearest neighbours among the rows of a spectral embedding.

A functional map's point map sends every vertex to the vertex whose eigenfunction row is
nearest to its mapped row: tens of thousands of queries among as many rows in 20-100
dimensions. A k-d tree degrades in these dimensions and exhaustive matrix products cost
``Q T k`` multiply-adds (and, in float32, lose the nearest row to cancellation: the rows'
norms are large against their spacing). The rows of an eigenfunction embedding lie on a
two-dimensional surface, so :func:`nearest_rows` groups them into small clusters, prunes
whole clusters with the triangle inequality and measures the rest exactly. On a GPU
(``device="gpu"``, CuPy) exhaustive float64 products are cheap instead:
:func:`dense_nearest_rows` takes each query's smallest product distance and sends the few
queries whose nearest row is not clear beyond rounding to the exact search.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np

from .._threads import map_ranges

__all__ = ["RowIndex", "dense_nearest_rows", "nearest_leading_rows", "nearest_rows", "row_index", "search_rows"]

#: Slack of the pruning bound, relative to the best distance and, for queries on a row, to
#: the largest norm: far above the float64 rounding of the distances to the cluster
#: centres, which come from matrix products (about 1e-8 of the norm near a centre).
PRUNE_SLACK = 1e-6

#: Queries whose distances to the cluster centres are held at once (x clusters float64).
CHUNK = 4096

#: A block of at least this many queries is searched on threads: starting them costs
#: about 2 ms, the serial search of ZoomOut's 500 queries in 3,000 rows 0.5 ms.
PARALLEL_QUERIES = 2048

#: Rounding bound of :func:`dense_nearest_rows`, relative to ``|q|^2 + max |x|^2``: far
#: above the float64 error of a product distance in up to a few hundred dimensions (k
#: times 1.1e-16).
DENSE_SLACK = 1e-10

#: Bytes of the (queries x rows) float64 block :func:`dense_nearest_rows` holds at once.
DENSE_BLOCK_BYTES = 1 << 28


# reassociation lets the distance sum vectorise (no early exit: a branch per term is
# slower than the whole sum); no assumption about infinities (the best starts at inf).
# A serial kernel of a query range, run on intrinsym._threads, not a prange loop: between
# ZoomOut's BLAS products, the spinning OpenMP workers of a prange took the cores from
# OpenBLAS's threads (8 ms per level on 3,000 rows, against 1 ms; docs/notes/2026-11-28-speed-behind-the-defaults.md)
@nb.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _search(
    lo: int,
    hi: int,
    query: np.ndarray,
    basis: np.ndarray,
    to_centre: np.ndarray,
    radius: np.ndarray,
    starts: np.ndarray,
    members: np.ndarray,
    floor: float,
    nearest: np.ndarray,
) -> None:  # pragma: no cover
    """Nearest basis row of the queries ``lo:hi``, visiting only the clusters that can
    hold it, into ``nearest[lo:hi]``.

    Parameters
    ----------
    lo, hi : int
        The queries searched.
    query : (Q, k) float64
    basis : (T, K) float64
        The rows; their first k columns are searched.
    to_centre : (Q, m) float64
        Distance of every query to every cluster centre.
    radius : (m,) float64
        Largest distance of a cluster's rows to its centre.
    starts, members : (m + 1,), (T,) int64
        The rows of cluster j are ``members[starts[j]:starts[j + 1]]``.
    floor : float
        Absolute slack of the bound (:data:`PRUNE_SLACK` times the largest norm).
    nearest : (Q,) int64
        Receives the nearest row (the smallest index among exact ties).
    """
    k = query.shape[1]
    m = radius.shape[0]
    for i in range(lo, hi):
        first = 0  # np.argmin, written out: it adds 0.4 s to the first run's compilation
        for j in range(1, m):
            if to_centre[i, j] < to_centre[i, first]:
                first = j
        best = np.inf
        best_row = -1
        q = query[i]
        for step in range(m + 1):
            # the nearest centre's cluster first: its rows bound the distance early
            j = first if step == 0 else step - 1
            if step > 0 and (j == first or to_centre[i, j] - radius[j] > np.sqrt(best) * (1.0 + PRUNE_SLACK) + floor):
                continue
            for p in range(starts[j], starts[j + 1]):
                row = members[p]
                x = basis[row]
                d = 0.0
                for c in range(k):
                    t = q[c] - x[c]
                    d += t * t
                if d < best or (d == best and row < best_row):
                    best = d
                    best_row = row
        nearest[i] = best_row


def _distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(len(a), len(b)) Euclidean distances, float64."""
    sq = np.einsum("ij,ij->i", a, a)[:, None] + np.einsum("ij,ij->i", b, b)[None, :] - 2.0 * (a @ b.T)
    return np.sqrt(np.maximum(sq, 0.0))


def dense_nearest_rows(query: np.ndarray, basis: np.ndarray, xp: Any = np) -> np.ndarray:
    """Index of the nearest ``basis`` row of every ``query`` row, by dense products in the
    array module ``xp`` (CuPy on a GPU, NumPy for the tests); exact as :func:`nearest_rows`.

    ``|x|^2 / 2 - q.x`` over all rows ``x`` of a block of queries, its argmin a candidate.
    A query for which another row lies within the rounding bound (:data:`DENSE_SLACK`) of
    the smallest value, the true nearest row among them, goes to :func:`nearest_rows`; for
    every other query the candidate is the nearest row.

    Parameters
    ----------
    query : (Q, k) float array
    basis : (T, k) float array
    xp : module
        ``numpy`` or ``cupy``.

    Returns
    -------
    (Q,) int64
        Nearest row of ``basis`` (the smallest index among exact ties), a NumPy array.
    """
    q = np.ascontiguousarray(query, dtype=np.float64)
    x = np.ascontiguousarray(basis, dtype=np.float64)
    _check(q, x)
    to_host = getattr(xp, "asnumpy", np.asarray)
    rows = xp.asarray(x)
    half = 0.5 * xp.sum(rows * rows, axis=1)
    queries = xp.asarray(q)
    slack = DENSE_SLACK * (xp.sum(queries * queries, axis=1) + 2.0 * half.max())
    nearest = np.empty(len(q), dtype=np.int64)
    unclear = np.zeros(len(q), dtype=bool)
    step = max(1, DENSE_BLOCK_BYTES // (8 * len(x)))
    for lo in range(0, len(q), step):
        d = half[None, :] - queries[lo : lo + step] @ rows.T
        best = xp.argmin(d, axis=1)
        low = d[xp.arange(len(best)), best] + slack[lo : lo + step]
        nearest[lo : lo + step] = to_host(best)
        unclear[lo : lo + step] = to_host(xp.count_nonzero(d <= low[:, None], axis=1) > 1)
    if unclear.any():
        nearest[unclear] = nearest_rows(q[unclear], x)
    return nearest


def _check(q: np.ndarray, x: np.ndarray) -> None:
    """ValueError unless ``q`` (Q, k) and ``x`` (T, k) with T >= 1."""
    if q.ndim != 2 or x.ndim != 2 or q.shape[1] != x.shape[1] or len(x) == 0:
        raise ValueError(f"need (Q, k) queries and (T, k) rows, T >= 1; got {q.shape} and {x.shape}")


@dataclass(frozen=True)
class RowIndex:
    """The rows of a basis grouped into clusters for :func:`nearest_rows`, built once by
    :func:`row_index` and searched with the rows' first ``k`` columns for any ``k``.

    A cluster of the full rows is a cluster of their leading columns too (dropping columns
    only brings rows closer), so ZoomOut, whose levels search the leading ``k`` columns
    of one basis for ``k = k_start, ..., K``, and a map that searches one basis for
    several queries, cluster once; the radii are measured again for each ``k``.

    Attributes
    ----------
    basis : (T, K) float64
        The rows, C-contiguous.
    centres : (m, K) float64
        Cluster centres (rows of ``basis``).
    cluster : (T,) int64
        The cluster of every row.
    starts, members : (m + 1,), (T,) int64
        The rows of cluster j are ``members[starts[j]:starts[j + 1]]``.
    """

    basis: np.ndarray
    centres: np.ndarray
    cluster: np.ndarray
    starts: np.ndarray
    members: np.ndarray


def row_index(basis: np.ndarray, n_clusters: int | None = None) -> RowIndex:
    """Group the rows of ``basis`` around ``n_clusters`` centres for :func:`nearest_rows`.

    The centres are basis rows drawn at random with a fixed seed; each row joins the
    cluster of its nearest centre (float32 products: any assignment is correct, a good one
    is fast).

    Parameters
    ----------
    basis : (T, K) float array, T >= 1
    n_clusters : int, optional
        Default ``4 sqrt(T)``: about ``sqrt(T) / 4`` rows per cluster.

    Returns
    -------
    RowIndex
    """
    x = np.ascontiguousarray(basis, dtype=np.float64)
    if x.ndim != 2 or len(x) == 0:
        raise ValueError(f"need (T, k) rows, T >= 1; got {x.shape}")
    n_rows = len(x)
    m = int(min(n_rows, n_clusters or max(1, round(4 * np.sqrt(n_rows)))))
    centres = x[np.sort(np.random.default_rng(0).choice(n_rows, m, replace=False))]
    x32 = x.astype(np.float32)
    c32 = centres.astype(np.float32)
    cluster = np.empty(n_rows, dtype=np.int64)
    half_norm = 0.5 * np.einsum("ij,ij->i", c32, c32)
    for lo in range(0, n_rows, CHUNK):
        cluster[lo : lo + CHUNK] = np.argmin(half_norm - x32[lo : lo + CHUNK] @ c32.T, axis=1)
    members = np.argsort(cluster, kind="stable")
    starts = np.searchsorted(cluster[members], np.arange(m + 1))
    return RowIndex(x, centres, cluster, starts, members)


def nearest_rows(query: np.ndarray, basis: np.ndarray | RowIndex, n_clusters: int | None = None) -> np.ndarray:
    """Index of the nearest ``basis`` row of every ``query`` row (Euclidean, exact).

    The basis rows are grouped into clusters (:func:`row_index`, unless ``basis`` is an
    index already), each cluster's radius ``R_j`` measured in float64 in the query's
    columns. A query visits its nearest centre's cluster first; the best distance ``b``
    so far then rules out every cluster with ``|q - c_j| - R_j > b`` (triangle
    inequality). Distances to the visited rows are summed in float64, term by term: no
    cancellation.

    Parameters
    ----------
    query : (Q, k) float array
    basis : (T, k) float array, or RowIndex
        The rows, or their index; an index of (T, K) rows, K >= k, is searched in its
        first k columns.
    n_clusters : int, optional
        Clusters of the index built from an array (:func:`row_index`).

    Returns
    -------
    (Q,) int64
        Nearest row of ``basis`` (the smallest index among exact ties).
    """
    q = np.ascontiguousarray(query, dtype=np.float64)
    if isinstance(basis, RowIndex):
        index = basis
        if q.ndim != 2 or q.shape[1] > index.basis.shape[1]:
            raise ValueError(
                f"need (Q, k) queries for an index of (T, K) rows, k <= K; got {q.shape} and {index.basis.shape}"
            )
    else:
        _check(q, np.asarray(basis))
        index = row_index(basis, n_clusters)
    k = q.shape[1]
    x = index.basis[:, :k]
    centres = np.ascontiguousarray(index.centres[:, :k])  # a strided slice slows the products 8x
    radius = np.zeros(len(centres))
    np.maximum.at(radius, index.cluster, np.linalg.norm(x - centres[index.cluster], axis=1))
    norms = [np.sqrt(np.einsum("ij,ij->i", a, a).max(initial=0.0)) for a in (q, x)]
    floor = PRUNE_SLACK * max(norms)
    nearest = np.empty(len(q), dtype=np.int64)
    for lo in range(0, len(q), CHUNK):
        block = q[lo : lo + CHUNK]
        # the kernel reads a row's first k entries: the full rows need no copy
        search = (block, index.basis, _distances(block, centres), radius, index.starts, index.members, floor)
        if len(block) >= PARALLEL_QUERIES:
            map_ranges(_search, len(block), *search, nearest[lo : lo + CHUNK])
        else:
            _search(0, len(block), *search, nearest[lo : lo + CHUNK])
    return nearest


def search_rows(rows: np.ndarray | RowIndex, device: str = "cpu") -> np.ndarray | RowIndex:
    """``rows`` (T, K) as they are best searched many times on ``device``: their index on
    the CPU (:func:`row_index`; an index as it is), the float64 array on a GPU
    (:func:`dense_nearest_rows`)."""
    if isinstance(rows, RowIndex):
        return rows if device == "cpu" else rows.basis
    return row_index(rows) if device == "cpu" else np.asarray(rows, dtype=np.float64)


def nearest_leading_rows(query: np.ndarray, rows: np.ndarray | RowIndex, device: str = "cpu") -> np.ndarray:
    """Index of the nearest row of every ``query`` row (Q, k), in the first k columns of
    ``rows`` (T, K >= k, or their :func:`search_rows`): :func:`nearest_rows` on the CPU,
    :func:`dense_nearest_rows` with CuPy on a GPU (``device="gpu"``); the same rows."""
    k = np.shape(query)[1]
    if device == "gpu":
        import cupy

        basis = rows.basis if isinstance(rows, RowIndex) else np.asarray(rows, dtype=np.float64)
        return dense_nearest_rows(query, basis[:, :k], cupy)
    return nearest_rows(query, rows if isinstance(rows, RowIndex) else np.asarray(rows)[:, :k])
