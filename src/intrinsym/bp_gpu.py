"""GPU backend of :mod:`intrinsym.bp` (CuPy): flooding BP with the exact sparse ring message.

Imported only when the GPU backend is asked for; CuPy is an optional dependency
(``pip install intrinsym[gpu]``). One CUDA thread computes one entry m_{s->q}(fq) of one
message, pulling over the ring slice of row fq (rows are symmetric, the slices are the
ones :func:`intrinsym.bp.ring_bounds` gives the CPU kernel), so a whole flooding
iteration is one kernel launch over all directed edges and labels.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .bp import BPResult, incoming_edges, iterate, ring_bounds
from .model import MRF

_RING_MESSAGE = r"""
extern "C" __global__ void ring_message(
    const float* h, const float* hsum, const int* lo, const int* hi,
    const int* indices, const float* dist, const float* edge_length,
    const long long n_dir, const int n_t, const float lam, const float rho2, float* out)
{
    long long k = (long long)blockDim.x * blockIdx.x + threadIdx.x;
    if (k >= n_dir * n_t) return;
    long long d = k / n_t;
    int fq = (int)(k - d * n_t);
    long long e = d >> 1;
    float len = edge_length[e];
    const float* hd = h + d * n_t;
    float acc = 0.0f;
    for (int j = lo[e * n_t + fq]; j < hi[e * n_t + fq]; ++j) {
        float x = dist[j] - len;
        acc += fmaxf(expf(-lam * x * x) - rho2, 0.0f) * hd[indices[j]];
    }
    out[k] = rho2 * hsum[d] + acc;
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
    iterations: int = 100,
    tol: float = 1e-4,
    damping: float = 0.0,
    progress: Callable[[int, float], None] | None = None,
) -> BPResult:
    """Flooding loopy BP on the GPU; same messages as the CPU flooding schedule.

    Float32 messages, float64 products over incoming messages. Arguments as in
    :func:`intrinsym.bp.belief_propagation` (validated there).

    Returns
    -------
    BPResult
        Marginals as a float32 NumPy array.
    """
    import cupy as cp

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
    out_edges = np.arange(n_dir)
    sender = cp.asarray(edges[out_edges >> 1, out_edges & 1])
    back = cp.asarray(out_edges ^ 1)
    lo, hi = ring_bounds(mrf.targets.indptr, mrf.targets.dist, mrf.edge_length, mrf.delta)
    kernel = cp.RawKernel(_RING_MESSAGE, "ring_message")
    args_fixed = (
        cp.asarray(lo, dtype=cp.int32), cp.asarray(hi, dtype=cp.int32),
        cp.asarray(mrf.targets.indices, dtype=cp.int32), cp.asarray(mrf.targets.dist, dtype=cp.float32),
        cp.asarray(mrf.edge_length, dtype=cp.float32),
    )
    unary = cp.asarray(mrf.unary, dtype=cp.float64)
    inc_gpu = cp.asarray(inc)
    messages = cp.ones((n_dir + 1, n_t), dtype=cp.float32)  # last row: the padding
    raw = cp.empty((n_dir, n_t), dtype=cp.float32)
    threads = 256
    blocks = (n_dir * n_t + threads - 1) // threads

    def node_products() -> cp.ndarray:
        return unary * cp.prod(messages[inc_gpu].astype(cp.float64), axis=1)

    def update(it: int) -> float:
        h = (node_products()[sender] / messages[back]).astype(cp.float32)
        hsum = h.sum(axis=1)
        kernel(
            (blocks,), (threads,),
            (h, hsum, *args_fixed, np.int64(n_dir), np.int32(n_t),
             np.float32(mrf.lam), np.float32(mrf.rho**2), raw),
        )
        new = (1.0 - damping) * (raw / raw.max(axis=1, keepdims=True)) + damping * messages[:n_dir]
        change = float(cp.abs(new - messages[:n_dir]).max())
        messages[:n_dir] = new
        return change

    setup = time.perf_counter() - started
    history, seconds, converged = iterate(update, iterations, tol, progress)
    b = node_products()
    marg = cp.asnumpy((b / b.sum(axis=1, keepdims=True)).astype(cp.float32))
    return BPResult(marg, len(history), converged, history[-1], history, seconds, setup, [n_dir] * len(history))
