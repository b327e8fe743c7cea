"""End to end on generated shapes with known symmetry, at small size.

Each star arm should find every other arm: the unary does, the BP marginals do not
(measured: loopy BP, serial or flooding, tolerance 0.5 or 1.5, 10 or 100 iterations,
keeps about one peak per source sample where the unary has about seven; it settles on
one of the star's 19 symmetries, or a blend of several). The extraction recovers the
pairs from the unary's peaks, and further BP passes (``passes``), each with the modes
found before removed from the unary, reach every arm. The failing property of one pass
is a strict xfail, so that a fix of BP shows up as XPASS.
"""

import dataclasses

import numpy as np
import pytest
import trimesh

import intrinsym
from conftest import cut_mesh
from intrinsym.evaluation import evaluate, partial_truth
from intrinsym.extract import extract
from intrinsym.globalmap import confidence, self_hypothesis, vertex_maps
from intrinsym.globalmap.vertex_maps import fitted_vertex_map
from intrinsym.mesh import generated as shapes
from intrinsym.mesh.shape import Shape, surface_area
from intrinsym.params import MAP_MARGIN

SMALL = dict(n_source=60, n_target=600, eigenpairs=40, spin_cloud=10000, iterations=10)


@pytest.fixture(scope="module")
def star():
    """The star and its detect at SMALL; its tests read the unary, the marginals and the
    extraction, not ZoomOut's global map, which runs after them: left out (the three are
    the same bit for bit without it, measured; 0.9 of 1.4 s)."""
    shape = shapes.star(5, resolution=4)
    return shape, intrinsym.detect((shape.vertices, shape.faces), intrinsym.make_params(**SMALL, zoomout=False))


def best_on_arms(potentials: np.ndarray, result: intrinsym.Result, labels: np.ndarray) -> np.ndarray:
    """(k, k): row i holds, for the source sample farthest out on arm i, the largest
    value of its max-normalised row on each arm."""
    arm_s, arm_t = labels[result.source_point_vertex], labels[result.target_point_vertex]
    k = int(labels.max())
    best = np.zeros((k, k))
    for i in range(k):
        on_arm = np.flatnonzero(arm_s == i + 1)
        tip = on_arm[np.argmax(np.linalg.norm(result.source_points[on_arm, :2], axis=1))]
        row = potentials[tip] / potentials[tip].max()
        best[i] = [row[arm_t == j + 1].max() for j in range(k)]
    return best


# Measured at this size: the unary's weakest other arm 0.13 (the floor is 1e-3), the
# marginals' 0.00; a threshold of 0.1 separates the two.
def test_star_unary_reaches_every_arm(star):
    shape, result = star
    best = best_on_arms(result.unary, result, shape.labels)
    assert best[~np.eye(5, dtype=bool)].min() >= 0.1, np.round(best, 2)


@pytest.mark.xfail(strict=True, reason="loopy BP collapses the marginals onto one symmetry")
def test_star_marginals_reach_every_arm(star):
    shape, result = star
    best = best_on_arms(result.marginals, result, shape.labels)
    assert best[~np.eye(5, dtype=bool)].min() >= 0.1, np.round(best, 2)


@pytest.mark.slow  # five BP passes at 60 / 600 (CI: -m slow); passes at small sizes: test_pipeline
def test_star_marginals_of_five_passes_reach_every_arm():
    # measured at this size: the weakest other arm over the passes' marginals 0.42 with
    # 4 passes, 1.0 with 5 (one pass: 0.00, 5 of the 20 arm pairs above 0.1)
    shape = shapes.star(5, resolution=4)
    result = intrinsym.detect((shape.vertices, shape.faces), intrinsym.make_params(**dict(SMALL, passes=5)))
    fields = [result.marginals, *result.pass_marginals]
    assert len(fields) == 5 and len(result.info.bp.passes) == 4
    best = np.max([best_on_arms(f, result, shape.labels) for f in fields], axis=0)
    assert best[~np.eye(5, dtype=bool)].min() >= 0.5, np.round(best, 2)
    assert np.allclose(result.pass_marginals.sum(axis=2), 1.0, atol=1e-4)


def arm_pairs(symmetries: list, result: intrinsym.Result, labels: np.ndarray) -> set[tuple[int, int]]:
    """(i, j), i != j, such that one symmetry carries half of arm i's source samples into arm j."""
    arm_s, arm_t = labels[result.source_point_vertex], labels[result.target_point_vertex]
    found = set()
    for sym in symmetries:
        for k in range(1, 6):
            counts = np.bincount(arm_t[sym.target[arm_s[sym.source] == k]], minlength=6)[1:]
            found |= {(k, j + 1) for j in np.flatnonzero(counts >= 0.5 * np.sum(arm_s == k)) if j + 1 != k}
    return found


def test_unary_seeds_recover_arm_pairs_the_marginals_lost(star):
    """The same result extracted with and without the unary's peaks as seeds (measured
    at this size: 5 and 20 of the 20 ordered arm pairs; 5 and 14 with the unary's
    widths measured in descriptor space, ``calibration="descriptor"``)."""
    shape, result = star
    kw = dict(unary=result.unary)
    args = (result.marginals, result.edges, result.support, result.source_points, result.target_points)
    off = extract.extract_from_support(*args, dataclasses.replace(result.params.extraction(), unary_seeds=False), **kw)
    on = extract.extract_from_support(*args, result.params.extraction(), **kw)
    n_off = len(arm_pairs(off.symmetries, result, shape.labels))
    n_on = len(arm_pairs(on.symmetries, result, shape.labels))
    assert n_on >= 16 and n_on >= 2 * n_off, (n_off, n_on)
    assert on.global_symmetry.target.tolist() == off.global_symmetry.target.tolist()


def test_star_extraction_maps_every_arm_onto_every_other(star):
    shape, result = star
    missing = {(i, j) for i in range(1, 6) for j in range(1, 6) if i != j}
    missing -= arm_pairs(result.extraction.symmetries, result, shape.labels)
    assert not missing, f"arm pairs not found: {sorted(missing)}"


@pytest.fixture(scope="module")
def figure():
    shape = shapes.figure()
    return shape, intrinsym.detect((shape.vertices, shape.faces), intrinsym.make_params(**SMALL))


def test_figure_segmentation_from_fitted_vertex_map(figure):
    """The figure's global map extended to the vertices by local linear fits against
    the Voronoi cells of the samples (vertex_fit 0.5), at this size (measured: per-part scores
    0.71-0.86 with cells, mean 0.78; 0.85-0.99 fitted, mean 0.94)."""
    shape, result = figure
    sym = result.extraction.symmetries[result.extraction.global_index]
    args = (sym, result.support, result.edges, result.source_points, result.target_points, result.target_point_vertex)
    scores = {}
    for fit in (0.0, 0.5):
        vmap = fitted_vertex_map(*args, dataclasses.replace(result.params.extraction(), vertex_fit=fit))
        scores[fit] = np.array(list(evaluate.segmentation_scores(vmap, shape.symmetries[0], shape.labels).values()))
    cells, fitted = scores.values()
    assert fitted.mean() >= 0.9 > cells.mean() + 0.1 and fitted.min() >= 0.8, scores


def test_figure_global_map_stays_precise_when_the_cell_map_keeps_a_hair_more_mass(figure):
    """The figure's exact mirror (composed with the plate's flip: the best of its three
    maps). At this size the extraction's cell map keeps a hair more marginal mass within
    0.10 than seeded ZoomOut's map (measured 0.967 against 0.965; within 0.05, 0.822
    against 0.785: every sample sits on a marginal peak), yet ZoomOut's is the precise
    one (within 0.05: 0.999 against 0.492); the global map stays ZoomOut's unless it
    keeps MAP_MARGIN less."""
    shape, result = figure
    chosen = result.info.global_map
    masses = chosen.masses
    assert masses["extraction"] > masses["zoomout"] > masses["extraction"] - MAP_MARGIN, masses
    assert chosen.source == "zoomout" and np.array_equal(result.symmetry_map(), result.global_map)
    mesh = Shape(shape.vertices, shape.faces)
    sym = result.extraction.global_symmetry
    cells = vertex_maps.vertex_map(sym, result.support.vertex_source, result.target_point_vertex, len(result.marginals))
    within = {
        name: max(evaluate.score_map(vmap, mesh, truth).within(0.05) for truth in shape.symmetries)
        for name, vmap in (("global", result.symmetry_map()), ("cells", cells))
    }
    assert within["global"] >= 0.99 and within["cells"] < within["global"] - 0.1, within
    mass = result.symmetry_mass()
    assert mass.shape == (len(shape.vertices),) and 0.0 <= mass.min() and mass.max() <= 1.0
    assert abs(float(mass[result.source_point_vertex].mean()) - chosen.mass) < 0.05


@pytest.mark.slow  # a detect at 120 / 1500, the size it was measured at (CI: -m slow)
@pytest.mark.parametrize("name", ["mirror", "figure"])
def test_confidence_is_calibrated_on_an_exact_symmetry(name, request):
    """The calibration tables (fitted on the TOSCA poses) on generated shapes whose
    symmetry is known exactly: the bent ellipsoid's mirror, and the posed figure's (the
    best of its three maps). Measured at this size, seeds 0 and 1: 0.999-1.000 of the
    vertices within 0.05, mean confidence 0.970-0.975, expected calibration error
    0.025-0.030 (the tables promise a little less than such an exact map delivers)."""
    if name == "mirror":
        v, f, sym = request.getfixturevalue("mirror")
        truths = [sym]
    else:
        g = shapes.figure()
        v, f, truths = g.vertices, g.faces, g.symmetries
    mesh = Shape(v, f)
    result = intrinsym.detect((v, f), intrinsym.make_params(n_source=120, n_target=1500))
    vmap = result.symmetry_map()
    truth = max(truths, key=lambda t: evaluate.score_map(vmap, mesh, t).within(0.05))
    conf = result.symmetry_confidence()
    report, _ = evaluate.evaluation_report(
        result.marginals, result.source_point_vertex, result.target_point_vertex, vmap, mesh, truth, confidence=conf
    )
    c = report["confidence"]
    assert c["within"] == pytest.approx(report["map"]["within_0.05"]) and c["within"] >= 0.99, c
    assert c["confidence"] == pytest.approx(result.global_confidence(), abs=1e-6)
    assert c["expected_calibration_error"] <= 0.05 and abs(c["confidence"] - c["within"]) <= 0.05, c
    # every confidence in the top bins, where an exact map belongs
    assert sum(b["share"] for b in c["bins"][9:]) >= 0.9, c["bins"]


@pytest.mark.slow  # a detect at 150 / 1500, the size its scores were measured at (CI: -m slow)
def test_the_partial_shapes_limbs_map_onto_each_other_and_its_body_has_no_partner():
    """The generated partial shape (two identical limbs on an asymmetric body, no global
    symmetry): the dominant symmetry is the limb swap, and the symmetry map leaves the body
    without a partner (-1), scored by the partial-symmetry protocol. Measured at this size,
    seed 0: body unmapped 1.00, limb vertices within 0.10 of their partner 0.41 (0.44
    before the residual cut of the self map; 0.23 before the dominant map took the swap's
    inverse too; 0.00 when the identity decision gave no map). The self hypothesis, a
    slide of the nearly round body that keeps its distances on 0.95 of it, does not
    count: its images' median likeness rank is 0.34 (the extraction's 0.02)."""
    g = shapes.partial()
    mesh = Shape(g.vertices, g.faces)
    result = intrinsym.detect((g.vertices, g.faces), intrinsym.make_params(n_source=150, n_target=1500))
    assert result.global_symmetry is None and result.extraction.grown_symmetry.kind == "partial"
    assert result.info.self_map is not None and result.info.self_map.source == "extraction"
    assert result.extraction.dominant_index == 0 and result.extraction.symmetries[0].kind == "self map"
    truth = partial_truth.PartialTruth(g.symmetries[0], np.zeros(len(g.vertices)), np.sqrt(surface_area(mesh)))
    scores = partial_truth.score_partial(result.symmetry_map(), mesh, truth)
    assert scores.unpartnered_unmapped >= 0.95, scores
    assert scores.partnered_within_010 >= 0.35, scores
    # a partial symmetry's map takes the partial symmetries' table, not the global maps'
    conf = result.symmetry_confidence()
    mapped = result.symmetry_map() >= 0
    own = confidence.calibrated(result.symmetry_score(), table=confidence.PARTIAL_CALIBRATION)
    assert np.allclose(conf[mapped], own[mapped], atol=1e-6) and not conf[~mapped].any()


@pytest.mark.slow  # a detect at 150 / 1500, the size of the test above (CI: -m slow)
def test_the_partial_shape_with_a_limb_cut_away_has_no_partner_anywhere():
    """The generated partial shape with limb 2 cut away (its vertices and every triangle
    touching them removed, leaving a stump's boundary): the limb swap, its only
    symmetry, lost its other half, so no vertex has a partner and the symmetry map must
    be -1 everywhere. Measured at this size, seeds 0 and 1: no global symmetry, and the
    self hypothesis, a slide of the body mapping 0.76-0.94 of the vertices, does not
    count (median likeness rank 0.31-0.39 against ``SELF_LIKENESS`` 0.15; 0.36-0.41 on
    the coarser 3,741-vertex shape, ``partial(8)``, at 60 / 600 and 100 / 1000, seeds 0-2)."""
    g = shapes.partial()
    cut, used = cut_mesh(g.vertices, g.faces, np.asarray(g.labels) != 2)
    closed = [trimesh.Trimesh(m.vertices, m.faces, process=False).is_watertight for m in (g, cut)]
    assert closed == [True, False]  # the cut opened the stump
    result = intrinsym.detect(cut, intrinsym.make_params(n_source=150, n_target=1500))
    assert result.global_symmetry is None
    assert result.info.self_map is not None and result.info.self_map.source == "none"
    assert result.info.self_map.likeness["hypothesis 1"] > self_hypothesis.SELF_LIKENESS
    unit = np.sqrt(surface_area(cut))
    truth = partial_truth.PartialTruth(np.full(len(used), partial_truth.NO_PARTNER), np.full(len(used), np.inf), unit)
    scores = partial_truth.score_partial(result.symmetry_map(), cut, truth)
    assert scores.unpartnered_unmapped == 1.0 and scores.n_partnered == 0, scores
