"""Peak tracking and region growing on hand-made marginals over a circle.

The shape is a circle of circumference 1: T = 40 targets 0.025 apart (target i at arc
length i / 40) and S = 10 source samples at targets 0, 4, ..., 36, joined in a cycle by
edges of length 0.1. Geodesics are arc lengths, so every expected map is known exactly:
the identity sends sample i to target 4i, the mirror about the axis through targets 2
and 22 sends it to (4 - 4i) mod 40 (no sample is a fixed point).
"""

import dataclasses

import numpy as np
import pytest

from intrinsym.extract import _kernels
from intrinsym.extract.extract import (
    MERGE_AGREEMENT,
    _merge,
    complete,
    consistency,
    extract,
    grow,
    mapped_symmetry,
    nearest_targets,
    normalise_rows,
    peaks,
    query,
    refine,
)
from intrinsym.extract.support import SourceGraph, Support
from intrinsym.extract.symmetry import Extraction, ExtractParams, Symmetry, with_inverse
from intrinsym.geodesics.geodesics import SparseDistances
from intrinsym.globalmap.confidence import kept_mass, map_mass, mass_within, sample_images
from intrinsym.globalmap.vertex_maps import fitted_vertex_map, vertex_map

T, S = 40, 10
IDENTITY = 4 * np.arange(S)
MIRROR = (4 - 4 * np.arange(S)) % T


def circle_targets(radius: float = 0.2) -> SparseDistances:
    ptr, idx, dist = [0], [], []
    for i in range(T):
        d = np.abs(np.arange(T) - i)
        d = np.minimum(d, T - d) / T
        keep = np.flatnonzero(d <= radius + 1e-12)
        order = keep[np.argsort(d[keep], kind="stable")]
        idx.extend(order)
        dist.extend(d[order])
        ptr.append(len(idx))
    return SparseDistances(np.array(ptr), np.array(idx), np.array(dist), radius)


TARGETS = circle_targets()
EDGES = np.array([[i, (i + 1) % S] for i in range(S)])
EDGES.sort(axis=1)
GRAPH = SourceGraph.from_edges(EDGES, np.full(S, 0.1), S)
SELF = IDENTITY.copy()


def marginals(mirror_value=0.8, mirror=MIRROR, with_mirror=None):
    """Identity peak 1.0, mirror peak ``mirror_value`` (rows in ``with_mirror``), floor 0.01."""
    m = np.full((S, T), 0.01)
    m[np.arange(S), IDENTITY] = 1.0
    rows = np.arange(S) if with_mirror is None else np.asarray(with_mirror)
    m[rows, mirror[rows]] = np.maximum(m[rows, mirror[rows]], mirror_value)
    return m / m.sum(axis=1, keepdims=True)


def test_source_graph_csr():
    assert GRAPH.ptr.tolist() == [2 * i for i in range(S + 1)]
    assert sorted(GRAPH.neighbour[GRAPH.ptr[0] : GRAPH.ptr[1]].tolist()) == [1, 9]
    assert np.all(GRAPH.length == 0.1)


def test_consistency_counts_the_edges_a_map_keeps():
    assert consistency(IDENTITY, GRAPH, TARGETS, 0.02) == 1.0 and consistency(MIRROR, GRAPH, TARGETS, 0.02) == 1.0
    # sample 3 one target along: its two edges become 0.125 and 0.075 long
    moved = IDENTITY.copy()
    moved[3] += 1
    assert consistency(moved, GRAPH, TARGETS, 0.02) == 0.8 and consistency(moved, GRAPH, TARGETS, 0.03) == 1.0
    # an unmapped sample's edges do not count
    moved[3] = -1
    assert consistency(moved, GRAPH, TARGETS, 0.02) == 1.0
    # identity on one half, mirror on the other: the two seams are 0.2 long
    fold = np.where(np.arange(S) < 5, IDENTITY, MIRROR)
    assert consistency(fold, GRAPH, TARGETS, 0.05) == 0.8
    assert consistency(np.full(S, -1), GRAPH, TARGETS, 0.02) == 1.0


def test_peaks_threshold_and_suppression():
    row = np.zeros(T)
    row[[3, 4, 20, 30]] = [0.9, 1.0, 0.6, 0.4]
    # 3 is within 0.05 of the stronger 4; 30 is below half the maximum
    assert peaks(row, TARGETS, 0.5, 0.05).tolist() == [4, 20]
    assert peaks(row, TARGETS, 0.75, 0.05).tolist() == [4]
    assert peaks(row, TARGETS, 0.5, 0.0).tolist() == [4, 3, 20]


def test_grow_recovers_the_mirror_and_the_identity():
    norm = normalise_rows(marginals())
    params = ExtractParams(threshold=0.5, d_error=0.01)
    assert grow(norm, GRAPH, TARGETS, 1, MIRROR[1], params).tolist() == MIRROR.tolist()
    assert grow(norm, GRAPH, TARGETS, 1, IDENTITY[1], params).tolist() == IDENTITY.tolist()


def test_grow_stops_at_geodesic_error_and_threshold():
    # sample 3's mirror peak is displaced by 2 targets (0.05): the edges 2-3 and 3-4
    # then map to lengths 0.05 and 0.15 instead of 0.1 (error 0.05)
    shifted = MIRROR.copy()
    shifted[3] = (MIRROR[3] + 2) % T
    norm = normalise_rows(marginals(mirror=shifted, with_mirror=[0, 1, 2, 3]))
    strict = grow(norm, GRAPH, TARGETS, 1, MIRROR[1], ExtractParams(threshold=0.5, d_error=0.03))
    assert np.flatnonzero(strict >= 0).tolist() == [0, 1, 2]
    loose = grow(norm, GRAPH, TARGETS, 1, MIRROR[1], ExtractParams(threshold=0.5, d_error=0.06))
    assert np.flatnonzero(loose >= 0).tolist() == [0, 1, 2, 3]
    assert loose[3] == shifted[3]
    # a mirror peak of 0.6 passes t = 0.5 but not t = 0.75
    norm = normalise_rows(marginals(mirror_value=0.6, with_mirror=[1, 2, 3, 4]))
    for threshold, grown in ((0.5, [1, 2, 3, 4]), (0.75, [1])):
        params = ExtractParams(threshold=threshold, d_error=0.01)
        assert np.flatnonzero(grow(norm, GRAPH, TARGETS, 1, MIRROR[1], params) >= 0).tolist() == grown


def test_query_returns_every_part_pair_with_kinds():
    parts = query(marginals(), GRAPH, TARGETS, 2, ExtractParams(d_error=0.01), self_target=SELF)
    assert sorted(p.kind for p in parts) == ["identity", "partial"]
    mirror = next(p for p in parts if p.kind == "partial")
    assert mirror.source.tolist() == list(range(S))
    assert mirror.target.tolist() == MIRROR.tolist()
    assert mirror.consistency == 1.0
    # score: every row at normalised 0.8, all edges consistent
    assert mirror.score == pytest.approx(0.8, rel=1e-6)
    # without self positions there is no identity kind
    assert {p.kind for p in query(marginals(), GRAPH, TARGETS, 2)} == {"partial"}


def test_extract_separates_identity_and_finds_the_global_mirror():
    result = extract(marginals(), GRAPH, TARGETS, ExtractParams(d_error=0.01), self_target=SELF)
    assert [s.kind for s in result.symmetries] == ["global"]
    assert result.global_index == 0 and result.global_symmetry is result.symmetries[0]
    assert result.symmetries[0].target.tolist() == MIRROR.tolist()
    both = extract(marginals(), GRAPH, TARGETS, ExtractParams(d_error=0.01, keep_identity=True), self_target=SELF)
    assert sorted(s.kind for s in both.symmetries) == ["global", "identity"]


def test_extraction_global_symmetry_follows_global_index():
    a = Symmetry(np.arange(3), np.arange(3), 0.5, 1.0, "partial")
    b = Symmetry(np.arange(4), np.arange(4) + 1, 0.4, 1.0, "global")
    params = ExtractParams()
    assert Extraction([a, b], 1, params).global_symmetry is b
    assert Extraction([a, b], -1, params).global_symmetry is None
    assert Extraction([], -1, params).global_symmetry is None


def test_the_dominant_symmetry_is_the_global_one_else_the_widest_partial():
    a = Symmetry(np.arange(3), np.arange(3) + 1, 0.5, 1.0, "partial")
    b = Symmetry(np.arange(5), np.arange(5) + 1, 0.4, 1.0, "partial")
    c = Symmetry(np.arange(2), np.arange(2) + 1, 0.3, 1.0, "global")
    same = Symmetry(np.arange(5) + 1, np.arange(5), 0.2, 1.0, "partial")
    identity = Symmetry(np.arange(9), np.arange(9), 0.9, 1.0, "identity")
    params = ExtractParams()
    assert Extraction([a, b, c], 2, params).dominant_symmetry is c
    assert Extraction([identity, a, b, same], -1, params).dominant_index == 2  # the best ranked of equals
    assert Extraction([identity], -1, params).dominant_symmetry is None
    assert Extraction([], -1, params).dominant_index == -1
    # detect's partial symmetry map is dominant wherever it stands; the marginals' own stays the grown one
    kept = Symmetry(np.arange(2), np.arange(2) + 3, 0.1, 1.0, "self map")
    found = Extraction([identity, a, b, kept], -1, params)
    assert found.dominant_symmetry is kept and found.grown_symmetry is b
    assert Extraction([kept], -1, params).grown_index == -1
    assert Extraction([a, b, c], 2, params).grown_symmetry is c


def test_a_dense_map_on_the_samples():
    # ten input vertices, two per source sample's cell (vertex 2i and 2i+1 in sample i's);
    # the targets' cells hold vertex v in target v // 2 * 4 (the source samples' places)
    support = Support(np.full(S, 0.1), TARGETS, np.arange(2 * S) // 2, np.arange(2 * S) // 2 * 4, True)
    source_vertex = 2 * np.arange(S)
    vmap = np.full(2 * S, -1)
    vmap[source_vertex] = 2 * ((1 - np.arange(S)) % S)  # the mirror sends sample i to sample 1 - i
    vmap[source_vertex[7]] = -1  # no partner
    sym = mapped_symmetry(vmap, source_vertex, EDGES, support, ExtractParams())
    assert sym.kind == "self map" and sym.source.tolist() == [0, 1, 2, 3, 4, 5, 6, 8, 9]
    assert np.array_equal(sym.target, MIRROR[sym.source]) and sym.consistency == 1.0
    assert sym.score == pytest.approx(0.9)
    # one sample sent one sample along: its two edges of eight mapped break
    vmap[source_vertex[3]] = 2 * ((1 - 3 + 1) % S)
    moved = mapped_symmetry(vmap, source_vertex, EDGES, support, ExtractParams())
    assert moved.consistency == pytest.approx(6 / 8) and moved.score == pytest.approx(0.9 * 6 / 8)
    # stored and read back with its kind
    arrays = Extraction([moved], -1, ExtractParams()).to_arrays()
    assert Extraction.from_arrays(arrays, ExtractParams(), S, T).symmetries[0].kind == "self map"


def test_with_inverse_covers_the_other_side_of_a_one_sided_part():
    # samples on a line at x = 0..9 and targets at the same places; the part sends 0, 1, 2
    # to 9, 8, 7: its inverse sends 7, 8, 9 back (the nearest image decides), and 5 stays out
    points = np.column_stack([np.arange(10.0), np.zeros(10), np.zeros(10)])
    part = Symmetry(np.array([0, 1, 2]), np.array([9, 8, 7]), 0.3, 1.0, "partial")
    both = with_inverse(part, points, points, 0.5)
    assert both.source.tolist() == [0, 1, 2, 7, 8, 9] and both.target.tolist() == [9, 8, 7, 2, 1, 0]
    assert (both.score, both.kind) == (0.3, "partial")
    # images farther than the radius from every sample add nothing
    assert with_inverse(part, points, points + [0.0, 1.0, 0.0], 0.5).source.tolist() == [0, 1, 2]


def test_extract_partial_symmetry_is_not_global():
    m = marginals(with_mirror=[1, 2, 3])
    result = extract(m, GRAPH, TARGETS, ExtractParams(d_error=0.01), self_target=SELF)
    assert result.global_index == -1 and result.global_symmetry is None
    assert [s.source.tolist() for s in result.symmetries] == [[1, 2, 3]]
    assert result.symmetries[0].kind == "partial"
    assert extract(m, GRAPH, TARGETS, ExtractParams(d_error=0.01, min_fraction=0.4), self_target=SELF).symmetries == []


def test_grow_rejects_an_image_that_most_mapped_neighbours_contradict():
    """With chords (i ~ i+2, length 0.2) every sample has four neighbours. Sample 5's
    only peak is target 12, the image of sample 3: it keeps the length to sample 4
    (parent, 0.1) but not to 3, 6 or 7. A blend of two maps looks like this; the
    growing leaves 5 unmapped rather than take it."""
    edges = np.array([[i, (i + k) % S] for i in range(S) for k in (1, 2)])
    edges.sort(axis=1)
    graph = SourceGraph.from_edges(edges, np.tile([0.1, 0.2], S), S)
    m = np.full((S, T), 0.01, dtype=np.float32)  # grow's float32 rows (as normalise_rows gives them)
    m[np.arange(S), IDENTITY] = 1.0
    m[5, IDENTITY[5]], m[5, 12] = 0.01, 1.0
    image = grow(m, graph, TARGETS, 0, 0, ExtractParams(d_error=0.01))
    assert image[5] == -1
    assert np.array_equal(np.delete(image, 5), np.delete(IDENTITY, 5))


def test_complete_fills_a_gap_by_geometry_alone():
    # sample 4 has no mirror peak; its mapped neighbours 3 and 5 pin its image
    norm = normalise_rows(marginals(with_mirror=[0, 1, 2, 3, 5, 6, 7, 8, 9]))
    params = ExtractParams(d_error=0.01)
    grown = grow(norm, GRAPH, TARGETS, 1, MIRROR[1], params, SELF)
    assert grown[4] == -1 and np.sum(grown >= 0) == 9
    assert complete(norm, GRAPH, TARGETS, grown, params).tolist() == MIRROR.tolist()
    # a sample with a single mapped neighbour stays open
    lone = np.where(np.arange(S) <= 3, MIRROR, -1)
    assert complete(norm, GRAPH, TARGETS, lone, params).tolist() == lone.tolist()
    result = extract(norm, GRAPH, TARGETS, params, self_target=SELF)
    assert result.symmetries[result.global_index].target.tolist() == MIRROR.tolist()


ROTATION = (IDENTITY + 8) % T  # turns the circle by a fifth: another isometry


def test_unary_peaks_seed_the_symmetries_bp_lost():
    """Marginals that kept only the mirror, a unary that also has the rotation: the
    rotation is found from the unary's peaks, scored on the marginals; the unary's copy
    of the mirror is dropped, not merged, so the mirror stays the marginals' own."""
    m = marginals()
    u = marginals(mirror=ROTATION)
    p = ExtractParams(d_error=0.01)
    alone = extract(m, GRAPH, TARGETS, p, self_target=SELF)
    both = extract(m, GRAPH, TARGETS, p, self_target=SELF, unary=u)
    assert [s.target.tolist() for s in alone.symmetries] == [MIRROR.tolist()]
    assert [s.target.tolist() for s in both.symmetries] == [MIRROR.tolist(), ROTATION.tolist()]
    assert [s.kind for s in both.symmetries] == ["global", "partial"]
    assert both.symmetries[1].score < 0.05 < both.symmetries[0].score  # the marginals barely support it
    # the parameter turns the extra seeds off
    off = extract(m, GRAPH, TARGETS, ExtractParams(d_error=0.01, unary_seeds=False), self_target=SELF, unary=u)
    assert [s.target.tolist() for s in off.symmetries] == [MIRROR.tolist()]
    # a partial mirror in the marginals is not extended by the unary's full mirror
    part = extract(marginals(with_mirror=[1, 2, 3]), GRAPH, TARGETS, p, self_target=SELF, unary=m)
    assert [s.source.tolist() for s in part.symmetries] == [[1, 2, 3]]
    # query: the rotation appears among the chosen point's parts
    images = {tuple(s.target.tolist()) for s in query(m, GRAPH, TARGETS, 2, p, SELF, unary=u)}
    assert tuple(ROTATION.tolist()) in images and tuple(MIRROR.tolist()) in images


def test_a_map_grown_where_the_marginals_hold_no_peak_is_not_global():
    """Marginals with the identity alone (every point "has no partner"), a unary with a
    full rotation: the rotation is extracted from the unary's seeds but, its pairs far
    below the marginals' peaks, it is not the shape's global symmetry."""
    p = ExtractParams(d_error=0.01)
    identity_only = marginals(with_mirror=np.zeros(0, np.int64))
    result = extract(identity_only, GRAPH, TARGETS, p, self_target=SELF, unary=marginals(mirror=ROTATION))
    assert [(s.target.tolist(), s.kind) for s in result.symmetries] == [(ROTATION.tolist(), "partial")]
    assert result.global_index == -1
    # marginals that do peak on it make it global
    result = extract(marginals(mirror=ROTATION), GRAPH, TARGETS, p, self_target=SELF)
    assert result.global_index == 0 and result.symmetries[0].kind == "global"


def test_the_unary_does_not_grow_where_the_marginals_say_no_partner():
    """Marginals that keep the mirror on samples 0-2 and the identity elsewhere (the
    trivial match kept at a weight: "no partner"), a unary with a full rotation: the
    rotation grown from the unary's seeds stays on 0-2 with ``no_partner``."""
    m = np.full((S, T), 0.01)
    m[np.arange(S), IDENTITY] = 1.0
    m[:3, IDENTITY[:3]] = 0.3
    m[np.arange(3), MIRROR[:3]] = 1.0
    u = marginals(mirror=ROTATION)
    found = {}
    for flag in (False, True):
        result = extract(m, GRAPH, TARGETS, ExtractParams(d_error=0.01, no_partner=flag), self_target=SELF, unary=u)
        found[flag] = [s.source.tolist() for s in result.symmetries if s.target.tolist() == ROTATION[s.source].tolist()]
    assert found == {False: [list(range(S))], True: [[0, 1, 2]]}


def test_later_passes_add_their_modes_scored_on_their_own_marginals():
    """Pass 1 kept the mirror, pass 2 (mirror removed) the rotation: both are extracted,
    each scored on its own pass; the unary of pass 2 seeds what neither pass kept."""
    p = ExtractParams(d_error=0.01)
    first, second = marginals(), marginals(mirror=ROTATION)
    alone = extract(first, GRAPH, TARGETS, p, self_target=SELF)
    both = extract(first, GRAPH, TARGETS, p, self_target=SELF, passes=[(second, second)])
    assert [s.target.tolist() for s in alone.symmetries] == [MIRROR.tolist()]
    assert sorted(s.target.tolist() for s in both.symmetries) == sorted([MIRROR.tolist(), ROTATION.tolist()])
    scores = {tuple(s.target.tolist()): s.score for s in both.symmetries}
    assert scores[tuple(ROTATION.tolist())] == pytest.approx(scores[tuple(MIRROR.tolist())])
    # a third map only in the second pass's unary, seeded with unary_seeds
    turn = (IDENTITY + 16) % T
    seeded = extract(first, GRAPH, TARGETS, p, self_target=SELF, unary=first, passes=[(second, marginals(mirror=turn))])
    assert tuple(turn.tolist()) in {tuple(s.target.tolist()) for s in seeded.symmetries}
    images = {tuple(s.target.tolist()) for s in query(first, GRAPH, TARGETS, 2, p, SELF, passes=[(second, second)])}
    assert {tuple(MIRROR.tolist()), tuple(ROTATION.tolist())} <= images
    # at most max_count symmetries per pass
    capped = extract(
        first, GRAPH, TARGETS, dataclasses.replace(p, max_count=1), self_target=SELF, passes=[(second, second)]
    )
    assert len(capped.symmetries) == 2


def test_merge_joins_agreeing_maps_only():
    p = ExtractParams(d_error=0.01)
    left = np.where(np.arange(S) <= 5, MIRROR, -1)
    right = np.where(np.arange(S) >= 4, MIRROR, -1)
    rotated = np.where(np.arange(S) >= 4, (IDENTITY + 8) % T, -1)
    groups = _merge([left, right, rotated], GRAPH, TARGETS, p)
    assert len(groups) == 2
    assert any(g.tolist() == MIRROR.tolist() for g in groups)
    # adjacent but not overlapping parts of one map merge across the edge 5-6
    groups = _merge(
        [np.where(np.arange(S) <= 5, MIRROR, -1), np.where(np.arange(S) >= 6, MIRROR, -1)], GRAPH, TARGETS, p
    )
    assert [g.tolist() for g in groups] == [MIRROR.tolist()]


def test_agreement_that_stops_early_decides_as_the_full_count():
    """Against the full count (share 0): the early stop of the merge's agreement test
    gives the same decision on random partial maps of the circle, and the same counts
    whenever the maps agree."""
    rng = np.random.default_rng(0)
    t = TARGETS
    args = (GRAPH.ptr, GRAPH.neighbour, GRAPH.length, t.indptr, t.indices, t.dist, 0.03, 0.05)
    base = [IDENTITY, MIRROR, (IDENTITY + 8) % T]
    stopped = 0
    for _ in range(400):
        a, b = (np.where(rng.random(S) < 0.7, (base[rng.integers(3)] + rng.integers(-1, 2, S)) % T, -1) for _ in "ab")
        full = _kernels.edge_agreement(a, b, False, *args)
        early = _kernels.edge_agreement(a, b, False, *args, MERGE_AGREEMENT)
        decide = [bool(g and g >= MERGE_AGREEMENT * (g + d)) for g, d in (full, early)]
        assert decide[0] == decide[1]
        if decide[0]:
            assert early == full
        stopped += early != full
    assert stopped > 50  # the early stop is exercised


def test_vertex_map_and_nearest_targets():
    sym = query(marginals(), GRAPH, TARGETS, 2, ExtractParams(d_error=0.01))
    mirror = next(s for s in sym if s.target.tolist() == MIRROR.tolist())
    vertex_source = np.array([0, 0, 3, -1, 9])
    target_vertex = 100 + np.arange(T)
    assert vertex_map(mirror, vertex_source, target_vertex, S).tolist() == [
        100 + MIRROR[0],
        100 + MIRROR[0],
        100 + MIRROR[3],
        -1,
        100 + MIRROR[9],
    ]
    angle = 2 * np.pi * np.arange(T) / T
    pts = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(T)]) / (2 * np.pi)
    assert nearest_targets(pts[IDENTITY] * 1.001, pts).tolist() == IDENTITY.tolist()


FIT = ExtractParams(vertex_fit=0.5)


def plane_mirror(image_of=None):
    """A 9 x 9 vertex grid on the unit square (z = 0), samples at every other vertex (a
    5 x 5 grid, edges of length 0.25), mirrored by x -> 1 - x. Returns the symmetry
    (``image_of`` overrides sample images), the support, the sample edges, the sample
    positions, the true vertex map and the vertex of every sample."""
    from scipy.spatial import cKDTree

    ij = np.array([(i, j) for i in range(9) for j in range(9)])
    vertices = np.column_stack([ij / 8.0, np.zeros(len(ij))])
    truth = (8 - ij[:, 0]) * 9 + ij[:, 1]
    sample_vertex = np.flatnonzero((ij % 2 == 0).all(axis=1))
    points = vertices[sample_vertex]
    n = len(points)
    image = np.array([np.flatnonzero(sample_vertex == truth[v])[0] for v in sample_vertex])
    if image_of is not None:
        image[list(image_of)] = list(image_of.values())
    d = np.linalg.norm(points[:, None] - points[None], axis=2)
    edges = np.array([(a, b) for a in range(n) for b in range(a + 1, n) if abs(d[a, b] - 0.25) < 1e-9])
    rows = [np.argsort(d[i], kind="stable") for i in range(n)]
    targets = SparseDistances(
        np.arange(n + 1) * n,
        np.concatenate(rows),
        np.concatenate([d[i, r] for i, r in enumerate(rows)]),
        float(d.max()),
    )
    cells = cKDTree(points).query(vertices + 1e-6)[1]  # ties broken towards the lower-left sample
    support = Support(np.full(len(edges), 0.25), targets, cells, cells, True, vertices, vertices)
    return Symmetry(np.arange(n), image, 1.0, 1.0, "global"), support, edges, points, truth, sample_vertex


def test_fitted_vertex_map_resolves_the_cells():
    """The exact mirror of the samples: cells send every vertex to its sample's image,
    the local linear fits to its own mirror image."""
    sym, support, edges, points, truth, sample_vertex = plane_mirror()
    cells = vertex_map(sym, support.vertex_source, sample_vertex, len(points))
    fitted = fitted_vertex_map(sym, support, edges, points, points, sample_vertex, FIT)
    assert np.mean(cells == truth) < 0.5
    assert fitted.tolist() == truth.tolist()
    # vertex_fit 0, or a support without vertex positions, gives the cell map
    assert (
        fitted_vertex_map(sym, support, edges, points, points, sample_vertex, ExtractParams(vertex_fit=0.0)).tolist()
        == cells.tolist()
    )
    bare = Support(support.edge_length, support.targets, support.vertex_source, support.vertex_target, True)
    assert fitted_vertex_map(sym, bare, edges, points, points, sample_vertex, FIT).tolist() == cells.tolist()


def test_fitted_vertex_map_keeps_the_cells_where_the_fit_fails():
    """The centre sample (12) mapped to a corner: its neighbours' fits leave residuals
    far above vertex_fit, so their cells keep their samples' images; cells two steps
    away are still fitted exactly."""
    sym, support, edges, points, truth, sample_vertex = plane_mirror(image_of={12: 0})
    cells = vertex_map(sym, support.vertex_source, sample_vertex, len(points))
    fitted = fitted_vertex_map(sym, support, edges, points, points, sample_vertex, FIT)
    near_centre = np.isin(support.vertex_source, [7, 11, 12, 13, 17])
    assert fitted[near_centre].tolist() == cells[near_centre].tolist()
    far = np.isin(support.vertex_source, [0, 4, 20, 24])
    assert fitted[far].tolist() == truth[far].tolist()


@pytest.mark.parametrize(
    "bad",
    [
        dict(threshold=0.0),
        dict(d_error=0.0),
        dict(global_fraction=2.0),
        dict(min_fraction=1.5),
        dict(max_count=0),
        dict(vertex_fit=-1.0),
    ],
)
def test_params_validated(bad):
    with pytest.raises(ValueError):
        ExtractParams(**bad)


def test_detect_writes_symmetries_and_query_answers_from_disk(tmp_path, capsys):
    """End to end on a tiny generated figure: files, query without BP, evaluate with labels."""
    import json
    import math
    import time

    from intrinsym import Result
    from intrinsym.app import cli
    from intrinsym.extract.extract import query_from_support
    from intrinsym.mesh import generated as shapes

    figure = shapes.figure(resolution=4)
    shapes.save(figure, tmp_path / "fig.off")
    out = tmp_path / "out"
    small = ["--source", "20", "--target", "200", "--iterations", "3", "--spin-cloud", "2000", "-q"]
    start = time.perf_counter()
    assert cli.main(["detect", str(tmp_path / "fig.off"), "-o", str(out), *small]) == 0
    wall = time.perf_counter() - start
    listed = json.loads((out / "symmetries.json").read_text())
    vmap = np.load(out / "symmetry_map.npy")
    assert vmap.dtype == np.int64 and vmap.shape == (len(figure.vertices),)
    assert all(s["kind"] in ("partial", "global") for s in listed)
    assert [s["kind"] for s in listed].count("global") == int(vmap.max() >= 0)
    for s in listed:
        pairs = np.array(s["pairs"])
        assert pairs.shape[1] == 2 and set(pairs[:, 0]) <= set(s["source_vertex_index"])
    result = Result.load(out)
    # the extraction stage is timed, and took part of the run's wall time
    seconds = json.loads((out / "run.json").read_text())["seconds"]
    assert math.isfinite(seconds["extract"]) and 0 < seconds["extract"] < wall

    # the query reads the saved arrays and grows from the sample whose cell holds the vertex
    sample = 3
    vertex = int(result.source_point_vertex[sample])
    expected = query_from_support(
        result.marginals,
        result.edges,
        result.support,
        result.source_points,
        result.target_points,
        sample,
        result.params.extraction(),
        unary=result.unary,
    )
    capsys.readouterr()
    assert cli.main(["query", str(out), "--vertex", str(vertex), "--json"]) == 0
    answer = json.loads(capsys.readouterr().out)
    assert answer["source_sample"] == sample
    assert [s["pairs"] for s in answer["symmetries"]] == [
        np.column_stack([result.source_point_vertex[e.source], result.target_point_vertex[e.target]]).tolist()
        for e in expected
    ]
    assert cli.main(["query", str(out), "--vertex", str(10**6)]) == 2

    assert (
        cli.main(
            [
                "evaluate",
                str(out),
                "--symmetry-map",
                str(tmp_path / "fig.sym.npy"),
                "--labels",
                str(tmp_path / "fig.labels.npy"),
                "--json",
            ]
        )
        == 0
    )
    report = json.loads((out / "scores.json").read_text())
    assert set(report["map"]["segmentation"]) == {"1", "2", "3", "4", "5"}
    assert (out / "curve.png").is_file()


def test_refine_trilaterates_misplaced_samples():
    p = ExtractParams(d_error=0.03)
    assert refine(GRAPH, TARGETS, MIRROR, p, min_neighbours=2).tolist() == MIRROR.tolist()
    # sample 3 placed 0.05 off its image: its neighbours' images put it back
    slid = MIRROR.copy()
    slid[3] = (MIRROR[3] - 2) % T
    assert refine(GRAPH, TARGETS, slid, p, min_neighbours=2).tolist() == MIRROR.tolist()
    # a mirror with fixed points (samples 0 and 5 on the axis through targets 0 and 20):
    # the removed trivial match pushes sample 0 off the axis; refining returns it
    fixed = (-4 * np.arange(S)) % T
    pushed = fixed.copy()
    pushed[0] = 4
    assert refine(GRAPH, TARGETS, pushed, p, min_neighbours=2).tolist() == fixed.tolist()
    # every sample has two neighbours: with three required nothing moves
    assert refine(GRAPH, TARGETS, pushed, p).tolist() == pushed.tolist()
    # unmapped samples stay unmapped and do not vote
    holes = slid.copy()
    holes[[2, 4]] = -1
    assert refine(GRAPH, TARGETS, holes, p, min_neighbours=2).tolist() == holes.tolist()


def test_confidence_is_the_marginal_mass_near_the_map():
    """Marginals that put 0.8 on each sample's mirror image and 0.2 on the sample itself
    (0.25 away and more): a map agreeing with the mirror keeps 0.8 within 0.1, the
    identity 0.2, and every vertex takes its sample's value."""
    sym, support, _, _, truth, sample_vertex = plane_mirror()
    n = len(sample_vertex)
    marginals = np.zeros((n, n))
    marginals[np.arange(n), sym.target] += 0.8
    marginals[np.arange(n), np.arange(n)] += 0.2
    image = sample_images(truth, sample_vertex, support.vertex_target)
    assert image.tolist() == sym.target.tolist()
    mirror = mass_within(marginals, image, support.targets, 0.1)
    on_line = sym.target == np.arange(n)  # the 5 samples on the fixed line x = 0.5
    assert np.allclose(mirror[~on_line], 0.8) and np.allclose(mirror[on_line], 1.0)
    assert kept_mass(marginals, np.arange(n), support.targets, 0.1) == pytest.approx((20 * 0.2 + 5) / 25)
    assert mass_within(marginals, np.full(n, -1), support.targets, 0.1).tolist() == [0.0] * n
    conf = map_mass(marginals, truth, sample_vertex, support, 0.1)
    assert conf.dtype == np.float32 and np.allclose(conf, mirror[support.vertex_source])
    assert map_mass(marginals, np.full(len(truth), -1), sample_vertex, support, 0.1).max() == 0.0
