"""Partial functional maps (globalmap/partial_fmap.py): the gradient against linear
functions, the commutativity term and the C-step against their dense Kronecker forms, the
spin-image descriptors' locality, and a part of the posed figure mapped into the figure."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import trimesh

from conftest import part_of, right_share
from intrinsym.evaluation import evaluate
from intrinsym.geodesics import geodesics
from intrinsym.globalmap import confidence, part_map, partial_fmap
from intrinsym.mesh.shape import from_arrays, surface_area
from intrinsym.params import Params
from intrinsym.surface import prepare_pair


def test_the_gradient_of_a_linear_function_is_its_tangent_part() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=2)
    v = sphere.vertices * [1.5, 1.0, 0.6]
    grad, areas = partial_fmap.gradient_operator(v, sphere.faces)
    a = np.array([0.3, -1.2, 0.7])
    per_face = (grad @ (v @ a)).reshape(3, -1).T
    normal = np.cross(v[sphere.faces[:, 1]] - v[sphere.faces[:, 0]], v[sphere.faces[:, 2]] - v[sphere.faces[:, 0]])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    assert np.allclose(per_face, a - (normal @ a)[:, None] * normal, atol=1e-12)
    assert areas.sum() == pytest.approx(trimesh.Trimesh(v, sphere.faces).area)
    assert np.allclose(grad @ np.ones(len(v)), 0.0, atol=1e-12)  # constants have no gradient


def _symmetric(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    m = rng.normal(size=(n, k, k))
    return m + m.transpose(0, 2, 1)


def _dense_commutativity(f: np.ndarray, g: np.ndarray) -> np.ndarray:
    """The term's quadratic form on the row-major vec(C): mean_f of
    kron(I, F^2) + kron(G^2, I) - 2 kron(G, F)."""
    k_w, k_p = g.shape[1], f.shape[1]
    return sum(
        np.kron(np.eye(k_w), ff @ ff) + np.kron(gg @ gg, np.eye(k_p)) - 2 * np.kron(gg, ff) for ff, gg in zip(f, g)
    ) / len(f)


def test_the_commutativity_gradient_is_its_dense_quadratic_form() -> None:
    rng = np.random.default_rng(0)
    f, g = _symmetric(rng, 4, 5), _symmetric(rng, 4, 7)
    c = rng.normal(size=(7, 5))
    q = _dense_commutativity(f, g)
    assert np.allclose(partial_fmap.commutativity_gradient(c, f, g).ravel(), q @ c.ravel())
    energy = np.mean([np.linalg.norm(c @ ff - gg @ c) ** 2 for ff, gg in zip(f, g)])
    assert c.ravel() @ q @ c.ravel() == pytest.approx(energy)


def test_the_normal_equations_are_solved_as_the_dense_system_solves_them() -> None:
    rng = np.random.default_rng(1)
    k_w, k_p = 8, 5
    f, g = _symmetric(rng, 3, k_p) / 10, _symmetric(rng, 3, k_w) / 10
    a = rng.normal(size=(k_p, 20))
    gram = a @ a.T / 40
    w_sq = rng.random((k_w, k_p))
    rhs = rng.normal(size=(k_w, k_p))
    h = (
        np.kron(np.eye(k_w), gram)
        + partial_fmap.MU_W * np.diag(w_sq.ravel())
        + partial_fmap.MU_DC * _dense_commutativity(f, g)
    )
    dense = scipy.linalg.solve(h, rhs.ravel(), assume_a="pos")
    identity = np.broadcast_to(np.eye(k_p), (k_w, k_p, k_p))
    for start in (None, rng.normal(size=(k_w, k_p))):
        found = partial_fmap._solve_normal_equations(gram, w_sq, (f, g), rhs, identity, start)
        assert np.allclose(found, dense, rtol=1e-7, atol=1e-9 * np.abs(dense).max())


def test_a_cut_changes_the_descriptors_only_near_it(figure_and_part) -> None:
    """The part's descriptor functions equal the whole's at the same vertices away from
    the cut (farther than the spin radius), up to the sampling of the images: their
    difference there is a small share of the difference between two vertices."""
    figure, used = figure_and_part
    p = Params()
    a, b = prepare_pair(part_of(figure, used), from_arrays(figure.vertices, figure.faces), 0, "auto")
    d_part, d_whole = part_map.part_descriptors(a, b, p)
    assert d_part.shape == (len(a.shape.vertices), part_map.SPIN_COMPONENTS) and d_whole.shape[1] == d_part.shape[1]
    assert d_whole.min() == 0.0
    # the part's working vertices on the whole's working mesh, and their distance to the cut
    on_whole = b.vertex_map[used[a.nearest_input_vertex(a.shape.vertices)]]
    cut = b.shape.vertices[b.vertex_map[np.setdiff1d(np.arange(len(figure.vertices)), used)]]
    far = np.linalg.norm(a.shape.vertices[:, None] - cut[None], axis=2).min(axis=1) > 1.5 * p.spin_radius
    assert far.sum() > 50
    same = np.linalg.norm(d_part[far] - d_whole[on_whole[far]], axis=1)
    rng = np.random.default_rng(0)
    other = np.linalg.norm(d_whole[on_whole[far]] - d_whole[rng.permutation(on_whole[far])], axis=1)
    assert np.median(same) < 0.3 * np.median(other)


def test_a_part_of_the_figure_maps_onto_its_place(figure_and_part) -> None:
    # measured at this size: 0.92 within 0.10, the indicator covering 0.98 of the part's area
    figure, used = figure_and_part
    a, b = prepare_pair(part_of(figure, used), from_arrays(figure.vertices, figure.faces), 0, "auto")
    assert right_share(figure, used, part_map.part_fmap_map(a, b, part_map.part_descriptors(a, b, Params()))) >= 0.85


def test_the_less_distorted_map_is_kept(figure_and_part) -> None:
    """choose_part_map keeps the extraction's map when it is the true one and the
    partial functional map's is random, and the other way round."""
    figure, used = figure_and_part
    a, b = prepare_pair(part_of(figure, used), from_arrays(figure.vertices, figure.faces), 0, "auto")
    rng = np.random.default_rng(0)
    random_map = rng.integers(0, len(figure.vertices), len(used))
    image, stats = part_map.choose_part_map(used.copy(), a, b, random_map)
    assert image is None and stats.source == "extraction"
    assert stats.distortion["extraction"] < 0.05 < stats.distortion["partial_fmap"]
    # the share kept is the confidence's score: the true map near the table's top, a
    # random one at its floor, measured without a partial functional map too
    kept = {name: 1.0 - share for name, share in stats.distortion.items()}
    assert stats.kept == kept["extraction"] > 0.95 and kept["partial_fmap"] < 0.25
    table = confidence.PART_CALIBRATION
    assert confidence.calibrated(np.array([kept["partial_fmap"]]), table=table)[0] == min(table)
    alone = part_map.choose_part_map(used.copy(), a, b)
    assert alone == (None, part_map.PartMapStats("extraction", {"extraction": stats.distortion["extraction"]}))
    image, stats = part_map.choose_part_map(rng.integers(0, len(used), len(used)), a, b, used.copy())
    assert stats.source == "partial_fmap" and image is not None
    assert np.array_equal(image, used)
    # an extraction that gives no image at all is replaced
    image, stats = part_map.choose_part_map(np.full(len(used), -1), a, b, used.copy())
    assert stats.source == "partial_fmap" and stats.distortion["extraction"] is None
    # a map that gives no image keeps none of the distances
    assert part_map.choose_part_map(np.full(len(used), -1), a, b)[1].kept == 0.0


def test_refining_a_cell_map_gives_the_vertices_their_own_images(figure_and_part) -> None:
    """refine_part_map of the true map coarsened to 30 cells (every vertex takes its cell
    centre's image, as a map from BP's samples does; a few without an image) puts more
    of the part within 0.05 of the truth than the cell map, and gives every vertex an
    image; refined_if_less_distorted keeps it, not a random map; a map without images
    comes back as it is."""
    figure, used = figure_and_part
    a, b = prepare_pair(part_of(figure, used), from_arrays(figure.vertices, figure.faces), 0, "auto")
    rng = np.random.default_rng(0)
    centres = rng.choice(len(used), 30, replace=False)
    part_vertices = figure.vertices[used]
    cell = np.linalg.norm(part_vertices[:, None] - part_vertices[centres][None], axis=2).argmin(axis=1)
    coarse = used[centres][cell]
    coarse[rng.choice(len(used), 10, replace=False)] = -1
    refined = part_map.refine_part_map(coarse, a, b)
    assert refined.shape == coarse.shape and (refined >= 0).all()

    def within(images: np.ndarray, t: float) -> float:
        unit = np.sqrt(surface_area(from_arrays(figure.vertices, figure.faces)))
        graph = geodesics.surface_graph(figure.vertices / unit, figure.faces)
        return float(np.mean(evaluate.map_errors(images, used, graph) <= t))

    # measured: 0.39 -> 0.73 within 0.05 (seeds 1, 2 of the cells: 0.38 -> 0.90, 0.36 -> 0.70)
    assert within(refined, 0.05) > within(coarse, 0.05) + 0.25
    # the refinement changes fewer of the part's distances than the cell map: it is kept,
    # and its share is the confidence's score; a random "refinement" is not
    _, stats = part_map.choose_part_map(coarse, a, b)
    better, kept = part_map.refined_if_less_distorted(refined, a, b, stats)
    assert better and kept.refined and kept.source == "extraction"
    assert kept.distortion["refined"] < kept.distortion["extraction"] and kept.kept == 1.0 - kept.distortion["refined"]
    better, kept = part_map.refined_if_less_distorted(rng.integers(0, len(figure.vertices), len(used)), a, b, stats)
    assert not better and not kept.refined and kept.distortion["refined"] > kept.distortion["extraction"]
    assert kept.kept == 1.0 - kept.distortion["extraction"]
    none = np.full(len(used), -1)
    assert np.array_equal(part_map.refine_part_map(none, a, b), none)
