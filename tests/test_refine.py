"""Geodesic trilateration of a dense map against exact mirror images (the bent ellipsoid)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import intrinsym
from intrinsym import evaluate, geodesics
from intrinsym.globalmap import refined_map
from intrinsym.refine import _nearest_sources, agreeing_anchors, trilaterate
from intrinsym.shape import from_arrays
from intrinsym.surface import prepare, sample


def _surface(mirror):
    v, f, sym = mirror
    surf = prepare(from_arrays(v, f))
    assert np.array_equal(surf.vertex_map, np.arange(len(v)))
    return surf, sym, sample(surf, 80, None, 1)


def _slid(surf, sym: np.ndarray, offset: float) -> np.ndarray:
    """The mirror map composed with a slide along the long axis by ``offset`` (normalised
    units): every image is off by about that much, smoothly."""
    work = surf.shape.vertices
    return sym[cKDTree(work).query(work + [0.0, offset, 0.0])[1]]


def _errors(surf, image: np.ndarray, sym: np.ndarray) -> np.ndarray:
    return evaluate.map_errors(image, sym, surf.graph)


def test_a_slid_map_is_pulled_back_onto_the_mirror(mirror):
    surf, sym, ps = _surface(mirror)
    start = _slid(surf, sym, 0.06)
    before = _errors(surf, start, sym)
    assert np.median(before) > 0.04
    refined = trilaterate(surf.graph, np.arange(len(sym)), start, ps, sym[ps], 20, 0.01, 0.4)
    after = _errors(surf, refined, sym)
    spacing = np.median(surf.graph.data)
    assert np.mean(after <= 2 * spacing) > 0.95
    assert after.mean() < before.mean() / 5


def test_the_exact_map_is_kept(mirror):
    surf, sym, ps = _surface(mirror)
    refined = trilaterate(surf.graph, np.arange(len(sym)), sym, ps, sym[ps], 20, 0.01, 0.4)
    np.testing.assert_array_equal(refined, sym)


def test_a_vertex_without_its_k_anchors_within_reach_keeps_its_image(mirror):
    surf, sym, ps = _surface(mirror)
    start = _slid(surf, sym, 0.06)
    spacing = np.sqrt(1.0 / len(ps))  # the samples' spacing: a disc this wide holds about 3
    refined = trilaterate(surf.graph, np.arange(len(sym)), start, ps, sym[ps], 20, 0.01, spacing)
    np.testing.assert_array_equal(refined, start)
    with pytest.raises(ValueError, match="differ in length"):
        trilaterate(surf.graph, np.arange(3), start[:2], ps, sym[ps], 20, 0.01, 0.4)


def test_anchors_agree_within_the_tolerance(mirror):
    surf, sym, ps = _surface(mirror)
    anchors = sym[ps].copy()
    anchors[:5] = np.argmax(geodesics.distances_from(surf.graph, sym[ps[:5]]), axis=1)
    ok = agreeing_anchors(surf.graph, anchors, sym[ps], 0.1)
    assert not ok[:5].any() and ok[5:].all()


def test_refined_map_ignores_marginals_that_disagree_with_the_map(mirror):
    """Marginals peaked at the true image of every sample but ten, whose peaks are far
    off: the exact map stays, and a slid one is pulled back by the agreeing samples."""
    surf, sym, ps = _surface(mirror)
    pt = np.arange(len(sym))
    marginals = np.full((len(ps), len(pt)), 1e-3)
    marginals[np.arange(len(ps)), sym[ps]] = 1.0
    far = np.argmax(geodesics.distances_from(surf.graph, sym[ps[:10]]), axis=1)
    marginals[np.arange(10), sym[ps[:10]]] = 1e-3
    marginals[np.arange(10), far] = 1.0
    p = intrinsym.Params(refine_anchors=8)  # 80 samples: about 20 within reach, 10 of them dropped
    spacing = 0.005  # the tolerance, 2 spacings, is below the slide's error
    np.testing.assert_array_equal(refined_map(surf, ps, pt, ps, marginals, sym, spacing, p), sym)
    start = _slid(surf, sym, 0.04)
    refined = refined_map(surf, ps, pt, ps, marginals, start, spacing, p)
    assert _errors(surf, refined, sym).mean() < _errors(surf, start, sym).mean() / 3


def test_nearest_sources_against_a_dense_sort():
    """Every query's k nearest sources, as a dense argsort finds them, in source order."""
    rng = np.random.default_rng(0)
    n_sources, n_vertices, k = 30, 50, 4
    dense = np.where(rng.random((n_sources, n_vertices)) < 0.3, rng.random((n_sources, n_vertices)), np.inf)
    rows, cols = np.nonzero(np.isfinite(dense))
    queries = np.array([0, 7, 7, 49, 3])
    ptr, source, distance = _nearest_sources(rows, cols, dense[rows, cols], n_vertices, queries, k)
    for q, v in enumerate(queries):
        finite = np.flatnonzero(np.isfinite(dense[:, v]))
        want = np.sort(finite[np.argsort(dense[finite, v], kind="stable")[:k]])
        np.testing.assert_array_equal(source[ptr[q] : ptr[q + 1]], want)
        np.testing.assert_array_equal(distance[ptr[q] : ptr[q + 1]], dense[want, v])
