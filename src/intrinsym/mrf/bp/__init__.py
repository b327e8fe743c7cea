"""Sum-product loopy belief propagation on the correspondence MRF (paper Sec. 3.1, 4).

:func:`belief_propagation` runs BP with the exact sparse ring message on the CPU
(:mod:`.cpu`, Numba) or the GPU (:mod:`.gpu`, CuPy); :func:`belief_propagation_dense`
(:mod:`.dense`) is the paper-literal O(|Pt|^2) message in NumPy, the test oracle. All
three share the schedules and the message layout of :mod:`.schedule` and the result,
normalisation and stopping rule of :mod:`.common`, and every iteration updates every
directed edge exactly once (the residual schedule skips the nodes whose inputs have settled).

Modules import one way: ``schedule`` <- ``common`` <- ``cpu``, ``gpu``, ``dense`` <- this
package.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..model import MRF
from .common import BPResult, beliefs, check_arguments, initial_messages, iterate, run_schedule
from .cpu import MAX_WEIGHT_DEGREE, belief_propagation_cpu, sparse_sweep, weight_polynomial
from .dense import belief_propagation_dense
from .gpu import available as gpu_available
from .gpu import belief_propagation_gpu
from .schedule import (
    GPU_SCHEDULES,
    SCHEDULES,
    Steps,
    active_steps,
    colour_classes,
    incoming_edges,
    resolve_schedule,
    ring_bounds,
    schedule_steps,
    serial_orders,
    visiting_orders,
)

BACKENDS = ("auto", "cpu", "gpu")

__all__ = [
    "BACKENDS",
    "BPResult",
    "GPU_SCHEDULES",
    "MAX_WEIGHT_DEGREE",
    "SCHEDULES",
    "Steps",
    "active_steps",
    "belief_propagation",
    "belief_propagation_cpu",
    "belief_propagation_dense",
    "belief_propagation_gpu",
    "beliefs",
    "check_arguments",
    "colour_classes",
    "gpu_available",
    "incoming_edges",
    "initial_messages",
    "iterate",
    "resolve_backend",
    "resolve_schedule",
    "ring_bounds",
    "run_schedule",
    "schedule_steps",
    "serial_orders",
    "sparse_sweep",
    "visiting_orders",
    "weight_polynomial",
]


def resolve_backend(backend: str, schedule: str, dtype: type = np.float32) -> str:
    """The backend that runs: "cpu" or "gpu".

    "auto" picks the GPU when CuPy sees a CUDA device, the schedule is one of
    :data:`GPU_SCHEDULES` and the messages are stored in float32 (the GPU backend's
    precision), else the CPU. "gpu" without a usable GPU or with the residual schedule
    is an error.

    Parameters
    ----------
    backend : {"auto", "cpu", "gpu"}
    schedule : str
        One of :data:`SCHEDULES`.
    dtype : numpy float type
        Storage of the messages.

    Returns
    -------
    {"cpu", "gpu"}
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; expected one of {BACKENDS}")
    if backend == "cpu":
        return "cpu"
    usable = gpu_available()
    if backend == "gpu":
        if not usable:
            raise ValueError("backend 'gpu' needs CuPy and a CUDA device (pip install intrinsym[gpu])")
        if schedule not in GPU_SCHEDULES:
            raise ValueError(f"the GPU backend runs the schedules {', '.join(GPU_SCHEDULES)}, not {schedule!r}")
        return "gpu"
    return "gpu" if usable and schedule in GPU_SCHEDULES and np.dtype(dtype) == np.float32 else "cpu"


def belief_propagation(
    mrf: MRF,
    schedule: str = "auto",
    iterations: int = 100,
    tol: float = 1e-4,
    damping: float = 0.0,
    seed: int = 0,
    dtype: type = np.float32,
    progress: Callable[[int, float], None] | None = None,
    backend: str = "auto",
    initial: np.ndarray | None = None,
) -> BPResult:
    """Loopy sum-product BP with the exact sparse ring message.

    Parameters
    ----------
    mrf : MRF
        The model. ``mrf.targets.radius`` must be at least
        ``mrf.edge_length.max() + mrf.delta``, else the message would not be exact.
    schedule : {"auto", "colour", "serial", "residual", "flooding"}
        "auto": "residual" on the CPU, "colour" on the GPU (:func:`resolve_schedule`).
        "colour": a serial schedule that visits the classes of a graph colouring
        (:func:`colour_classes`) in turn; every node of a class sends to all its
        neighbours at once. "serial": the paper's forward and backward sweeps, index
        order first, then random orders (see :func:`schedule_steps`). "residual": the
        colour schedule, but a node sends only while its incoming messages have changed
        by more than ``tol`` since it last sent (see :func:`run_schedule`); same fixed
        point, fewer message updates. "flooding": every message is recomputed from the
        previous iteration's messages.
    iterations : int
        Maximum number of iterations T (paper: 100).
    tol : float
        Stop when the largest change of a max-normalised message falls below this.
    damping : float in [0, 1)
        New message = (1 - damping) * computed + damping * previous.
    seed : int
        Seed of the random serial orders.
    dtype : numpy float type
        Storage of messages and of the working arrays of a message; products over
        incoming messages are formed in float64.
    progress : callable(iteration, max_change), optional
    backend : {"auto", "cpu", "gpu"}
        See :func:`resolve_backend`. The GPU backend (CuPy, :mod:`intrinsym.mrf.bp.gpu`)
        stores float32 messages.
    initial : (2E, T) array, optional
        Messages to start from (directed edge d = 2e + k sends from ``edges[e, k]``),
        finite and positive; default all ones (paper Sec. 4).

    Returns
    -------
    BPResult
    """
    started = time.perf_counter()
    check_arguments(mrf.unary, schedule, iterations, damping)
    if resolve_backend(backend, schedule, dtype) == "gpu":
        return belief_propagation_gpu(mrf, schedule, iterations, tol, damping, seed, progress, initial)
    return belief_propagation_cpu(mrf, schedule, iterations, tol, damping, seed, dtype, progress, initial, started)
