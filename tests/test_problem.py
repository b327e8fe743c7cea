"""The sampled problem: its source graph against a dense Dijkstra over the same graph, its
target spacing against the hexagonal-packing formula, its nearest input vertices against
a k-d tree; detect and match read their samples' positions and vertices from it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

import intrinsym
from intrinsym.errors import ParameterError
from intrinsym.mesh import generated
from intrinsym.pipeline import sample_pair
from intrinsym.problem import sampled

SMALL = {"n_source": 40, "n_target": 400}


@pytest.fixture(scope="module")
def surface():
    star = generated.star(resolution=8)
    return intrinsym.prepare((star.vertices, star.faces), intrinsym.make_params(**SMALL))


def test_source_graph_joins_the_samples_whose_voronoi_cells_touch(surface):
    p = intrinsym.make_params(**SMALL)
    ps, pt = sample_pair(surface, surface, p)
    problem = sampled(surface, surface, ps, pt, p, True)
    dist, _, nearest = dijkstra(surface.graph, indices=ps, min_only=True, return_predecessors=True)
    cell = np.searchsorted(ps, nearest)  # ps is sorted: the index of each vertex's seed
    rows, cols = surface.graph.nonzero()
    touching = {(min(a, b), max(a, b)) for a, b in zip(cell[rows], cell[cols]) if a != b}
    assert {tuple(e) for e in problem.edges.tolist()} == touching
    assert np.all(problem.edges[:, 0] < problem.edges[:, 1])
    full = dijkstra(surface.graph, indices=ps)
    want = full[problem.edges[:, 0], ps[problem.edges[:, 1]]]
    assert problem.edge_length == pytest.approx(want, rel=1e-9)


def test_target_spacing_and_sample_positions(surface):
    p = intrinsym.make_params(**SMALL)
    ps, pt = sample_pair(surface, surface, p)
    problem = sampled(surface, surface, ps, pt, p, True)
    assert problem.t_spacing == pytest.approx(np.sqrt(2 / (np.sqrt(3) * len(pt))))
    given = sampled(surface, surface, ps, pt, intrinsym.make_params(**SMALL, target_spacing=0.07), True)
    assert given.t_spacing == 0.07
    assert np.array_equal(problem.source_points, surface.shape.vertices[ps])
    assert np.array_equal(problem.target_points, surface.shape.vertices[pt])
    tree = cKDTree(surface.input_vertices)
    assert np.array_equal(problem.source_vertex, tree.query(surface.to_input(problem.source_points))[1])
    assert np.array_equal(problem.target_vertex, tree.query(surface.to_input(problem.target_points))[1])


def test_a_single_sample_has_no_source_graph(surface):
    p = intrinsym.make_params(**SMALL)
    _, pt = sample_pair(surface, surface, p)
    with pytest.raises(ParameterError, match="no neighbourhood graph"):
        sampled(surface, surface, np.array([0]), pt, p, True)
