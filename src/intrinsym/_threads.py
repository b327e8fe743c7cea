"""Row-parallel Numba kernels on Python threads.

A kernel over independent rows that runs a few times per ``detect`` is compiled as a
serial ``nogil`` function of a row range ``[lo, hi)`` and run here on a thread pool,
instead of as a ``prange`` loop: Numba's parallel transform costs 1-4 s of compilation
per kernel on the first run after install (about 12 s over the descriptor, descent and
BP kernels), and the threads reach the same speed. On two cores a ``prange`` also costs
at run time: its OpenMP workers spin after each loop and take the cores from the BLAS
threads of the NumPy products around it. A kernel called thousands of times on short
blocks runs serially below a size where the threads pay for their start
(:data:`intrinsym.spectral.neighbours.PARALLEL_QUERIES`).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from concurrent.futures import Executor, ThreadPoolExecutor
from contextlib import nullcontext
from typing import Any, ParamSpec, TypeVar

import numba as nb
import numpy as np
from threadpoolctl import threadpool_limits

__all__ = ["map_ranges", "n_workers", "one_blas_thread", "split", "worker_pool"]

R = TypeVar("R")
P = ParamSpec("P")

#: Pieces per worker thread: rows of uneven cost (a spin image's support, a descent's
#: steps) balance over several pieces each.
PIECES_PER_WORKER = 8


def n_workers() -> int:
    """Threads to use: Numba's thread count (``NUMBA_NUM_THREADS``), at most the cores."""
    return max(1, min(nb.get_num_threads(), os.cpu_count() or 1))


def one_blas_thread(fn: Callable[P, R]) -> Callable[P, R]:
    """``fn`` with the BLAS library (OpenBLAS, MKL) on one thread while it runs.

    OpenBLAS splits a product's or a Lanczos step's sums by its thread count, so their
    last bits, and the maps built on them, would change with a machine's cores: a
    SHREC'16 shape's eigenpairs by 1e-12 with two threads against one, and its match
    (holes_cat_shape_10) from 0.934 to 0.918 of the vertices within 0.10. On one thread
    the results are those of the benchmarks, which run so. The whole ``match`` of three
    SHREC'16 pairs took as long either way (26.5 / 38.7 / 39.1 s against 26.5 / 40.0 /
    39.3 s on two threads).
    """

    @functools.wraps(fn)
    def on_one_thread(*args: P.args, **kwargs: P.kwargs) -> R:
        with threadpool_limits(1, user_api="blas"):
            return fn(*args, **kwargs)

    return on_one_thread


def split(n: int, n_parts: int) -> list[tuple[int, int]]:
    """Contiguous [lo, hi) ranges covering range(n) in about n_parts pieces."""
    bounds = np.linspace(0, n, max(1, min(n, n_parts)) + 1).astype(np.int64)
    return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def worker_pool() -> ThreadPoolExecutor:
    """A pool of :func:`n_workers` threads shared by several :func:`map_ranges` calls in a
    row (BP's sweep makes three per batch), so that they start their threads once."""
    return ThreadPoolExecutor(n_workers())


def map_ranges(
    fn: Callable[..., R],
    n: int,
    *args: Any,
    pieces_per_worker: int = PIECES_PER_WORKER,
    pool: Executor | None = None,
) -> list[R]:
    """``fn(lo, hi, *args)`` on pieces ``[lo, hi)`` covering ``range(n)``, over
    :func:`n_workers` threads.

    ``fn`` must release the GIL (a ``nogil`` Numba kernel) for the threads to run at
    once. Results come back in the order of the pieces; on one worker, or one piece,
    everything runs on the calling thread. ``pieces_per_worker`` 1 gives each thread one
    contiguous piece, for rows of even cost. ``pool``: the threads to use
    (:func:`worker_pool`; default: started for this call).
    """
    workers = n_workers()
    ranges = split(n, pieces_per_worker * workers)
    if workers == 1 or len(ranges) <= 1:
        return [fn(lo, hi, *args) for lo, hi in ranges]
    with worker_pool() if pool is None else nullcontext(pool) as threads:
        return list(threads.map(lambda r: fn(r[0], r[1], *args), ranges))
