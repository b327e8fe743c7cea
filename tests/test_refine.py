"""Geodesic trilateration of a dense map against exact mirror images (the bent ellipsoid)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import intrinsym
from intrinsym.evaluation import evaluate
from intrinsym.geodesics import geodesics
from intrinsym.globalmap.globalmap import refined_map
from intrinsym.globalmap.refine import (
    _nearest_sources,
    agreeing_anchors,
    consistent_anchors,
    spectral_descent,
    trilaterate,
)
from intrinsym.mesh.shape import from_arrays
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


def test_a_vertex_with_fewer_than_k_anchors_within_reach_uses_those_it_has(mirror):
    """At a reach of 0.08 (the 80 samples lie about 0.11 apart) a vertex has at most three
    anchors, as at the tip of a limb: one to three still pull a slid image back onto the
    mirror (from one, the descent stops on the circle about it nearest the start), none
    leave it where it was."""
    surf, sym, ps = _surface(mirror)
    start = _slid(surf, sym, 0.06)
    reach = 0.08
    near = np.count_nonzero(geodesics.distances_from(surf.graph, ps) <= reach, axis=0)
    assert near.max() <= 3 and np.count_nonzero(near == 0) > 10
    refined = trilaterate(surf.graph, np.arange(len(sym)), start, ps, sym[ps], 20, 0.01, reach)
    before, after = _errors(surf, start, sym), _errors(surf, refined, sym)
    np.testing.assert_array_equal(refined[near == 0], start[near == 0])
    assert np.median(before[near > 0]) > 0.05
    assert after[near == 1].mean() < before[near == 1].mean() / 3
    assert after[near >= 2].mean() < before[near >= 2].mean() / 10
    with pytest.raises(ValueError, match="differ in length"):
        trilaterate(surf.graph, np.arange(3), start[:2], ps, sym[ps], 20, 0.01, 0.4)


def test_a_tip_turned_about_the_long_axis_is_caught_by_its_nearest_anchor(mirror):
    """The tip of the ellipsoid's long axis turned 40 degrees about that axis: the turn
    keeps the distances to the anchors up the axis, so some tip vertices keep them within
    the tolerance in the root mean square, but not the distance to their nearest anchor.
    Those move, onto the mirror."""
    surf, sym, ps = _surface(mirror)
    v = surf.shape.vertices
    tip = v[:, 1] > np.quantile(v[:, 1], 0.93)
    axis = [v[tip, 0].mean(), 0.0, v[tip, 2].mean()]
    angle = np.deg2rad(40.0)
    turn = np.array([[np.cos(angle), 0.0, np.sin(angle)], [0.0, 1.0, 0.0], [-np.sin(angle), 0.0, np.cos(angle)]])
    start = sym.copy()
    start[tip] = sym[cKDTree(v).query((v[tip] - axis) @ turn.T + axis)[1]]
    tolerance, reach = 0.05, 0.4
    from_samples = geodesics.distances_from(surf.graph, ps)
    from_anchors = geodesics.distances_from(surf.graph, sym[ps])
    caught = []
    for x in np.flatnonzero(tip):
        inside = np.flatnonzero(from_samples[:, x] <= reach)
        nearest = inside[np.argsort(from_samples[inside, x], kind="stable")[:20]]
        residual = from_anchors[nearest, start[x]] - from_samples[nearest, x]
        if np.sqrt(np.mean(residual**2)) <= tolerance < abs(residual[0]):
            caught.append(x)
    assert len(caught) >= 10
    refined = trilaterate(surf.graph, np.arange(len(sym)), start, ps, sym[ps], 20, tolerance, reach)
    before, after = _errors(surf, start, sym), _errors(surf, refined, sym)
    assert before[caught].mean() > 0.05
    assert after[caught].mean() < 0.01
    np.testing.assert_array_equal(refined[~tip], start[~tip])


def test_anchors_agree_within_the_tolerance(mirror):
    surf, sym, ps = _surface(mirror)
    anchors = sym[ps].copy()
    anchors[:5] = np.argmax(geodesics.distances_from(surf.graph, sym[ps[:5]]), axis=1)
    ok = agreeing_anchors(surf.graph, anchors, sym[ps], 0.1)
    assert not ok[:5].any() and ok[5:].all()


def _group(surf, ps: np.ndarray, radius: float) -> np.ndarray:
    """The sample farthest from the mirror plane and every sample within ``radius`` of it."""
    first = np.argmax(surf.shape.vertices[ps, 0])
    return np.flatnonzero(geodesics.distances_from(surf.graph, ps[[first]])[0, ps] <= radius)


def _orientation(surf, ps: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return geodesics.voronoi_adjacency(surf.graph, ps), surf.shape.vertices, surf.normals


def test_the_anchors_of_a_part_the_map_flipped_are_kept(mirror):
    """The map keeps a part in place (the identity: it does not turn the part around,
    as the mirror turns the rest); there the true anchors disagree with it, turn the
    part around and keep the distances, so they are kept."""
    surf, sym, ps = _surface(mirror)
    group = _group(surf, ps, 0.2)
    assert len(group) >= 3
    images = sym[ps].copy()
    images[group] = ps[group]
    assert not agreeing_anchors(surf.graph, sym[ps], images, 0.1)[group].any()
    keep = consistent_anchors(surf.graph, ps, sym[ps], images, 0.1, 20, 0.4, _orientation(surf, ps))
    assert keep.all()


def test_a_disagreeing_anchor_where_the_map_turns_the_right_way_is_trusted_beyond_the_trivial_radius(mirror):
    """The map slides a part 0.15 along the mirror (still turning it around). Without a
    trivial radius the true anchors there are not used, as a marginal pushed off the
    midline would not be; with 0.08 they are (the part lies far from the mirror plane, so
    its images lie far beyond the radius from it, and the anchors keep the distances)."""
    surf, sym, ps = _surface(mirror)
    group = _group(surf, ps, 0.2)
    images = sym[ps].copy()
    images[group] = _slid(surf, sym, 0.15)[ps[group]]
    agree = agreeing_anchors(surf.graph, sym[ps], images, 0.1)
    assert np.count_nonzero(~agree[group]) >= 3
    orientation = _orientation(surf, ps)
    keep = consistent_anchors(surf.graph, ps, sym[ps], images, 0.1, 20, 0.4, orientation)
    np.testing.assert_array_equal(keep, agree)
    assert consistent_anchors(surf.graph, ps, sym[ps], images, 0.1, 20, 0.4, orientation, 0.08).all()


def test_a_disagreeing_anchor_is_not_trusted_where_the_map_keeps_a_part_within_the_trivial_radius(mirror):
    """Samples on the mirror plane slid 0.045-0.075 along it: their images stay within
    the trivial radius 0.08 of them (the midline, where a marginal is pushed off the true
    image), so their true anchors are not used; with a radius of 0.04 they are."""
    surf, sym, ps = _surface(mirror)
    near = np.flatnonzero(np.abs(surf.shape.vertices[ps, 0]) < 0.05)
    slid = _slid(surf, sym, 0.06)[ps[near]]
    moved = geodesics.pair_distances(surf.graph, np.column_stack([ps[near], slid]))
    between = (moved > 0.045) & (moved < 0.075)  # the bend stretches some slides
    images = sym[ps].copy()
    images[near[between]] = slid[between]
    agree = agreeing_anchors(surf.graph, sym[ps], images, 0.03)
    assert np.count_nonzero(~agree) >= 3
    orientation = _orientation(surf, ps)
    keep = consistent_anchors(surf.graph, ps, sym[ps], images, 0.03, 20, 0.4, orientation, 0.08)
    np.testing.assert_array_equal(keep, agree)
    assert consistent_anchors(surf.graph, ps, sym[ps], images, 0.03, 20, 0.4, orientation, 0.04).all()


def test_anchors_that_do_not_keep_the_distances_are_dropped(mirror):
    """The map keeps a part in place and the anchors there turn it around but lie half the
    shape away (another part's images): they keep the distances worse and are dropped."""
    surf, sym, ps = _surface(mirror)
    group = _group(surf, ps, 0.2)
    images = sym[ps].copy()
    images[group] = ps[group]
    anchors = sym[ps].copy()
    anchors[group] = _slid(surf, sym, -0.6)[ps[group]]
    agree = agreeing_anchors(surf.graph, anchors, images, 0.1)
    assert np.count_nonzero(~agree[group]) >= 3
    keep = consistent_anchors(surf.graph, ps, anchors, images, 0.1, 20, 0.4, _orientation(surf, ps))
    np.testing.assert_array_equal(keep, agree)


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
    edges = geodesics.voronoi_adjacency(surf.graph, ps)
    np.testing.assert_array_equal(refined_map(surf, ps, pt, ps, marginals, sym, edges, spacing, p), sym)
    start = _slid(surf, sym, 0.04)
    refined = refined_map(surf, ps, pt, ps, marginals, start, edges, spacing, p)
    assert _errors(surf, refined, sym).mean() < _errors(surf, start, sym).mean() / 3


def test_nearest_sources_against_a_dense_sort():
    """Every query's k nearest sources, as a dense argsort finds them, in source order."""
    rng = np.random.default_rng(0)
    n_sources, n_vertices, k = 30, 50, 4
    dense = np.where(rng.random((n_sources, n_vertices)) < 0.3, rng.random((n_sources, n_vertices)), np.inf)
    # contiguous, as the refinement passes them: np.nonzero's columns of one array would
    # compile the kernel a second time, for strided arrays
    rows, cols = (np.ascontiguousarray(a) for a in np.nonzero(np.isfinite(dense)))
    queries = np.array([0, 7, 7, 49, 3])
    ptr, source, distance = _nearest_sources(rows, cols, dense[rows, cols], n_vertices, queries, k)
    for q, v in enumerate(queries):
        finite = np.flatnonzero(np.isfinite(dense[:, v]))
        want = np.sort(finite[np.argsort(dense[finite, v], kind="stable")[:k]])
        np.testing.assert_array_equal(source[ptr[q] : ptr[q + 1]], want)
        np.testing.assert_array_equal(distance[ptr[q] : ptr[q + 1]], dense[want, v])


def _jittered(surf, sym: np.ndarray, share: float, seed: int = 0) -> np.ndarray:
    """The mirror map with ``share`` of the images moved to a random graph neighbour:
    vertex-to-vertex noise of about one chord, no bias."""
    rng = np.random.default_rng(seed)
    g = surf.graph.tocsr()
    out = sym.copy()
    for x in np.flatnonzero(rng.random(len(sym)) < share):
        nbrs = g.indices[g.indptr[sym[x]] : g.indptr[sym[x] + 1]]
        out[x] = rng.choice(nbrs)
    return out


def test_spectral_descent_removes_vertex_noise_from_the_mirror_map(mirror):
    from intrinsym.spectral.laplacian import eigenpairs

    surf, sym, _ = _surface(mirror)
    evals, evecs = eigenpairs(surf.shape.vertices, surf.shape.faces, 60)
    noisy = _jittered(surf, sym, 0.5)
    before = _errors(surf, noisy, sym)
    points = np.arange(len(sym))
    smoothed = spectral_descent(surf.graph, points, noisy, evecs)
    after = _errors(surf, smoothed, sym)
    assert np.mean(before == 0) < 0.55 and np.mean(after < 1e-9) > 0.9
    assert after.mean() < 0.25 * before.mean()
    # the exact mirror map is a fixed point: its projection is exact
    assert np.array_equal(spectral_descent(surf.graph, points, sym, evecs), sym)


def test_spectral_descent_ends_at_local_minima_of_the_projection(mirror):
    from intrinsym.spectral.laplacian import eigenpairs

    surf, sym, _ = _surface(mirror)
    _, evecs = eigenpairs(surf.shape.vertices, surf.shape.faces, 20)
    noisy = _jittered(surf, sym, 1.0, seed=1)
    points = np.arange(len(sym))
    out = spectral_descent(surf.graph, points, noisy, evecs)
    # the functional map and the projected points, computed again with NumPy
    C = np.linalg.pinv(evecs) @ evecs[noisy]
    query = evecs @ C
    g = surf.graph.tocsr()
    own = np.linalg.norm(evecs[out] - query, axis=1)
    for x in range(0, len(points), 7):
        nbrs = g.indices[g.indptr[out[x]] : g.indptr[out[x] + 1]]
        assert own[x] <= np.linalg.norm(evecs[nbrs] - query[x], axis=1).min() + 1e-9
    with pytest.raises(ValueError, match="differ in length"):
        spectral_descent(surf.graph, points, noisy[:-1], evecs)
    with pytest.raises(ValueError, match="cannot fit"):
        spectral_descent(surf.graph, points[:10], noisy[:10], evecs)
