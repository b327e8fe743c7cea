"""The test oracle: paper-literal BP with the O(|Pt|^2) message of Eq. 7, in NumPy."""

from __future__ import annotations

import time

import numpy as np

from ..model import pairwise_dense
from .common import BPResult, check_arguments, run_schedule
from .schedule import Steps, incoming_edges


def belief_propagation_dense(
    unary: np.ndarray,
    edges: np.ndarray,
    edge_length: np.ndarray,
    target_dist: np.ndarray,
    lam: float,
    rho: float,
    schedule: str = "colour",
    iterations: int = 100,
    tol: float = 1e-4,
    damping: float = 0.0,
    seed: int = 0,
    initial: np.ndarray | None = None,
) -> BPResult:
    """Paper-literal BP (Eq. 7 with the full |Pt| x |Pt| pairwise table); the oracle.

    Same schedule (:func:`~intrinsym.mrf.bp.schedule.schedule_steps`), normalisation and
    stopping rule as :func:`intrinsym.mrf.bp.belief_propagation`, but the product over
    incoming messages excludes the recipient explicitly and the message is a dense
    matrix-vector product. Float64 throughout. Use on small problems only.

    Parameters
    ----------
    unary : (S, T) array
    edges : (E, 2) int
    edge_length : (E,) float
    target_dist : (T, T) float
        All target-target geodesic distances.
    lam, rho : float
        Pairwise term of Eq. 6.
    schedule, iterations, tol, damping, seed, initial
        As in :func:`intrinsym.mrf.bp.belief_propagation`.

    Returns
    -------
    BPResult
    """
    started = time.perf_counter()
    check_arguments(unary, schedule, iterations, damping)
    unary = np.asarray(unary, dtype=np.float64)
    n_s = unary.shape[0]
    ptr, directed = incoming_edges(edges, n_s)

    def sweep(read: np.ndarray, write: np.ndarray, steps: Steps, moved: np.ndarray) -> float:
        change = 0.0
        for k, s in enumerate(steps.node):
            incoming = directed[ptr[s] : ptr[s + 1]]
            for out in steps.out[steps.ptr[k] : steps.ptr[k + 1]]:
                h = unary[s].copy()
                for other in incoming:
                    if other != out ^ 1:
                        h *= read[other]
                psi = pairwise_dense(float(edge_length[out >> 1]), target_dist, lam, rho)
                msg = psi.T @ h
                new = (1.0 - damping) * msg / msg.max() + damping * write[out]
                moved[out] = np.abs(new - write[out]).max()
                change = max(change, moved[out])
                write[out] = new
        return change

    return run_schedule(unary, edges, schedule, iterations, tol, seed, np.float64, sweep, None, started, initial)
