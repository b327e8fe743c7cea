"""Sum-product loopy belief propagation on the correspondence MRF (paper Sec. 3.1, 4).

Two implementations share one schedule and one normalisation:

* :func:`belief_propagation` — the exact sparse ring message of DESIGN.md in Numba.
  Because Psi = max(psi, rho^2) (Eq. 6), the message of Eq. 7 splits into
  ``rho^2 * sum(h) + sum_{|d(fs,fq) - d(s,q)| < delta} (psi - rho^2) h(fs)``, and the
  second sum runs over a contiguous slice of the distance-sorted target row.
* :func:`belief_propagation_dense` — the paper-literal O(|Pt|^2) message in NumPy,
  the test oracle.

Messages are max-normalised (they then lie in [rho^2, 1], so products of a dozen stay
far from float32 underflow). A message is stored per directed edge: undirected edge e
joining (i, j) gives directed edge 2e for i -> j and 2e + 1 for j -> i.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from .model import MRF, pairwise_dense

SCHEDULES = ("serial", "flooding")


@dataclass
class BPResult:
    """Outcome of loopy belief propagation.

    Attributes
    ----------
    marginals : (S, T) array
        Beliefs of Eq. 8, each row normalised to sum 1.
    iterations : int
        Iterations run.
    converged : bool
        Whether the largest message change fell below the tolerance.
    max_change : float
        Largest absolute change of a (max-normalised) message in the last iteration.
    history : list of float
        ``max_change`` after every iteration.
    seconds : list of float
        Wall time of every iteration.
    """

    marginals: np.ndarray
    iterations: int
    converged: bool
    max_change: float
    history: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)


def incoming_edges(edges: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR lists of the directed edges entering every node.

    Parameters
    ----------
    edges : (E, 2) int
        Undirected edges.
    n_nodes : int

    Returns
    -------
    ptr : (n_nodes + 1,) int64
    directed : (2E,) int64
        ``directed[ptr[s]:ptr[s+1]]`` are the directed edges n -> s; ``d ^ 1`` is the
        reverse edge s -> n.
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    heads = np.empty(2 * len(edges), dtype=np.int64)
    heads[0::2] = edges[:, 1]
    heads[1::2] = edges[:, 0]
    directed = np.argsort(heads, kind="stable").astype(np.int64)
    ptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.cumsum(np.bincount(heads, minlength=n_nodes), out=ptr[1:])
    return ptr, directed


def serial_orders(n_nodes: int, iterations: int, seed: int) -> list[np.ndarray]:
    """Node order of every serial iteration (paper Sec. 4).

    The first iteration visits nodes in index order, later ones in a random order; each
    iteration is a forward pass followed by the backward (reversed) pass.

    Returns
    -------
    list of (2 n_nodes,) int64 arrays, one per iteration.
    """
    rng = np.random.default_rng(seed)
    orders = []
    for it in range(iterations):
        order = np.arange(n_nodes) if it == 0 else rng.permutation(n_nodes)
        orders.append(np.concatenate([order, order[::-1]]).astype(np.int64))
    return orders


def beliefs(unary: np.ndarray, messages: np.ndarray, ptr: np.ndarray, directed: np.ndarray) -> np.ndarray:
    """Normalised beliefs of Eq. 8 from the incoming messages.

    Returns
    -------
    (S, T) float64 array, rows summing to 1.
    """
    b = np.array(unary, dtype=np.float64, copy=True)
    for s in range(b.shape[0]):
        for d in directed[ptr[s] : ptr[s + 1]]:
            b[s] *= messages[d]
        b[s] /= b[s].sum()
    return b


@nb.njit(cache=True, inline="always")
def _first_above(dist, lo, hi, x):
    """First k in [lo, hi) with dist[k] > x (dist ascending)."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if dist[mid] > x:
            hi = mid
        else:
            lo = mid + 1
    return lo


@nb.njit(cache=True, inline="always")
def _first_at_least(dist, lo, hi, x):
    """First k in [lo, hi) with dist[k] >= x (dist ascending)."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if dist[mid] >= x:
            hi = mid
        else:
            lo = mid + 1
    return lo


@nb.njit(parallel=True, cache=True)
def _update_node(
    s, read, write, unary, ptr, directed, edge_length,
    indptr, indices, dist, delta, lam, rho2, damping, prod, h, m,
):
    """Send every message leaving node s; return the largest change.

    ``read`` holds the incoming messages, ``write`` receives the outgoing ones (the same
    array in the serial schedule). The product of all incoming messages is formed once;
    the message to q divides q's own message out, which is safe because every message
    is bounded below by rho^2 (DESIGN.md, "Known traps").
    """
    n_t = unary.shape[1]
    a = ptr[s]
    b = ptr[s + 1]
    for f in nb.prange(n_t):
        p = np.float64(unary[s, f])
        for k in range(a, b):
            p *= read[directed[k], f]
        prod[f] = p
    change = 0.0
    for k in range(a, b):
        back = directed[k]
        out = back ^ 1
        d_sq = edge_length[out >> 1]
        hsum = 0.0
        for f in nb.prange(n_t):
            v = prod[f] / read[back, f]
            h[f] = v
            hsum += v
        lo_d = d_sq - delta
        hi_d = d_sq + delta
        mmax = 0.0
        for fq in nb.prange(n_t):
            r0 = indptr[fq]
            r1 = indptr[fq + 1]
            lo = _first_above(dist, r0, r1, lo_d)
            hi = _first_at_least(dist, lo, r1, hi_d)
            acc = 0.0
            for j in range(lo, hi):
                diff = dist[j] - d_sq
                w = np.exp(-lam * diff * diff) - rho2
                if w > 0.0:
                    acc += w * h[indices[j]]
            v = rho2 * hsum + acc
            m[fq] = v
            mmax = max(mmax, v)
        local = 0.0
        for fq in nb.prange(n_t):
            old = write[out, fq]
            v = (1.0 - damping) * (m[fq] / mmax) + damping * old
            write[out, fq] = v
            local = max(local, abs(v - old))
        change = max(change, local)
    return change


def _check(mrf_unary: np.ndarray, schedule: str, iterations: int, damping: float) -> None:
    if schedule not in SCHEDULES:
        raise ValueError(f"unknown schedule {schedule!r}; expected one of {SCHEDULES}")
    if iterations < 1:
        raise ValueError(f"iterations must be at least 1, got {iterations}")
    if not 0.0 <= damping < 1.0:
        raise ValueError(f"damping must lie in [0, 1), got {damping}")
    if np.any(~np.isfinite(mrf_unary)) or np.any(mrf_unary <= 0):
        raise ValueError("unary potentials must be finite and positive")


def _run(
    unary: np.ndarray,
    edges: np.ndarray,
    schedule: str,
    iterations: int,
    tol: float,
    seed: int,
    dtype: type,
    sweep: Callable[[np.ndarray, np.ndarray, np.ndarray], float],
    progress: Callable[[int, float], None] | None,
) -> BPResult:
    """Iterate a node-update ``sweep(read, write, order)`` to convergence."""
    n_s, n_t = unary.shape
    ptr, directed = incoming_edges(edges, n_s)
    messages = np.ones((2 * len(edges), n_t), dtype=dtype)
    orders = serial_orders(n_s, iterations, seed)
    history: list[float] = []
    seconds: list[float] = []
    converged = False
    for it in range(iterations):
        t0 = time.perf_counter()
        if schedule == "serial":
            change = sweep(messages, messages, orders[it])
        else:
            new = messages.copy()
            change = sweep(messages, new, orders[0][:n_s])
            messages = new
        seconds.append(time.perf_counter() - t0)
        history.append(float(change))
        if progress is not None:
            progress(it + 1, float(change))
        if change < tol:
            converged = True
            break
    marg = beliefs(unary, messages, ptr, directed).astype(dtype)
    return BPResult(marg, len(history), converged, history[-1] if history else 0.0, history, seconds)


def belief_propagation(
    mrf: MRF,
    schedule: str = "serial",
    iterations: int = 100,
    tol: float = 1e-4,
    damping: float = 0.0,
    seed: int = 0,
    dtype: type = np.float32,
    progress: Callable[[int, float], None] | None = None,
) -> BPResult:
    """Loopy sum-product BP with the exact sparse ring message.

    Parameters
    ----------
    mrf : MRF
        The model. ``mrf.targets.radius`` must be at least
        ``mrf.edge_length.max() + mrf.delta``, else the message would not be exact.
    schedule : {"serial", "flooding"}
        "serial": the paper's forward and backward sweeps, index order first, then random
        orders; every node sends to all neighbours from the latest messages.
        "flooding": every message is recomputed from the previous iteration's messages.
    iterations : int
        Maximum number of iterations T (paper: 100).
    tol : float
        Stop when the largest change of a max-normalised message falls below this.
    damping : float in [0, 1)
        New message = (1 - damping) * computed + damping * previous.
    seed : int
        Seed of the random serial orders.
    dtype : numpy float type
        Message storage; arithmetic is float64 throughout.
    progress : callable(iteration, max_change), optional

    Returns
    -------
    BPResult
    """
    _check(mrf.unary, schedule, iterations, damping)
    delta = mrf.delta
    if len(mrf.edge_length) and mrf.targets.radius < mrf.edge_length.max() + delta - 1e-12:
        raise ValueError(
            f"target distances reach {mrf.targets.radius:.4g}, but the exact message needs "
            f"{mrf.edge_length.max() + delta:.4g} (longest edge + delta)"
        )
    n_s, n_t = mrf.unary.shape
    ptr, directed = incoming_edges(mrf.edges, n_s)
    edge_length = np.ascontiguousarray(mrf.edge_length, dtype=np.float64)
    unary = np.ascontiguousarray(mrf.unary)
    tg = mrf.targets
    prod = np.empty(n_t)
    h = np.empty(n_t)
    m = np.empty(n_t)
    rho2 = mrf.rho**2

    def sweep(read: np.ndarray, write: np.ndarray, order: np.ndarray) -> float:
        change = 0.0
        for s in order:
            c = _update_node(
                s, read, write, unary, ptr, directed, edge_length,
                tg.indptr, tg.indices, tg.dist, delta, mrf.lam, rho2, damping, prod, h, m,
            )
            change = max(change, c)
        return change

    return _run(unary, mrf.edges, schedule, iterations, tol, seed, dtype, sweep, progress)


def belief_propagation_dense(
    unary: np.ndarray,
    edges: np.ndarray,
    edge_length: np.ndarray,
    target_dist: np.ndarray,
    lam: float,
    rho: float,
    schedule: str = "serial",
    iterations: int = 100,
    tol: float = 1e-4,
    damping: float = 0.0,
    seed: int = 0,
) -> BPResult:
    """Paper-literal BP (Eq. 7 with the full |Pt| x |Pt| pairwise table); the oracle.

    Same schedule, normalisation and stopping rule as :func:`belief_propagation`, but
    the product over incoming messages excludes the recipient explicitly and the message
    is a dense matrix-vector product. Float64 throughout. Use on small problems only.

    Parameters
    ----------
    unary : (S, T) array
    edges : (E, 2) int
    edge_length : (E,) float
    target_dist : (T, T) float
        All target-target geodesic distances.
    lam, rho, schedule, iterations, tol, damping, seed
        As in :func:`belief_propagation`.
    """
    _check(unary, schedule, iterations, damping)
    unary = np.asarray(unary, dtype=np.float64)
    n_s = unary.shape[0]
    ptr, directed = incoming_edges(edges, n_s)

    def sweep(read: np.ndarray, write: np.ndarray, order: np.ndarray) -> float:
        change = 0.0
        for s in order:
            incoming = directed[ptr[s] : ptr[s + 1]]
            for back in incoming:
                out = back ^ 1
                h = unary[s].copy()
                for other in incoming:
                    if other != back:
                        h *= read[other]
                psi = pairwise_dense(float(edge_length[out >> 1]), target_dist, lam, rho)
                msg = psi.T @ h
                new = (1.0 - damping) * msg / msg.max() + damping * write[out]
                change = max(change, float(np.abs(new - write[out]).max()))
                write[out] = new
        return change

    return _run(unary, edges, schedule, iterations, tol, seed, np.float64, sweep, None)
