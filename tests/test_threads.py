"""Row ranges on threads: every row once, and the same result on any thread count; the
pipeline's BLAS on one thread."""

from __future__ import annotations

import os
import threading

import numba as nb
import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import intrinsym
from conftest import sphere_points, unit_sphere
from intrinsym import _threads
from intrinsym.geodesics import geodesics
from intrinsym.globalmap.part_trilateration import best_images
from intrinsym.globalmap.refine import spectral_descent
from intrinsym.mesh import generated as shapes
from intrinsym.mrf.bp import belief_propagation
from intrinsym.pipeline import self_matching, two_shapes
from intrinsym.spectral.laplacian import eigenpairs
from intrinsym.spectral.neighbours import nearest_rows
from intrinsym.unary.descriptors import nmi, quantize, spin_images
from test_bp import sphere_problem


@pytest.mark.parametrize("n,parts", [(0, 4), (1, 4), (7, 3), (100, 16), (5, 50)])
def test_split_covers_the_range_in_order(n, parts):
    ranges = _threads.split(n, parts)
    covered = np.concatenate([np.arange(lo, hi) for lo, hi in ranges]) if ranges else np.zeros(0)
    assert np.array_equal(covered, np.arange(n))
    assert all(hi > lo for lo, hi in ranges)
    assert len(ranges) == min(n, parts)


def test_map_ranges_visits_every_row_once_and_keeps_the_order():
    seen = np.zeros(1000, dtype=np.int64)
    threads = set()

    def fn(lo, hi, offset):
        threads.add(threading.get_ident())
        seen[lo:hi] += 1
        return lo + offset

    results = _threads.map_ranges(fn, len(seen), 5)
    starts = [lo for lo, _ in _threads.split(len(seen), _threads.PIECES_PER_WORKER * _threads.n_workers())]
    assert results == [lo + 5 for lo in starts]
    assert (seen == 1).all()
    assert len(threads) <= _threads.n_workers()
    assert _threads.map_ranges(fn, 0, 5) == []
    assert len(_threads.map_ranges(fn, 1000, 0, pieces_per_worker=1)) == min(1000, _threads.n_workers())


def _on_threads(n: int, fn):
    before = nb.get_num_threads()
    nb.set_num_threads(n)
    try:
        assert _threads.n_workers() == n
        return fn()
    finally:
        nb.set_num_threads(before)


@pytest.mark.skipif(min(nb.config.NUMBA_NUM_THREADS, os.cpu_count() or 1) < 2, reason="needs two cores")
def test_kernels_give_the_same_result_on_one_thread_and_on_two():
    """The descriptor kernels, the BP sweep, the nearest-row search, the descent, the
    chord pruning of the geodesic graph and the trilateration's search split their rows
    over the threads; each row is computed alone, so the results agree bit for bit."""
    cloud = sphere_points(3000, seed=1)
    points = cloud[:200]
    rng = np.random.default_rng(0)
    basis, query = rng.normal(size=(500, 20)), rng.normal(size=(300, 20))
    mrf, _ = sphere_problem(30, 400, 4, seed=2)
    vertices, faces = unit_sphere(3)
    graph = geodesics.surface_graph(vertices, faces)
    evecs = eigenpairs(vertices, faces, 20)[1]
    start = rng.permutation(len(vertices))
    on_part, on_whole = rng.random((12, 300)), rng.random((12, 400))

    def run():
        images = quantize(spin_images(points, points, cloud, 0.3, 8))
        marginals = belief_propagation(mrf, schedule="colour", iterations=4, tol=0.0, dtype=np.float32).marginals
        descent = spectral_descent(graph, np.arange(len(vertices)), start, evecs)
        chords = geodesics.surface_graph(vertices, faces)
        located = best_images(on_part, on_whole, 0.5, np.full(300, -1))
        nearest = nearest_rows(query, basis)
        return images, nmi(images, images), nearest, marginals, descent, chords.indices, chords.data, located

    one, two = _on_threads(1, run), _on_threads(2, run)
    for a, b in zip(one, two, strict=True):
        assert np.array_equal(a, b)


def _blas_threads() -> set[int]:
    """The thread counts of the BLAS libraries loaded (NumPy's and SciPy's may be two)."""
    return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}


class _Stop(Exception):
    """Raised by a patched stage once it has seen the thread count."""


@pytest.mark.parametrize("entry", ["detect", "match"])
def test_detect_and_match_run_blas_on_one_thread_and_give_the_callers_back(entry, monkeypatch):
    """Whatever the caller's BLAS thread count, the pipeline's products and eigensolves
    run on one thread (their sums, and the maps, then do not depend on the machine's
    cores: tests/test_laplacian.py), and the caller's count is back afterwards, on an
    error too."""
    module = {"detect": self_matching, "match": two_shapes}[entry]
    seen = []

    def solve(*args, **kwargs):
        seen.append(_blas_threads())
        raise _Stop

    monkeypatch.setattr(module, "solve", solve)
    figure = shapes.figure(4)
    # small counts: the defaults' 4,000 targets subdivided the figure to 8,000 vertices first
    p = intrinsym.make_params(n_source=20, n_target=200)
    run = {"detect": lambda: intrinsym.detect(figure, p), "match": lambda: intrinsym.match(figure, figure, p)}[entry]
    with threadpool_limits(2, user_api="blas"):
        with pytest.raises(_Stop):
            run()
        assert _blas_threads() == {2}
    assert seen == [{1}]
