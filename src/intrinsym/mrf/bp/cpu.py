"""The CPU backend: loopy BP with the exact sparse ring message, in Numba.

Because Psi = max(psi, rho^2) (Eq. 6), the message of Eq. 7 splits into
``rho^2 * sum(h) + sum_{|d(fs,fq) - d(s,q)| < delta} (psi - rho^2) h(fs)``, and the
second sum runs over a contiguous slice of the distance-sorted row of fq. Messages
that do not depend on each other are computed in one batch (a batch of
:func:`~intrinsym.mrf.bp.schedule.schedule_steps`): for an entry d(fs, fq) of the row, the
batch's edges whose length lies within delta of it form a contiguous run once sorted by
length, so the inner loop runs over edges with contiguous h, weights and sums, and
vectorises.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import Executor

import numba as nb
import numpy as np

from ..._sorted import right
from ..._threads import map_ranges, worker_pool
from ..model import MRF
from .common import BPResult, Sweep, run_schedule
from .schedule import Steps, incoming_edges

# Highest degree of the polynomial that replaces exp in psi - rho^2 (see weight_polynomial).
MAX_WEIGHT_DEGREE = 15


def weight_polynomial(rho: float, tol: float = 2.0**-52) -> np.ndarray:
    """Polynomial in t = (x / delta)^2 equal to psi - rho^2 = exp(-lam x^2) - rho^2.

    x = |d(fs,fq) - d(s,q)| in [0, delta], so t in [0, 1] and psi - rho^2 =
    exp(-ln(1/rho^2) t) - rho^2. Numba's exp in a loop stays scalar (no SVML in pip
    builds), while a Horner polynomial vectorises, and is faster than a lookup table.
    Each degree costs one multiply-add per ring term, so the degree is the lowest whose
    Chebyshev interpolant is within ``tol`` of the weight on [0, 1]; where none up to
    :data:`MAX_WEIGHT_DEGREE` is (the power basis rounds at about 1e-15), the most
    accurate one. For float32 storage (tol = its epsilon, 1.2e-7) that is
    degree 7 at rho 0.4, against 11 for 1e-13.

    Parameters
    ----------
    rho : float
        The truncation level; the weight on t depends on nothing else.
    tol : float
        Largest error allowed on [0, 1] (absolute; the weight lies in [0, 1 - rho^2]).

    Returns
    -------
    (degree + 1,) float64
        Power-basis coefficients, constant term first.
    """
    rate = np.log(1.0 / rho**2)

    def weight(u: np.ndarray) -> np.ndarray:
        return np.exp(-rate * u) - rho**2

    t = np.linspace(0.0, 1.0, 4097)
    best, best_error = np.zeros(1), np.inf
    for degree in range(1, MAX_WEIGHT_DEGREE + 1):
        coef = (
            np.polynomial.Chebyshev.interpolate(weight, degree, domain=[0.0, 1.0])
            .convert(kind=np.polynomial.Polynomial)
            .coef
        )
        error = np.abs(np.polynomial.polynomial.polyval(t, coef) - weight(t)).max()
        if error <= tol:
            return coef
        if error < best_error:
            best, best_error = coef, error
    return best


@nb.njit(inline="always")
def _horner(t, coef):
    # coef is a tuple: its length is a compile-time constant, so the loop unrolls and
    # the ring loop around it still vectorises
    w = coef[-1]
    for k in range(len(coef) - 2, -1, -1):
        w = coef[k] + t * w
    return w


@nb.njit(cache=True, nogil=True, fastmath=True)
def _products(lo, hi, k0, k1, node, steps_ptr, steps_out, read, unary, ptr, directed, col, ht):  # pragma: no cover
    """Rows ``lo:hi`` of ``ht``: h of every outgoing message of the batch's steps
    ``k0:k1`` (the node's unary times its incoming messages, the receiver's own divided
    out), in the column ``col`` of the message's position by edge length."""
    e0 = steps_ptr[k0]
    for f in range(lo, hi):
        for k in range(k0, k1):
            s = node[k]
            p = np.float64(unary[s, f])
            for i in range(ptr[s], ptr[s + 1]):
                p *= read[directed[i], f]
            for i in range(steps_ptr[k], steps_ptr[k + 1]):
                ht[f, col[i - e0]] = p / read[steps_out[i] ^ 1, f]


@nb.njit(cache=True, nogil=True, fastmath=True)
def _rings(lo, hi, n_b, indptr, indices, dist, d, ring_scale, coef, ht, ring):  # pragma: no cover
    """Rows ``lo:hi`` of ``ring``: the ring sums of Eq. 7 of the batch's ``n_b``
    messages, whose edge lengths ``d`` are sorted."""
    dlt = ring_scale[0]  # delta, and 1 / delta^2, in the storage precision
    inv = ring_scale[1]
    zero = dlt - dlt
    first = d[0] - dlt
    last = d[n_b - 1] + dlt
    for fq in range(lo, hi):
        acc = ring[fq, :n_b]
        for c in range(n_b):
            acc[c] = zero
        a = indptr[fq]
        b = indptr[fq + 1]
        j = right(dist, a, b, first)
        lo_c = 0
        hi_c = 0
        while j < b and dist[j] < last:
            x = dist[j]
            while d[lo_c] <= x - dlt:
                lo_c += 1
            while hi_c < n_b and d[hi_c] < x + dlt:
                hi_c += 1
            # views starting at 0 let LLVM drop the negative-index wraparound and vectorise
            av = acc[lo_c:hi_c]
            hv = ht[indices[j], lo_c:hi_c]
            dv = d[lo_c:hi_c]
            for c in range(hi_c - lo_c):
                y = x - dv[c]
                t = y * y * inv
                w = _horner(t, coef)
                av[c] += max(w, zero) * hv[c]
            j += 1


@nb.njit(cache=True, nogil=True, fastmath=True)
def _normalise(lo, hi, n_b, outs, by_length, rho2, damping, ht, ring, hsum, colmax, write, moved):  # pragma: no cover
    """The blocks ``lo:hi`` of 16 messages: ``rho^2 * sum(h)`` added to the ring sums, each
    message max-normalised, damped and written; returns the largest change."""
    n_t = ht.shape[0]
    change = 0.0
    # 16 messages per block: reads of ring rows and writes of message rows both stream
    for blk in range(lo, hi):
        c_lo = blk * 16
        c_hi = min(n_b, c_lo + 16)
        for c in range(c_lo, c_hi):
            hsum[c] = 0.0
            colmax[c] = 0.0
        for f in range(n_t):
            for c in range(c_lo, c_hi):
                hsum[c] += ht[f, c]
                colmax[c] = max(colmax[c], ring[f, c])
        # rounding is monotonic, so the largest of ring + rho^2 sum(h) is the largest
        # ring sum plus rho^2 sum(h), bit for bit
        for c in range(c_lo, c_hi):
            colmax[c] = colmax[c] + rho2 * hsum[c]
        for c in range(c_lo, c_hi):
            out = outs[by_length[c]]
            m = colmax[c]
            mc = 0.0
            for f in range(n_t):
                old = write[out, f]
                # the sum stored in the ring's precision, as a write back to it would be
                total = ring.dtype.type(ring[f, c] + rho2 * hsum[c])
                v = (1.0 - damping) * (total / m) + damping * old
                write[out, f] = v
                mc = max(mc, abs(v - old))
            moved[out] = mc
            change = max(change, mc)
    return change


def _sweep(
    steps: Steps,
    read: np.ndarray,
    write: np.ndarray,
    unary: np.ndarray,
    ptr: np.ndarray,
    directed: np.ndarray,
    edge_length: np.ndarray,
    targets: tuple[np.ndarray, np.ndarray, np.ndarray],
    coef: tuple[float, ...],
    ring_scale: np.ndarray,
    rho2: float,
    damping: float,
    work: dict[str, np.ndarray],
    moved: np.ndarray,
    order: np.ndarray,
    pool: Executor,
) -> float:
    """Run one iteration of message updates, on the threads of ``pool``; return the
    largest change.

    ``moved[d]`` receives the largest change of every directed edge d sent. A batch's
    messages ``steps.out[e0:e0 + n_b]`` in order of edge length are those at the
    positions ``order[e0:e0 + n_b]`` within it (:func:`_by_length`).

    ``read`` holds the incoming messages, ``write`` receives the outgoing ones (the same
    array in the serial schedules). The steps of one batch read their inputs before any
    of them writes (:func:`~intrinsym.mrf.bp.schedule.schedule_steps` only batches steps
    that do not feed each other). Per batch, each step over the target rows on threads
    (:func:`intrinsym._threads.map_ranges`): h of every outgoing message, transposed
    into ``ht`` (T, B) with the messages sorted by edge length (:func:`_products`); the
    ring sums of Eq. 7 row by row (:func:`_rings`); then ``rho^2 * sum(h)`` is added and
    each message is max-normalised (:func:`_normalise`). The message to q divides q's
    own message out of the node's product, which is safe because every message is
    bounded below by rho^2.
    """
    n_t = unary.shape[1]
    indptr, indices, dist = targets
    ht, ring, hsum, colmax = work["ht"], work["ring"], work["hsum"], work["colmax"]
    change = 0.0
    for bt in range(len(steps.batch) - 1):
        k0, k1 = int(steps.batch[bt]), int(steps.batch[bt + 1])
        e0 = int(steps.ptr[k0])
        n_b = int(steps.ptr[k1]) - e0
        if n_b == 0:
            continue
        outs = steps.out[e0 : e0 + n_b]
        by_length = order[e0 : e0 + n_b]
        col = np.empty(n_b, dtype=np.int64)
        col[by_length] = np.arange(n_b)
        d = edge_length[outs[by_length] >> 1]
        inputs = (k0, k1, steps.node, steps.ptr, steps.out, read, unary, ptr, directed, col, ht)
        map_ranges(_products, n_t, *inputs, pieces_per_worker=1, pool=pool)
        rings = (n_b, indptr, indices, dist, d, ring_scale, coef, ht, ring)
        map_ranges(_rings, n_t, *rings, pieces_per_worker=1, pool=pool)
        outputs = (n_b, outs, by_length, rho2, damping, ht, ring, hsum, colmax, write, moved)
        changes = map_ranges(_normalise, (n_b + 15) // 16, *outputs, pieces_per_worker=1, pool=pool)
        change = max(change, *changes)
    return change


def _by_length(steps: Steps, edge_length: np.ndarray) -> np.ndarray:
    """Every batch's messages sorted by edge length, as positions within the batch.

    Returns
    -------
    (2E,) int64
        Entries ``ptr[batch[b]]:ptr[batch[b + 1]]`` order the messages of batch b.
    """
    sizes = np.diff(steps.ptr[steps.batch])
    batch = np.repeat(np.arange(len(sizes)), sizes)
    start = np.repeat(steps.ptr[steps.batch[:-1]], sizes)
    return np.lexsort((edge_length[steps.out >> 1], batch)) - start


def sparse_sweep(mrf: MRF, dtype: type = np.float32, damping: float = 0.0) -> Sweep:
    """Set up the sparse kernel once: weight polynomial, distances in storage precision.

    Parameters
    ----------
    mrf, dtype, damping
        As in :func:`intrinsym.mrf.bp.belief_propagation`.

    Returns
    -------
    callable(read, write, steps, moved) -> float
        Updates the messages of ``steps`` (read from ``read``, (2E, T), written to
        ``write``), stores the largest change of every message sent in ``moved`` (2E,)
        and returns the largest of all. Its working arrays, two (T, B) for
        the largest batch of B messages, grow on demand and are kept between calls.
    """
    delta = mrf.delta
    if not np.isfinite(delta):
        raise ValueError(f"lambda must be positive, got {mrf.lam}")
    if len(mrf.edge_length) and mrf.targets.radius < mrf.edge_length.max() + delta - 1e-12:
        raise ValueError(
            f"target distances reach {mrf.targets.radius:.4g}, but the exact message needs "
            f"{mrf.edge_length.max() + delta:.4g} (longest edge + delta)"
        )
    n_s, n_t = mrf.unary.shape
    ptr, directed = incoming_edges(mrf.edges, n_s)
    unary = np.ascontiguousarray(mrf.unary)
    tg = mrf.targets
    # the ring sum runs in the storage precision (float32: twice the SIMD width)
    dist: np.ndarray = tg.dist.astype(dtype)
    indices = tg.indices.astype(np.int32 if n_t < 2**31 else np.int64)
    coef = tuple(dtype(c) for c in weight_polynomial(mrf.rho, float(np.finfo(dtype).eps)))
    edge_length: np.ndarray = mrf.edge_length.astype(dtype)
    ring_scale: np.ndarray = np.array([delta, 1.0 / delta**2], dtype=dtype)
    rho2 = mrf.rho**2
    work: dict[str, np.ndarray] = {}

    def sweep(read: np.ndarray, write: np.ndarray, steps: Steps, moved: np.ndarray) -> float:
        width = int(np.diff(steps.ptr[steps.batch]).max(initial=1))
        if work.get("ht", np.empty((0, 0))).shape[1] < width:
            work.update(
                ht=np.empty((n_t, width), dtype=dtype),
                ring=np.empty((n_t, width), dtype=dtype),
                hsum=np.empty(width),
                colmax=np.empty(width),
            )
        with worker_pool() as pool:
            return _sweep(
                steps,
                read,
                write,
                unary,
                ptr,
                directed,
                edge_length,
                (tg.indptr, indices, dist),
                coef,
                ring_scale,
                rho2,
                damping,
                work,
                moved,
                _by_length(steps, edge_length),
                pool,
            )

    return sweep


def belief_propagation_cpu(
    mrf: MRF,
    schedule: str,
    iterations: int,
    tol: float,
    damping: float,
    seed: int,
    dtype: type,
    progress: Callable[[int, float], None] | None,
    initial: np.ndarray | None,
    started: float | None = None,
) -> BPResult:
    """Loopy BP on the CPU with the exact sparse ring message.

    Arguments as in :func:`intrinsym.mrf.bp.belief_propagation` (validated there);
    ``started`` is the ``time.perf_counter()`` the setup time counts from (default: now).

    Returns
    -------
    BPResult
        Marginals in ``dtype``.
    """
    if started is None:
        started = time.perf_counter()
    sweep = sparse_sweep(mrf, dtype, damping)
    return run_schedule(mrf.unary, mrf.edges, schedule, iterations, tol, seed, dtype, sweep, progress, started, initial)
