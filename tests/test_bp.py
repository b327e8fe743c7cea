"""Belief propagation: the sparse ring message against the dense paper-literal oracle,
and BP on a tree against brute-force enumeration."""

from __future__ import annotations

import inspect
import itertools
import typing

import numpy as np
import pytest

from intrinsym import params
from intrinsym.geodesics.geodesics import SparseDistances
from intrinsym.mrf.bp import (
    BACKENDS,
    SCHEDULES,
    belief_propagation,
    belief_propagation_dense,
    resolve_backend,
    resolve_schedule,
)
from intrinsym.mrf.bp.cpu import weight_polynomial
from intrinsym.mrf.bp.gpu import available as gpu_available
from intrinsym.mrf.bp.schedule import (
    active_steps,
    colour_classes,
    incoming_edges,
    schedule_steps,
    serial_orders,
    visiting_orders,
)
from intrinsym.mrf.model import MRF, lambda_for_tolerance, pairwise_dense


def sparse_from_dense(dist: np.ndarray, radius: float) -> SparseDistances:
    """Row-sorted sparse form of a dense distance matrix, entries <= radius."""
    indptr = [0]
    indices, values = [], []
    for row in dist:
        keep = np.flatnonzero(row <= radius)
        keep = keep[np.argsort(row[keep], kind="stable")]
        indices.append(keep)
        values.append(row[keep])
        indptr.append(indptr[-1] + len(keep))
    return SparseDistances(
        np.asarray(indptr, dtype=np.int64),
        np.concatenate(indices).astype(np.int64),
        np.concatenate(values).astype(np.float64),
        float(radius),
    )


def sphere_problem(n_source: int, n_target: int, k: int, seed: int, tolerance: float = 1.5):
    """Sources and targets on the unit sphere with exact great-circle distances."""
    rng = np.random.default_rng(seed)

    def points(n):
        x = rng.normal(size=(n, 3))
        return x / np.linalg.norm(x, axis=1, keepdims=True)

    src, tgt = points(n_source), points(n_target)
    d_ss = np.arccos(np.clip(src @ src.T, -1, 1))
    d_tt = np.arccos(np.clip(tgt @ tgt.T, -1, 1))
    nearest = np.argsort(d_ss, axis=1)[:, 1 : k + 1]
    edges = np.unique(np.sort(np.column_stack([np.repeat(np.arange(n_source), k), nearest.ravel()]), axis=1), axis=0)
    length = d_ss[edges[:, 0], edges[:, 1]]
    spacing = np.sqrt(4 * np.pi / n_target)
    rho = 0.4
    delta = tolerance * spacing
    lam = lambda_for_tolerance(delta, rho)
    unary = rng.uniform(0.01, 1.0, size=(n_source, n_target))
    targets = sparse_from_dense(d_tt, length.max() + delta)
    return MRF(unary, edges, length, targets, lam, rho), d_tt


@pytest.mark.parametrize("schedule", ["serial", "colour", "flooding"])
@pytest.mark.parametrize(
    "n_source,n_target,k,iters",
    # few sources far apart: rings of most targets. The dense oracle's messages cost n_target^2
    # each: 800 targets by default, 2000 in CI (-m slow)
    [(40, 300, 4, 6), (12, 800, 3, 2), pytest.param(12, 2000, 3, 2, marks=pytest.mark.slow)],
)
def test_sparse_equals_dense_oracle(schedule, n_source, n_target, k, iters):
    mrf, d_tt = sphere_problem(n_source, n_target, k, seed=n_target)
    kw = dict(schedule=schedule, iterations=iters, tol=0.0, seed=3)
    sparse = belief_propagation(mrf, dtype=np.float64, backend="cpu", **kw)
    dense = belief_propagation_dense(mrf.unary, mrf.edges, mrf.edge_length, d_tt, mrf.lam, mrf.rho, **kw)
    assert sparse.iterations == dense.iterations == iters
    assert np.abs(sparse.marginals - dense.marginals).max() < 1e-6
    assert np.allclose(sparse.history, dense.history, atol=1e-6)
    # and the marginals are informative, not uniform
    assert np.abs(sparse.marginals - 1.0 / n_target).max() > 1e-4


@pytest.mark.parametrize("schedule", ["colour", "flooding"])
def test_initial_messages_match_oracle(schedule):
    mrf, d_tt = sphere_problem(40, 300, 4, seed=301)
    start = np.random.default_rng(0).uniform(0.2, 1.0, size=(2 * len(mrf.edges), 300))
    kw = dict(schedule=schedule, iterations=2, tol=0.0, seed=3)
    sparse = belief_propagation(mrf, dtype=np.float64, initial=start, backend="cpu", **kw)
    dense = belief_propagation_dense(mrf.unary, mrf.edges, mrf.edge_length, d_tt, mrf.lam, mrf.rho, initial=start, **kw)
    assert np.abs(sparse.marginals - dense.marginals).max() < 1e-6
    # the start matters: from all ones BP is elsewhere after two iterations
    ones = belief_propagation(mrf, dtype=np.float64, backend="cpu", **kw)
    assert np.abs(sparse.marginals - ones.marginals).max() > 1e-3
    with pytest.raises(ValueError, match="shape"):
        belief_propagation(mrf, initial=start[1:], backend="cpu", **kw)
    with pytest.raises(ValueError, match="positive"):
        belief_propagation(mrf, initial=np.zeros_like(start), backend="cpu", **kw)


def test_residual_schedule_matches_oracle_and_saves_updates():
    # 200 targets: the dense oracle's residual run takes 1.5 s (3.7 s at 300); measured here:
    # converged after 22 sweeps, 69 messages in the fewest, 0.93 of the colour schedule's in all
    mrf, d_tt = sphere_problem(40, 200, 4, seed=300)
    kw = dict(iterations=60, tol=1e-6, seed=3)
    sparse = belief_propagation(mrf, schedule="residual", dtype=np.float64, backend="cpu", **kw)
    dense = belief_propagation_dense(
        mrf.unary, mrf.edges, mrf.edge_length, d_tt, mrf.lam, mrf.rho, schedule="residual", **kw
    )
    colour = belief_propagation(mrf, schedule="colour", dtype=np.float64, backend="cpu", **kw)
    assert sparse.converged and colour.converged
    # the oracle skips exactly the same nodes
    assert sparse.updates == dense.updates
    assert np.abs(sparse.marginals - dense.marginals).max() < 1e-6
    # every message in the first iteration, fewer later, fewer in all than colour
    assert sparse.updates[0] == colour.updates[0] == 2 * len(mrf.edges)
    assert min(sparse.updates) < 2 * len(mrf.edges)
    assert sum(sparse.updates) < sum(colour.updates)
    # the same fixed point, up to the tolerance
    assert np.abs(sparse.marginals - colour.marginals).max() < 1e-4 * sparse.marginals.max()


def test_auto_schedule_is_residual_on_the_cpu_and_colour_on_the_gpu():
    assert resolve_schedule("auto", "cpu") == "residual"
    assert resolve_schedule("auto", "gpu") == "colour"
    for schedule in SCHEDULES[1:]:
        assert resolve_schedule(schedule, "cpu") == resolve_schedule(schedule, "gpu") == schedule
    mrf, _ = sphere_problem(40, 300, 4, seed=300)
    kw = dict(iterations=60, tol=1e-3, seed=3, backend="cpu")
    auto = belief_propagation(mrf, **kw)
    residual = belief_propagation(mrf, schedule="residual", **kw)
    colour = belief_propagation(mrf, schedule="colour", **kw)
    assert auto.schedule == residual.schedule == "residual" and colour.schedule == "colour"
    assert auto.updates == residual.updates and np.array_equal(auto.marginals, residual.marginals)
    assert sum(auto.updates) < sum(colour.updates)


def test_active_steps_keeps_the_sends_of_active_nodes():
    """The 6-cycle with chord 0-2 (colours 0 2 1 0 1 2): batch 0 is nodes 0 and 3."""
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 0], [0, 2]])
    ptr, directed = incoming_edges(edges, 6)
    steps = schedule_steps("colour", visiting_orders("colour", edges, 6, 1, 0)[0], edges, ptr, directed)
    assert steps.node[: steps.batch[1]].tolist() == [0, 3]
    active = np.array([False, True, True, True, True, True])
    part = active_steps(steps, 0, active)
    assert part.node.tolist() == [3]
    # 3 -> 2 is edge 2 reversed (5), 3 -> 4 is edge 3 (6)
    assert sorted(part.out.tolist()) == [5, 6]
    assert part.ptr.tolist() == [0, 2] and part.batch.tolist() == [0, 1]
    assert len(active_steps(steps, 0, np.zeros(6, dtype=bool)).out) == 0


def test_damped_flooding_matches_oracle():
    mrf, d_tt = sphere_problem(20, 400, 3, seed=1)
    kw = dict(schedule="flooding", iterations=4, tol=0.0, damping=0.5, seed=0)
    sparse = belief_propagation(mrf, dtype=np.float64, backend="cpu", **kw)
    dense = belief_propagation_dense(mrf.unary, mrf.edges, mrf.edge_length, d_tt, mrf.lam, mrf.rho, **kw)
    assert np.abs(sparse.marginals - dense.marginals).max() < 1e-6


def test_float32_close_to_float64():
    mrf, _ = sphere_problem(30, 500, 4, seed=2)
    kw = dict(schedule="serial", iterations=5, tol=0.0, backend="cpu")
    a = belief_propagation(mrf, dtype=np.float64, **kw)
    b = belief_propagation(mrf, dtype=np.float32, **kw)
    assert b.marginals.dtype == np.float32
    assert np.abs(a.marginals - b.marginals).max() < 1e-5
    assert np.allclose(b.marginals.sum(axis=1), 1.0, atol=1e-5)


def test_too_short_target_radius_is_refused():
    mrf, d_tt = sphere_problem(10, 100, 3, seed=4)
    short = sparse_from_dense(d_tt, mrf.edge_length.max())
    bad = MRF(mrf.unary, mrf.edges, mrf.edge_length, short, mrf.lam, mrf.rho)
    with pytest.raises(ValueError, match="exact message needs"):
        belief_propagation(bad, schedule="serial", backend="cpu")


def test_tree_marginals_equal_brute_force():
    """On a tree, converged sum-product BP gives the exact marginals."""
    rng = np.random.default_rng(7)
    n_label = 5
    pos = rng.uniform(0, 1, size=(n_label, 2))
    d_tt = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    edges = np.array([[0, 1], [1, 2], [1, 3], [3, 4]])  # a tree on 5 nodes
    length = np.array([0.3, 0.5, 0.2, 0.4])
    rho, lam = 0.4, 8.0  # sphere_problem's rho: the float64 kernels compiled once for both
    unary = rng.uniform(0.05, 1.0, size=(5, n_label))
    targets = sparse_from_dense(d_tt, np.inf)
    mrf = MRF(unary, edges, length, targets, lam, rho)

    joint = np.zeros((n_label,) * 5)
    for labels in itertools.product(range(n_label), repeat=5):
        p = np.prod([unary[s, labels[s]] for s in range(5)])
        for (i, j), d in zip(edges, length, strict=True):
            p *= max(np.exp(-lam * (d - d_tt[labels[i], labels[j]]) ** 2), rho**2)
        joint[labels] = p
    joint /= joint.sum()
    exact = np.array([joint.sum(axis=tuple(a for a in range(5) if a != s)) for s in range(5)])

    for schedule in ("serial", "colour", "residual", "flooding"):
        res = belief_propagation(mrf, schedule=schedule, iterations=50, tol=1e-12, dtype=np.float64, backend="cpu")
        assert res.converged
        assert np.abs(res.marginals - exact).max() < 1e-9


def test_pairwise_dense_truncates():
    d = np.array([[0.0, 1.0], [1.0, 0.0]])
    psi = pairwise_dense(1.0, d, lam=100.0, rho=0.5)
    assert psi[0, 1] == 1.0
    assert psi[0, 0] == 0.25


def test_schedule_orders():
    orders = serial_orders(6, 3, seed=1)
    assert np.array_equal(orders[0], np.arange(6))
    for o in orders[1:]:
        assert sorted(o) == list(range(6))
    again = serial_orders(6, 3, seed=1)
    assert all(np.array_equal(a, b) for a, b in zip(orders, again, strict=True))


def test_serial_steps_update_every_directed_edge_once():
    """Path 0-1-2 plus edge 0-2, order (1, 0, 2): hand-checked forward/backward sends."""
    edges = np.array([[0, 1], [1, 2], [0, 2]])
    ptr, directed = incoming_edges(edges, 3)
    steps = schedule_steps("serial", np.array([1, 0, 2]), edges, ptr, directed)
    assert steps.node.tolist() == [1, 0, 2, 2, 0, 1]
    sent = [sorted(steps.out[steps.ptr[k] : steps.ptr[k + 1]].tolist()) for k in range(6)]
    # forward: 1 -> 0 (edge 0 reversed: 1), 1 -> 2 (2); 0 -> 2 (4); 2 sends nothing
    # backward: 2 -> 0 (5), 2 -> 1 (3); 0 -> 1 (0); 1 sends nothing
    assert sent == [[1, 2], [4], [], [3, 5], [0], []]
    assert sorted(steps.out.tolist()) == list(range(6))
    # a new batch wherever the step's node was just sent to: 0 (by 1), 2 (by 0), 0, 1
    assert steps.batch.tolist() == [0, 1, 2, 4, 5, 6]
    flood = schedule_steps("flooding", np.arange(3), edges, ptr, directed)
    assert flood.node.tolist() == [0, 1, 2]
    assert sorted(flood.out.tolist()) == list(range(6))
    assert flood.batch.tolist() == [0, 3]


def test_colour_schedule_batches_whole_classes():
    """A 6-cycle with the chord 0-2: a proper colouring, each class one batch, every
    directed edge sent once per iteration."""
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 0], [0, 2]])
    colour = colour_classes(edges, 6)
    assert np.all(colour[edges[:, 0]] != colour[edges[:, 1]])
    # largest degree first (0, 2), then index order: hand-checked greedy colours
    assert colour.tolist() == [0, 2, 1, 0, 1, 2]
    ptr, directed = incoming_edges(edges, 6)
    orders = visiting_orders("colour", edges, 6, 4, seed=2)
    for order in orders:
        steps = schedule_steps("colour", order, edges, ptr, directed)
        assert sorted(steps.out.tolist()) == list(range(14))
        for b in range(len(steps.batch) - 1):
            nodes = steps.node[steps.batch[b] : steps.batch[b + 1]]
            assert len(set(colour[nodes].tolist())) == 1
            assert len(nodes) == np.sum(colour == colour[nodes[0]])
    assert all(np.array_equal(o, orders[0]) for o in orders)
    assert np.all(np.diff(colour[orders[0]]) >= 0)


def test_incoming_edges():
    ptr, directed = incoming_edges(np.array([[0, 1], [1, 2]]), 3)
    assert ptr.tolist() == [0, 1, 3, 4]
    # into 0: 1->0 (directed 1); into 1: 0->1 (0), 2->1 (3); into 2: 1->2 (2)
    assert directed.tolist() == [1, 0, 3, 2]


def test_bad_arguments():
    mrf, _ = sphere_problem(5, 50, 2, seed=5)
    with pytest.raises(ValueError, match="schedule"):
        belief_propagation(mrf, schedule="random", backend="cpu")
    with pytest.raises(ValueError, match="damping"):
        belief_propagation(mrf, schedule="serial", damping=1.0, backend="cpu")


def test_defaults_equal_params_defaults():
    """Called without a schedule or backend, BP runs as the pipeline does by default."""
    defaults = inspect.signature(belief_propagation).parameters
    p = params.Params()
    assert defaults["schedule"].default == p.schedule == "auto"
    assert defaults["backend"].default == p.backend == "auto"
    assert defaults["iterations"].default == p.iterations
    assert set(typing.get_args(params.Schedule)) == set(SCHEDULES)
    assert set(typing.get_args(params.Backend)) == set(BACKENDS)


@pytest.mark.parametrize("rho,tol", [(0.6, 1e-13), (0.4, 1e-12), (0.2, 1e-9), (0.1, 1e-8)])
def test_weight_polynomial_matches_exp(rho, tol):
    t = np.linspace(0.0, 1.0, 10001)
    exact = np.exp(-np.log(1 / rho**2) * t) - rho**2
    assert np.abs(np.polynomial.polynomial.polyval(t, weight_polynomial(rho)) - exact).max() < tol
    # float32 storage asks only for its epsilon, with fewer terms
    eps = float(np.finfo(np.float32).eps)
    coarse = weight_polynomial(rho, eps)
    assert np.abs(np.polynomial.polynomial.polyval(t, coarse) - exact).max() <= eps
    assert len(coarse) < len(weight_polynomial(rho))


def test_backend_choice():
    assert resolve_backend("cpu", "serial") == "cpu"
    with pytest.raises(ValueError, match="backend"):
        resolve_backend("tpu", "serial")
    assert resolve_backend("auto", "residual") == "cpu"
    assert resolve_backend("auto", "colour", np.float64) == "cpu"
    assert resolve_backend("auto", "auto", np.float64) == "cpu"
    if gpu_available():
        assert resolve_backend("auto", "colour") == "gpu"
        assert resolve_backend("auto", "serial") == "gpu"
        # the default schedule keeps the default backend on the GPU (as colour)
        assert resolve_backend("auto", "auto") == resolve_backend("gpu", "auto") == "gpu"
        with pytest.raises(ValueError, match="residual"):
            resolve_backend("gpu", "residual")
    else:
        assert resolve_backend("auto", "colour") == resolve_backend("auto", "auto") == "cpu"
        with pytest.raises(ValueError, match="CuPy"):
            resolve_backend("gpu", "flooding")


@pytest.mark.skipif(not gpu_available(), reason="needs CuPy and a CUDA device")
@pytest.mark.parametrize(
    "schedule, damping", [("flooding", 0.0), ("flooding", 0.3), ("colour", 0.0), ("colour", 0.3), ("serial", 0.0)]
)
def test_gpu_equals_cpu(schedule, damping):
    mrf, _ = sphere_problem(40, 2000, 4, seed=8)
    kw = dict(schedule=schedule, iterations=8, tol=0.0, damping=damping, seed=3)
    cpu = belief_propagation(mrf, dtype=np.float64, backend="cpu", **kw)
    gpu = belief_propagation(mrf, backend="gpu", **kw)
    assert gpu.iterations == cpu.iterations
    assert np.abs(gpu.marginals / cpu.marginals - 1.0).max() < 1e-4


@pytest.mark.skipif(not gpu_available(), reason="needs CuPy and a CUDA device")
def test_gpu_equals_cpu_from_initial_messages():
    mrf, _ = sphere_problem(40, 2000, 4, seed=8)
    start = np.random.default_rng(0).uniform(0.2, 1.0, size=(2 * len(mrf.edges), 2000))
    kw = dict(schedule="colour", iterations=3, tol=0.0, initial=start)
    cpu = belief_propagation(mrf, dtype=np.float64, backend="cpu", **kw)
    gpu = belief_propagation(mrf, backend="gpu", **kw)
    assert gpu.backend == "gpu" and cpu.backend == "cpu"
    assert np.abs(gpu.marginals / cpu.marginals - 1.0).max() < 1e-4
