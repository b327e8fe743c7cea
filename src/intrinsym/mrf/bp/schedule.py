"""Message schedules and the data layout shared by the CPU, GPU and dense implementations.

A message is stored per directed edge: undirected edge e joining (i, j) gives directed
edge 2e for i -> j and 2e + 1 for j -> i. :func:`incoming_edges` lists the directed edges
entering every node; :func:`schedule_steps` turns a schedule and a node order into the
:class:`Steps` of one iteration, which update every directed edge exactly once, grouped
into batches whose messages can be computed at once. :func:`ring_bounds` precomputes
the slices of the target distance rows that the exact sparse message sums over.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

#: "auto" is :func:`resolve_schedule`'s choice for the backend that runs.
SCHEDULES = ("auto", "serial", "colour", "residual", "flooding")
#: Schedules the GPU backend runs ("residual" decides at run time which nodes send).
GPU_SCHEDULES = ("auto", "serial", "colour", "flooding")


def resolve_schedule(schedule: str, backend: str) -> str:
    """The schedule that runs: ``schedule``, or for "auto" the fastest on ``backend``.

    On the CPU, "auto" is "residual": once most nodes' inputs have settled it skips
    their messages, which the "colour" schedule would recompute unchanged (at the
    default ``bp_tol`` about a fifth of the updates at 250 / 4000 samples, half at the
    paper's elephant size). On the GPU it is "colour", whose batches each run in one
    kernel launch whatever the number of messages.

    Parameters
    ----------
    schedule : str
        One of :data:`SCHEDULES`.
    backend : {"cpu", "gpu"}

    Returns
    -------
    str
        One of :data:`SCHEDULES` other than "auto".
    """
    if schedule != "auto":
        return schedule
    return "colour" if backend == "gpu" else "residual"


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
    iteration is a forward pass in this order, then the backward (reversed) pass.

    Returns
    -------
    list of (n_nodes,) int64 arrays, one per iteration.
    """
    rng = np.random.default_rng(seed)
    return [(np.arange(n_nodes) if it == 0 else rng.permutation(n_nodes)).astype(np.int64) for it in range(iterations)]


def colour_classes(edges: np.ndarray, n_nodes: int) -> np.ndarray:
    """Greedy colouring of the source graph, largest degree first.

    No two neighbours share a colour, so the nodes of one colour can send their messages
    at once, exactly as if one after the other.

    Parameters
    ----------
    edges : (E, 2) int
    n_nodes : int

    Returns
    -------
    (n_nodes,) int64
        The colour of every node, 0 .. (number of colours - 1).
    """
    ptr, directed = incoming_edges(edges, n_nodes)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    sender = edges[directed >> 1, directed & 1]
    colour = np.full(n_nodes, -1, dtype=np.int64)
    for s in np.argsort(-np.diff(ptr), kind="stable"):
        used = colour[sender[ptr[s] : ptr[s + 1]]]
        colour[s] = np.flatnonzero(~np.isin(np.arange(len(used) + 1), used))[0]
    return colour


def visiting_orders(schedule: str, edges: np.ndarray, n_nodes: int, iterations: int, seed: int) -> list[np.ndarray]:
    """Node order of every iteration of a schedule.

    "serial" and "flooding": :func:`serial_orders`. "colour" and "residual": the classes of
    :func:`colour_classes` in class order, the same in every iteration (a fixed class
    order converges in fewer iterations than a random one each iteration); within a class
    nodes keep index order (any order gives the same messages).

    Returns
    -------
    list of (n_nodes,) int64 arrays, one per iteration.
    """
    if schedule not in ("colour", "residual"):
        return serial_orders(n_nodes, iterations, seed)
    order = np.argsort(colour_classes(edges, n_nodes), kind="stable").astype(np.int64)
    return [order] * iterations


@dataclass(frozen=True)
class Steps:
    """The message updates of one iteration: nodes in visiting order and what each sends.

    Attributes
    ----------
    node : (K,) int64
        The node of every step.
    ptr : (K + 1,) int64
        Step k sends the directed edges ``out[ptr[k]:ptr[k+1]]``.
    out : (2E,) int64
        Directed edges, each exactly once; those of step k leave ``node[k]``.
    batch : (B + 1,) int64
        Batch b is the steps ``batch[b]:batch[b+1]``: none of them receives a message
        that an earlier step of the batch sends, so the batch's messages can all be
        computed from the messages as they were before it.
    """

    node: np.ndarray
    ptr: np.ndarray
    out: np.ndarray
    batch: np.ndarray


def schedule_steps(schedule: str, order: np.ndarray, edges: np.ndarray, ptr: np.ndarray, directed: np.ndarray) -> Steps:
    """One iteration of a schedule, updating every directed edge exactly once.

    "serial" (paper Sec. 4): the forward pass visits ``order`` and node s sends to the
    neighbours that come after it; the backward pass visits the reversed order and s
    sends to the neighbours that come before it, so each message is computed from the
    latest incoming ones and never twice. "colour": every node of ``order`` sends to all
    its neighbours, in one pass. "flooding": every node sends to all its neighbours from
    the previous iteration's messages (the caller double-buffers), all in one batch.
    Otherwise batches are the longest runs of steps in which no step's node receives a
    message sent earlier in the run; computing a batch at once gives exactly the
    messages of visiting its steps one by one.

    Parameters
    ----------
    schedule : {"serial", "colour", "residual", "flooding"}
        "residual" gives the steps of "colour" (it skips some at run time).
    order : (S,) int64
        A permutation of the nodes (see :func:`visiting_orders`).
    edges : (E, 2) int
    ptr, directed : from :func:`incoming_edges`

    Returns
    -------
    Steps
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    order = np.asarray(order, dtype=np.int64)
    n = len(order)
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n)
    sender = edges[directed >> 1, directed & 1]  # q of every incoming edge q -> s
    receiver = np.repeat(np.arange(n), np.diff(ptr))  # s
    if schedule == "serial":
        later = rank[sender] > rank[receiver]
        passes = [(order, later), (order[::-1], ~later)]
    else:
        passes = [(order, np.ones(len(directed), dtype=bool))]
    nodes, outs, counts = [], [], []
    for visit, mask in passes:
        for s in visit:
            sel = directed[ptr[s] : ptr[s + 1]][mask[ptr[s] : ptr[s + 1]]]
            outs.append(sel ^ 1)
            counts.append(len(sel))
        nodes.append(visit)
    step_ptr = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=step_ptr[1:])
    node = np.concatenate(nodes)
    if schedule == "flooding":
        batch = [0]
    else:
        batch, fed = [], np.zeros(n, dtype=bool)
        for k, s in enumerate(node):
            if fed[s] or not batch:
                batch.append(k)
                fed[:] = False
            fed[edges[outs[k] >> 1, 1 - (outs[k] & 1)]] = True
    batch.append(len(node))
    return Steps(node, step_ptr, np.concatenate(outs).astype(np.int64), np.asarray(batch, dtype=np.int64))


def active_steps(steps: Steps, batch: int, active: np.ndarray) -> Steps:
    """The steps of one batch whose node is active, as a one-batch :class:`Steps`.

    Parameters
    ----------
    steps : Steps
    batch : int
        Index of the batch.
    active : (S,) bool
        Nodes that send.

    Returns
    -------
    Steps
    """
    k = np.arange(steps.batch[batch], steps.batch[batch + 1])
    k = k[active[steps.node[k]]]
    counts = steps.ptr[k + 1] - steps.ptr[k]
    ptr = np.zeros(len(k) + 1, dtype=np.int64)
    np.cumsum(counts, out=ptr[1:])
    out = steps.out[np.repeat(steps.ptr[k] - ptr[:-1], counts) + np.arange(ptr[-1])]
    return Steps(steps.node[k], ptr, out, np.array([0, len(k)], dtype=np.int64))


@nb.njit(parallel=True, cache=True)
def _ring_bounds(indptr, dist, edge_length, delta, lo, hi):
    n_t = len(indptr) - 1
    for e in nb.prange(len(edge_length)):
        a = edge_length[e] - delta
        b = edge_length[e] + delta
        for f in range(n_t):
            row = dist[indptr[f] : indptr[f + 1]]
            left = np.searchsorted(row, a, side="right")
            right = np.searchsorted(row, b, side="left")
            lo[e, f] = indptr[f] + left
            hi[e, f] = indptr[f] + max(left, right)


def ring_bounds(
    indptr: np.ndarray, dist: np.ndarray, edge_length: np.ndarray, delta: float
) -> tuple[np.ndarray, np.ndarray]:
    """Slice of every distance row inside the ring of every edge, computed once.

    The ring of row fs for edge (s, q) depends only on d(s, q), which is fixed per edge,
    so the binary searches are done here and not in every iteration.

    Parameters
    ----------
    indptr : (T + 1,) int64
    dist : (nnz,) float
        Row-sorted distances of :class:`~intrinsym.geodesics.geodesics.SparseDistances`.
    edge_length : (E,) float64
    delta : float

    Returns
    -------
    lo, hi : (E, T) int32 (int64 when nnz >= 2^31)
        Row fs of edge e: the entries ``lo[e, fs] <= j < hi[e, fs]`` are those with
        ``|dist[j] - edge_length[e]| < delta``.
    """
    index = np.int32 if len(dist) < 2**31 else np.int64
    lo = np.empty((len(edge_length), len(indptr) - 1), dtype=index)
    hi = np.empty_like(lo)
    _ring_bounds(indptr, dist, np.asarray(edge_length, dtype=np.float64), float(delta), lo, hi)
    return lo, hi
