"""The GPU backend (CuPy): loopy BP with the exact sparse ring message.

CuPy is an optional dependency (``pip install intrinsym[gpu]``), imported only when the
backend runs, so this module imports without it. It runs the batches of
:func:`~intrinsym.mrf.bp.schedule.schedule_steps` (the colour classes of the "colour"
schedule, all messages at once for "flooding", the runs of the paper's "serial" sweeps),
so every schedule but "residual" gives the CPU backend's messages. Per batch, one kernel
launch computes every entry m_{s->q}(fq) of the batch's messages, one CUDA thread each,
pulling over the ring slice of row fq (rows are symmetric; the slices are the ones
:func:`~intrinsym.mrf.bp.schedule.ring_bounds` gives).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..model import MRF
from .common import BPResult, initial_messages, iterate
from .schedule import (
    GPU_SCHEDULES,
    Steps,
    incoming_edges,
    resolve_schedule,
    ring_bounds,
    schedule_steps,
    visiting_orders,
)

_RING_MESSAGE = r"""
extern "C" __global__ void ring_message(
    const float* h, const float* hsum, const long long* outs, const int* lo, const int* hi,
    const int* indices, const float* dist, const float* edge_length,
    const long long n_out, const int n_t, const float lam, const float rho2, float* out)
{
    long long k = (long long)blockDim.x * blockIdx.x + threadIdx.x;
    if (k >= n_out * n_t) return;
    long long i = k / n_t;
    int fq = (int)(k - i * n_t);
    long long e = outs[i] >> 1;
    float len = edge_length[e];
    const float* hd = h + i * n_t;
    float acc = 0.0f;
    for (int j = lo[e * n_t + fq]; j < hi[e * n_t + fq]; ++j) {
        float x = dist[j] - len;
        acc += fmaxf(expf(-lam * x * x) - rho2, 0.0f) * hd[indices[j]];
    }
    out[k] = rho2 * hsum[i] + acc;
}
"""


def available() -> bool:
    """Whether CuPy imports and sees at least one CUDA device."""
    try:
        import cupy

        return cupy.cuda.runtime.getDeviceCount() > 0
    except Exception:  # no CuPy, no driver, no device: all mean "not usable"
        return False


def belief_propagation_gpu(
    mrf: MRF,
    schedule: str = "colour",
    iterations: int = 100,
    tol: float = 1e-4,
    damping: float = 0.0,
    seed: int = 0,
    progress: Callable[[int, float], None] | None = None,
    initial: np.ndarray | None = None,
) -> BPResult:
    """Loopy BP on the GPU; the messages of the CPU backend's schedule.

    Float32 messages, float64 products over incoming messages. Arguments as in
    :func:`intrinsym.mrf.bp.belief_propagation` (validated there); ``schedule`` is one of
    :data:`~intrinsym.mrf.bp.schedule.GPU_SCHEDULES`.

    Returns
    -------
    BPResult
        Marginals as a float32 NumPy array.
    """
    import cupy as cp

    if schedule not in GPU_SCHEDULES:
        raise ValueError(f"the GPU backend runs the schedules {GPU_SCHEDULES}, not {schedule!r}")
    schedule = resolve_schedule(schedule, "gpu")
    started = time.perf_counter()
    n_s, n_t = mrf.unary.shape
    edges = np.asarray(mrf.edges, dtype=np.int64)
    n_dir = 2 * len(edges)
    ptr, directed = incoming_edges(edges, n_s)
    deg = np.diff(ptr)
    # incoming edges of every node padded to the largest degree with row n_dir (all ones)
    inc = np.full((n_s, max(1, int(deg.max(initial=0)))), n_dir, dtype=np.int64)
    for s in range(n_s):
        inc[s, : deg[s]] = directed[ptr[s] : ptr[s + 1]]
    lo, hi = ring_bounds(mrf.targets.indptr, mrf.targets.dist, mrf.edge_length, mrf.delta)
    kernel = cp.RawKernel(_RING_MESSAGE, "ring_message")
    rings = (
        cp.asarray(lo, dtype=cp.int32),
        cp.asarray(hi, dtype=cp.int32),
        cp.asarray(mrf.targets.indices, dtype=cp.int32),
        cp.asarray(mrf.targets.dist, dtype=cp.float32),
        cp.asarray(mrf.edge_length, dtype=cp.float32),
    )
    unary = cp.asarray(mrf.unary, dtype=cp.float64)
    inc_gpu = cp.asarray(inc)
    messages = cp.ones((n_dir + 1, n_t), dtype=cp.float32)  # last row: the padding
    messages[:n_dir] = cp.asarray(initial_messages(initial, len(edges), n_t, np.float32))
    threads = 256

    def batches(steps: Steps) -> list[tuple]:
        """(sending nodes, owner of every message, directed edges) of every batch."""
        out = []
        for k0, k1 in zip(steps.batch[:-1], steps.batch[1:], strict=True):
            e0, e1 = steps.ptr[k0], steps.ptr[k1]
            if e1 > e0:
                owner = np.repeat(np.arange(k1 - k0), np.diff(steps.ptr[k0 : k1 + 1]))
                out.append((cp.asarray(steps.node[k0:k1]), cp.asarray(owner), cp.asarray(steps.out[e0:e1])))
        return out

    def send(nodes: cp.ndarray, owner: cp.ndarray, outs: cp.ndarray) -> float:
        # a batch's messages are all computed from the messages as they were before it
        products = unary[nodes] * cp.prod(messages[inc_gpu[nodes]].astype(cp.float64), axis=1)
        h = (products[owner] / messages[outs ^ 1]).astype(cp.float32)
        raw = cp.empty_like(h)
        blocks = (h.size + threads - 1) // threads
        kernel(
            (blocks,),
            (threads,),
            (
                h,
                h.sum(axis=1),
                outs,
                *rings,
                np.int64(len(outs)),
                np.int32(n_t),
                np.float32(mrf.lam),
                np.float32(mrf.rho**2),
                raw,
            ),
        )
        old = messages[outs]
        new = (1.0 - damping) * (raw / raw.max(axis=1, keepdims=True)) + damping * old
        change = float(cp.abs(new - old).max())
        messages[outs] = new
        return change

    orders = visiting_orders(schedule, edges, n_s, iterations, seed)
    # only the serial schedule changes its order between iterations
    fixed = None if schedule == "serial" else batches(schedule_steps(schedule, orders[0], edges, ptr, directed))

    def update(it: int) -> float:
        steps = fixed if fixed is not None else batches(schedule_steps(schedule, orders[it], edges, ptr, directed))
        return max((send(*batch) for batch in steps), default=0.0)

    setup = time.perf_counter() - started
    history, seconds, converged = iterate(update, iterations, tol, progress)
    b = unary * cp.prod(messages[inc_gpu].astype(cp.float64), axis=1)
    marg = cp.asnumpy((b / b.sum(axis=1, keepdims=True)).astype(cp.float32))
    return BPResult(
        marg, len(history), converged, history[-1], history, seconds, setup, [n_dir] * len(history), "gpu", schedule
    )
