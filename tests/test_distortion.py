"""The distortion of a vertex map against Euclidean distances on a flat square."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import unit_square_grid
from intrinsym.geodesics import geodesics
from intrinsym.globalmap.distortion import local_distortion, local_distortion_on_graph, map_distortion
from intrinsym.mesh.shape import from_arrays


def test_map_distortion_against_euclidean_distances():
    n = 24
    v, f = unit_square_grid(n)
    shape = from_arrays(v, f)
    i, j = np.rint(v[:, 0] * n).astype(int), np.rint(v[:, 1] * n).astype(int)
    every = len(v)  # every vertex a source: the scores cover all pairs within the radius
    # a reflection of the square is an isometry: only the graph's metrication is left
    reflection = (n - i) * (n + 1) + j
    s = map_distortion(reflection, shape, radius=0.5, n_sources=every)
    assert s.above(0.05) == 0.0 and s.mean < 0.005
    # x -> x^2 (snapped to the grid) stretches the right and squeezes the left: the
    # distortion of every pair from the Euclidean distances of the snapped points
    squeeze = np.rint(n * (i / n) ** 2).astype(int) * (n + 1) + j
    s = map_distortion(squeeze, shape, radius=0.5, n_sources=every)
    d = np.linalg.norm(v[:, None, :2] - v[None, :, :2], axis=2)
    near = (d <= 0.5) & ~np.eye(len(v), dtype=bool)
    change = np.abs(np.linalg.norm(v[squeeze][:, None, :2] - v[squeeze][None, :, :2], axis=2) - d)[near]
    for t in (0.05, 0.10):
        assert s.above(t) == pytest.approx(np.mean(change > t), abs=0.02)
    assert s.mean == pytest.approx(change.mean(), rel=0.05)
    assert s.n_pairs == pytest.approx(near.sum(), rel=0.05)
    assert set(s.as_dict()) == {"above_0.05", "above_0.10", "mean", "radius", "n_pairs"}


def test_map_distortion_leaves_out_unmapped_vertices_and_checks_the_shape():
    v, f = unit_square_grid(12)
    shape = from_arrays(v, f)
    half = np.where(v[:, 0] < 0.5, np.arange(len(v)), -1)
    s = map_distortion(half, shape, n_sources=50, seed=3)
    assert s.above(0.0) == 0.0 and 0 < s.n_pairs
    left = np.flatnonzero(half >= 0)  # every pair lies in the mapped half
    d = np.linalg.norm(v[left, None, :2] - v[None, left, :2], axis=2)
    pairs = ((d <= 0.5) & ~np.eye(len(left), dtype=bool)).sum()
    assert map_distortion(half, shape, n_sources=len(left)).n_pairs == pytest.approx(pairs, rel=0.05)
    again = map_distortion(half, shape, n_sources=50, seed=3)
    assert again.as_dict() == s.as_dict()
    assert map_distortion(np.full(len(v), -1), shape).n_pairs == 0
    with pytest.raises(ValueError, match="expected"):
        map_distortion(np.arange(len(v) - 1), shape)


def test_local_distortion_against_euclidean_distances():
    n = 24
    v, f = unit_square_grid(n)
    shape = from_arrays(v, f)
    i, j = np.rint(v[:, 0] * n).astype(int), np.rint(v[:, 1] * n).astype(int)
    # a spacing below the grid step: every vertex is measured from itself
    fine = {"radius": 0.15, "spacing": 0.5 / n, "clip": 0.15}
    reflection = (n - i) * (n + 1) + j
    assert np.nanmax(local_distortion(reflection, shape, **fine)) < 0.005
    squeeze = np.rint(n * (i / n) ** 2).astype(int) * (n + 1) + j
    got = local_distortion(squeeze, shape, **fine)
    d = np.linalg.norm(v[:, None, :2] - v[None, :, :2], axis=2)
    near = d <= fine["radius"]
    change = np.abs(np.linalg.norm(v[squeeze][:, None, :2] - v[squeeze][None, :, :2], axis=2) - d)
    expected = (change * near).sum(axis=1) / near.sum(axis=1)
    assert np.abs(got - expected).max() < 0.01
    # x -> x^2 has slope 2x: it stretches lengths near x = 1 and keeps them near x = 1/2
    right, middle = (i == n - 2) & (j == n // 2), (i == n // 2) & (j == n // 2)
    assert got[right][0] > 2 * got[middle][0] > 0


def test_local_distortion_is_nan_where_nothing_is_mapped():
    v, f = unit_square_grid(12)
    shape = from_arrays(v, f)
    half = np.where(v[:, 0] < 0.5, np.arange(len(v)), -1)
    got = local_distortion(half, shape, spacing=0.05)
    assert np.all(got[v[:, 0] < 0.4] < 1e-9)
    assert np.all(np.isnan(got[v[:, 0] > 0.6]))
    with pytest.raises(ValueError, match="expected"):
        local_distortion(np.arange(len(v) - 1), shape)


def test_local_distortion_into_another_graph():
    """A map into a second graph is measured on that graph: the identity of the square
    onto the square grown by 1.5 changes every distance d by d / 2."""
    n = 24
    v, f = unit_square_grid(n)
    _, _, graph = geodesics.unit_area_graph(from_arrays(v, f))
    fine = {"radius": 0.15, "spacing": 0.5 / n, "clip": 0.15}
    identity = np.arange(len(v))
    same = local_distortion_on_graph(graph, v, identity, **fine)
    assert np.array_equal(local_distortion_on_graph(graph, v, identity, **fine, target_graph=graph), same)
    assert same.max() < 1e-12
    grown = local_distortion_on_graph(graph, v, identity, **fine, target_graph=1.5 * graph)
    d = np.linalg.norm(v[:, None, :2] - v[None, :, :2], axis=2)
    near = (d <= fine["radius"]) & (d > 0)
    expected = 0.5 * (d * near).sum(axis=1) / near.sum(axis=1)
    assert np.abs(grown - expected).max() < 0.01
