"""What the BP implementations share: the result, argument checks and the iteration loop.

Messages are max-normalised (they then lie in [rho^2, 1], so products of a dozen stay
far from float32 underflow). :func:`run_schedule` drives a message kernel (a *sweep*)
through the iterations of a schedule; the CPU backend and the dense oracle plug their
kernels into it, the GPU backend has its own loop around :func:`iterate`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .schedule import SCHEDULES, Steps, active_steps, incoming_edges, resolve_schedule, schedule_steps, visiting_orders

#: ``sweep(read, write, steps, moved)``: updates the messages of ``steps`` read from
#: ``read`` (2E, T) into ``write``, stores the largest change of every message sent in
#: ``moved`` (2E,) and returns the largest of all.
Sweep = Callable[[np.ndarray, np.ndarray, Steps, np.ndarray], float]


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
    setup_seconds : float
        Wall time spent before the first iteration (ring bounds, tables, buffers).
    updates : list of int
        Messages computed in every iteration (2E, except in the residual schedule).
    backend : {"cpu", "gpu"}
        Where BP ran.
    schedule : str
        The schedule that ran ("auto" resolved by
        :func:`~intrinsym.mrf.bp.schedule.resolve_schedule`).
    """

    marginals: np.ndarray
    iterations: int
    converged: bool
    max_change: float
    history: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    setup_seconds: float = 0.0
    updates: list[int] = field(default_factory=list)
    backend: str = "cpu"
    schedule: str = "colour"


def check_arguments(unary: np.ndarray, schedule: str, iterations: int, damping: float) -> None:
    """Raise ValueError unless the schedule, iteration count, damping and unary are valid."""
    if schedule not in SCHEDULES:
        raise ValueError(f"unknown schedule {schedule!r}; expected one of {SCHEDULES}")
    if iterations < 1:
        raise ValueError(f"iterations must be at least 1, got {iterations}")
    if not 0.0 <= damping < 1.0:
        raise ValueError(f"damping must lie in [0, 1), got {damping}")
    if np.any(~np.isfinite(unary)) or np.any(unary <= 0):
        raise ValueError("unary potentials must be finite and positive")


def initial_messages(initial: np.ndarray | None, n_edges: int, n_t: int, dtype: type) -> np.ndarray:
    """(2E, T) messages BP starts from, in ``dtype``: a copy of ``initial``, or all ones."""
    if initial is None:
        return np.ones((2 * n_edges, n_t), dtype=dtype)
    initial = np.asarray(initial)
    if initial.shape != (2 * n_edges, n_t):
        raise ValueError(f"initial messages must have shape {(2 * n_edges, n_t)}, got {initial.shape}")
    if np.any(~np.isfinite(initial)) or np.any(initial <= 0):
        raise ValueError("initial messages must be finite and positive")
    return initial.astype(dtype)


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


def iterate(
    update: Callable[[int], float],
    iterations: int,
    tol: float,
    progress: Callable[[int, float], None] | None,
) -> tuple[list[float], list[float], bool]:
    """Call ``update(iteration)`` (returns the largest message change) until convergence.

    Returns
    -------
    history : list of float
        The change after every iteration.
    seconds : list of float
        Wall time of every iteration.
    converged : bool
        Whether the change fell below ``tol``.
    """
    history: list[float] = []
    seconds: list[float] = []
    for it in range(iterations):
        t0 = time.perf_counter()
        change = float(update(it))
        seconds.append(time.perf_counter() - t0)
        history.append(change)
        if progress is not None:
            progress(it + 1, change)
        if change < tol:
            return history, seconds, True
    return history, seconds, False


def run_schedule(
    unary: np.ndarray,
    edges: np.ndarray,
    schedule: str,
    iterations: int,
    tol: float,
    seed: int,
    dtype: type,
    sweep: Sweep,
    progress: Callable[[int, float], None] | None,
    started: float,
    initial: np.ndarray | None = None,
) -> BPResult:
    """Iterate ``sweep(read, write, steps, moved)`` to convergence.

    The residual schedule runs the colour classes batch by batch and lets a node send
    only while the messages it received since it last sent have changed by more than
    ``tol`` in total (the sum over batches of the largest change of any of them); a node
    whose inputs are settled would resend what it sent. The first iteration sends all.

    Parameters
    ----------
    unary : (S, T) array
    edges : (E, 2) int
    schedule, iterations, tol, seed, progress, initial
        As in :func:`intrinsym.mrf.bp.belief_propagation`.
    dtype : numpy float type
        Storage of the messages and of the returned marginals.
    sweep : Sweep
        The message kernel.
    started : float
        ``time.perf_counter()`` when the caller started; the time until the first
        iteration is the result's ``setup_seconds``.

    Returns
    -------
    BPResult
    """
    schedule = resolve_schedule(schedule, "cpu")
    n_s, n_t = unary.shape
    ptr, directed = incoming_edges(edges, n_s)
    messages = initial_messages(initial, len(edges), n_t, dtype)
    moved = np.zeros(2 * len(edges))
    ends = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    receiver = ends[np.arange(2 * len(ends)) >> 1, 1 - (np.arange(2 * len(ends)) & 1)]  # s of d = q -> s
    residual = np.full(n_s, np.inf)
    updates: list[int] = []
    orders = visiting_orders(schedule, edges, n_s, iterations, seed)
    # only the serial schedule changes its order between iterations
    fixed = None if schedule == "serial" else schedule_steps(schedule, orders[0], edges, ptr, directed)

    def update(it: int) -> float:
        nonlocal messages
        steps = fixed if fixed is not None else schedule_steps(schedule, orders[it], edges, ptr, directed)
        if schedule == "flooding":
            new = messages.copy()
            change = sweep(messages, new, steps, moved)
            messages = new
        elif schedule != "residual":
            change = sweep(messages, messages, steps, moved)
        else:
            change, sent = 0.0, 0
            for b in range(len(steps.batch) - 1):
                part = active_steps(steps, b, residual > tol)
                if len(part.node) == 0:
                    continue
                change = max(change, sweep(messages, messages, part, moved))
                residual[part.node] = 0.0
                got = np.zeros(n_s)
                np.maximum.at(got, receiver[part.out], moved[part.out])
                residual[:] += got
                sent += len(part.out)
            updates.append(sent)
            return change
        updates.append(len(steps.out))
        return change

    setup = time.perf_counter() - started
    history, seconds, converged = iterate(update, iterations, tol, progress)
    marg: np.ndarray = beliefs(unary, messages, ptr, directed).astype(dtype)
    return BPResult(marg, len(history), converged, history[-1], history, seconds, setup, updates, "cpu", schedule)
