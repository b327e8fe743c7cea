"""A shape's partial symmetry map from its own descriptor matches
(globalmap/self_hypothesis.py): the residual of exact symmetries and of a map broken on
one arm, the cut by hand, the likeness ranks of the identity, of a symmetry and of a
random map, which maps count, and a SHREC'16 dog with holes, saved and summarised (slow);
spot with a leg cut away, the symmetry of what is there (slow, a strict xfail)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

import intrinsym
from conftest import cut_mesh, shared
from intrinsym.app import cli
from intrinsym.evaluation import partial_truth
from intrinsym.extract import part_mask
from intrinsym.globalmap import part_hypothesis, part_map, self_hypothesis
from intrinsym.mesh import generated as shapes
from intrinsym.mesh.shape import from_arrays, surface_area
from intrinsym.params import Params
from intrinsym.pipeline import self_matching
from intrinsym.surface import prepare


@pytest.fixture(scope="module")
def star():
    """The five-armed star (1,042 vertices; its 19 symmetries exact on the vertex grid),
    prepared as given, and its spin-image descriptors."""
    g = shapes.star(5, 8)
    surface = prepare(from_arrays(g.vertices, g.faces), 0)
    return g, surface, part_map.part_descriptors(surface, surface, Params())[0]


def test_an_exact_symmetry_changes_no_distance_and_a_broken_arm_has_no_partner(star) -> None:
    g, surface, _ = star
    identity = np.arange(len(g.vertices))
    assert np.abs(self_hypothesis.map_residual(identity, surface)).max() == 0.0
    rotation = g.symmetries[0]
    assert np.nanmax(self_hypothesis.map_residual(rotation, surface)) < 1e-9
    # arm 1's vertices all sent to arm 3's tip: their distances to the anchors around
    # them change; the arms two away from it keep the rotation's
    broken = rotation.copy()
    tip = int(np.argmax(np.where(g.labels == 3, np.linalg.norm(g.vertices[:, :2], axis=1), -1)))
    broken[g.labels == 1] = tip
    residual = self_hypothesis.map_residual(broken, surface)
    assert np.median(residual[g.labels == 1]) > self_hypothesis.SELF_RESIDUAL
    far = np.isin(g.labels, (3, 4))
    assert np.nanmax(residual[far]) < 1e-9
    unmapped = np.where(g.labels == 2, -1, rotation)
    assert np.isnan(self_hypothesis.map_residual(unmapped, surface)[g.labels == 2]).all()


def test_the_cut_by_hand() -> None:
    vertex_map = np.array([3, 2, 1, 0, 5])
    residual = np.array([0.0, 0.05, 0.051, np.nan, 0.01])
    assert self_hypothesis.residual_cut(vertex_map, residual).tolist() == [3, 2, -1, -1, 5]
    assert self_hypothesis.residual_cut(vertex_map, residual, 0.0).tolist() == [3, -1, -1, -1, -1]


def test_likeness_ranks_of_the_identity_a_symmetry_and_a_random_map(star) -> None:
    g, surface, descriptors = star
    n = len(g.vertices)
    assert not self_hypothesis.likeness_ranks(np.arange(n), surface, descriptors).any()
    # a symmetry's images have nearly their vertices' spin images (each vertex takes
    # that of its nearest sampled point, so not exactly)
    assert np.median(self_hypothesis.likeness_ranks(g.symmetries[0], surface, descriptors)) <= 0.05
    random = np.random.default_rng(0).integers(0, n, n)
    ranks = self_hypothesis.likeness_ranks(random, surface, descriptors)
    assert 0.35 <= np.median(ranks) <= 0.65
    ranks = self_hypothesis.likeness_ranks(np.where(g.labels == 1, -1, random), surface, descriptors)
    assert np.isnan(ranks[g.labels == 1]).all() and np.isfinite(ranks[g.labels != 1]).all()


def test_fixed_share_against_every_vertex(star) -> None:
    """The share of the vertices a map keeps within a radius of themselves, estimated on
    the samples, against the exact share over every vertex (Dijkstra from each)."""
    g, surface, _ = star
    graph = surface.chord_graph
    n = len(g.vertices)

    def exact(vertex_map: np.ndarray, radius: float) -> float:
        mapped = np.flatnonzero(vertex_map >= 0)
        d = dijkstra(graph, indices=mapped, limit=radius)
        return float(np.mean(d[np.arange(len(mapped)), vertex_map[mapped]] <= radius))

    assert self_hypothesis.fixed_share(np.arange(n), surface, 0.08) == 1.0
    assert self_hypothesis.fixed_share(np.full(n, -1), surface, 0.08) == 0.0
    rotation = g.symmetries[0]
    # the identity on the body (label 0) and two arms, a rotation elsewhere, one arm unmapped
    mixed = np.where(g.labels <= 2, np.arange(n), rotation)
    mixed[g.labels == 3] = -1
    for vertex_map in (rotation, mixed):
        for radius in (0.08, 0.2):
            share = self_hypothesis.fixed_share(vertex_map, surface, radius)
            assert share == pytest.approx(exact(vertex_map, radius), abs=0.05)
    assert self_hypothesis.fixed_share(rotation, surface, 0.08) < 0.2
    assert self_hypothesis.fixed_share(mixed, surface, 0.08) > 0.8


def test_which_map_counts(star, monkeypatch) -> None:
    """No hypotheses drawn: the extraction's map, cut where its residual is large,
    counts when its images look like their vertices; a random map is cut away, and a
    map whose images look less alike than the limit does not count."""
    g, surface, _ = star
    broken = g.symmetries[0].copy()
    broken[g.labels == 1] = int(np.flatnonzero(g.labels == 3)[0])
    kept, stats = self_hypothesis.self_symmetry_map(broken, surface, Params(), 0)
    assert stats.source == "extraction" and list(stats.mapped) == ["extraction"]
    likeness = stats.likeness["extraction"]
    assert likeness is not None and 0.0 < likeness <= self_hypothesis.SELF_LIKENESS
    assert (kept[g.labels == 1] == -1).mean() >= 0.9
    unbroken = g.labels != 1
    assert (kept[unbroken] == broken[unbroken]).mean() >= 0.9 and np.isin(kept, (-1, *broken)).all()
    assert stats.mapped["extraction"] == pytest.approx((kept >= 0).mean())
    random = np.random.default_rng(1).integers(0, len(g.vertices), len(g.vertices))
    none, stats = self_hypothesis.self_symmetry_map(random, surface, Params(), 0)
    assert stats.source == "none" and (none == -1).all()
    assert stats.mapped["extraction"] < 0.05
    # the identity keeps every distance and looks like itself: the trivial match does not count
    none, stats = self_hypothesis.self_symmetry_map(np.arange(len(g.vertices)), surface, Params(), 0)
    assert stats.source == "none" and stats.fixed["extraction"] == 1.0 and stats.likeness["extraction"] == 0.0
    monkeypatch.setattr(self_hypothesis, "SELF_LIKENESS", 0.5 * likeness)
    none, stats = self_hypothesis.self_symmetry_map(broken, surface, Params(), 0)
    assert stats.source == "none" and (none == -1).all() and stats.mapped["extraction"] > 0.5


def test_the_kept_map_returns_its_vertices(star, monkeypatch) -> None:
    """The star's reflection through arm 1 (arms 2 <-> 5, 3 <-> 4) with arm 2 sent onto
    arm 1 by the reflection that swaps those two, every residual said to be 0: arm 2's
    images come back on arm 1, arm 5's (on arm 2) on arm 1 too, far from where they
    started, so both lose their images as a global map's would; arms 1, 3 and 4 keep the
    reflection."""
    g, surface, _ = star
    reflection, swap = g.symmetries[4], g.symmetries[5]
    assert np.array_equal(reflection[reflection], np.arange(len(g.vertices)))
    mixed = np.where(g.labels == 2, swap, reflection)
    assert (g.labels[mixed[g.labels == 2]] == 1).all()
    monkeypatch.setattr(self_hypothesis, "map_residual", lambda vertex_map, surface: np.zeros(len(vertex_map)))
    kept, stats = self_hypothesis.self_symmetry_map(mixed, surface, Params(), 0)
    assert stats.source == "extraction" and stats.mapped["extraction"] == 1.0
    assert (kept[np.isin(g.labels, (2, 5))] == -1).all()
    others = np.isin(g.labels, (1, 3, 4))
    assert np.array_equal(kept[others], reflection[others])


def test_a_hypothesis_leaves_out_the_trivial_matches(star) -> None:
    """Matched to itself with the trivial matches left out, the star's first hypothesis
    is a symmetry, not the identity."""
    g, surface, descriptors = star
    maps = part_hypothesis.hypothesis_maps(surface, surface, (descriptors, descriptors), 1, 0.16)
    assert len(maps) == 1
    first = maps[0]
    located = first >= 0
    assert located.mean() >= 0.5 and (first[located] != np.arange(len(first))[located]).mean() >= 0.9
    with pytest.raises(ValueError, match="trivial"):
        part_hypothesis.hypothesis_maps(surface, surface, (descriptors, descriptors), 1, 0.5)


def test_a_global_map_that_is_the_trivial_match_gives_way(monkeypatch, tmp_path, capsys) -> None:
    """A global map more than TRIVIAL_SHARE of whose vertices stay put (here: said to) is
    demoted to an identity symmetry, and the shape takes the self map instead."""
    g = shapes.star(5, 5)
    small = intrinsym.make_params(n_source=30, n_target=300, spin_cloud=2000, iterations=20)
    shares: list[float] = []

    def stays_put(vertex_map: np.ndarray, surface, radius: float) -> float:
        shares.append(radius)
        return 0.9

    monkeypatch.setattr(self_matching, "fixed_share", stays_put)
    result = intrinsym.detect((g.vertices, g.faces), small)
    assert shares == [small.trivial_radius]  # asked once, of the global map
    assert result.global_symmetry is None and result.info.global_map is None and result.map_distortion is None
    assert result.info.self_map is not None and result.info.self_map.trivial_global == 0.9
    kinds = [sym.kind for sym in result.extraction.symmetries]
    assert "identity" in kinds and "global" not in kinds
    assert result.info.self_map.source == "none" or kinds[0] == "self map"
    cli._print_summary(cli._summary(result, result.save(tmp_path / "out")))
    assert "the global map is the trivial match (0.90 of its vertices stay put): the partial symmetry map is" in (
        capsys.readouterr().out
    )


@pytest.mark.slow  # a default detect of a 6,000-vertex SHREC'16 shape (CI: -m slow)
def test_a_dog_with_holes_gets_its_symmetry_and_no_partner_for_the_holes_mirrors(tmp_path, capsys) -> None:
    """holes_dog_shape_1 (SHREC'16; skipped without ``../shared/data``): no global
    symmetry, the extraction's map right within 0.10 on 0.31 of the partnered vertices.
    The hypothesis, kept, maps them within 0.10 on at least 0.8 and leaves the vertices
    whose mirror is in a hole unmapped (measured: 0.88 and 0.98)."""
    shape, truth = partial_truth.load_shrec16(shared("shrec16_partial/holes/holes_dog_shape_1.off"))
    result = intrinsym.detect(shape)
    assert result.global_symmetry is None and result.info.self_map is not None
    assert result.info.self_map.source == "hypothesis 1"
    scores = partial_truth.score_partial(result.symmetry_map(), shape, truth)
    assert scores.partnered_within_010 >= 0.8 and scores.unpartnered_unmapped >= 0.95, scores
    # the map kept ranks first among the symmetries, and its parts are the truth's partnered region
    assert result.extraction.dominant_index == 0 and result.extraction.symmetries[0].kind == "self map"
    assert np.array_equal(result.symmetry_maps()[0], result.symmetry_map())
    # saved and loaded: the same map and the same record of how it was chosen
    loaded = intrinsym.Result.load(result.save(tmp_path / "out"))
    assert np.array_equal(loaded.symmetry_map(), result.symmetry_map()) and loaded.info.self_map == result.info.self_map
    assert np.array_equal(np.load(tmp_path / "out" / "symmetry_map.npy"), result.symmetry_map())
    first = json.loads((tmp_path / "out" / "symmetries.json").read_text())[0]
    assert first["kind"] == "self map" and partial_truth.part_iou(part_mask(first, len(shape.vertices)), truth) >= 0.8
    cli._print_summary(cli._summary(result, tmp_path / "out"))
    assert "no global symmetry: the partial symmetry map is hypothesis 1 (vertices mapped: extraction" in (
        capsys.readouterr().out
    )


@pytest.mark.slow  # a default detect of a 7,000-vertex SHREC'16 shape (CI: -m slow)
def test_a_global_map_that_stays_put_on_a_shape_with_holes_gives_way_to_its_symmetry() -> None:
    """holes_michael_shape_10 (SHREC'16; skipped without ``../shared/data``): the global
    map the run finds is the identity (0.99 of its vertices within the trivial radius of
    themselves; within 0.10 of the partner on 0.33 of the partnered vertices). Demoted,
    the shape's hypothesis maps them within 0.10 on at least 0.85 and leaves the vertices
    whose mirror is in a hole unmapped on at least 0.9 (measured: 0.90 and 0.94)."""
    shape, truth = partial_truth.load_shrec16(shared("shrec16_partial/holes/holes_michael_shape_10.off"))
    result = intrinsym.detect(shape)
    stats = result.info.self_map
    assert stats is not None and stats.trivial_global is not None and stats.trivial_global >= 0.9
    assert stats.source == "hypothesis 1" and stats.fixed["hypothesis 1"] <= self_hypothesis.TRIVIAL_SHARE
    assert result.global_symmetry is None and result.extraction.symmetries[0].kind == "self map"
    scores = partial_truth.score_partial(result.symmetry_map(), shape, truth)
    assert scores.partnered_within_010 >= 0.85 and scores.unpartnered_unmapped >= 0.9, scores


@pytest.mark.slow  # a detect of the shipped spot at 150 / 1500 (CI: -m slow)
@pytest.mark.xfail(
    strict=True, raises=AssertionError, reason="the unary's WKS vetoes the partner with a leg cut: BP loses that end"
)
def test_spot_with_a_leg_cut_away_keeps_the_symmetry_of_what_is_there() -> None:
    """The shipped spot (mirror-symmetric in x to the vertex) with one leg cut away (the
    +x one at the +z end): the left/right symmetry of the rest, at the issue's targets
    (partnered within 0.10 on 0.90, unpartnered left unmapped on 0.85). Measured, seed 0:
    0.497 and 0.151 at this size, 0.516 and 0.783 at 250 / 4000; BP's argmax is right on
    every partnered sample at the far end (z <= -0.3) and on none at the cut leg's end
    (z > 0.2), while the complete spot's map is exact. The spin image alone with each row's own
    widths (``unary="spin", calibration="row"``) gets 0.94 within 0.05 here but loses the
    global map of posed complete shapes (docs/limitations.md, Incomplete shapes)."""
    whole = intrinsym.load(intrinsym.example_path())
    v, f = whole.vertices, whole.faces
    drop = (v[:, 0] > 0.05) & (v[:, 1] < -0.35) & (v[:, 2] > 0.2)
    shape, _ = cut_mesh(v, f, ~drop)
    unit = np.sqrt(surface_area(whole))
    truth = partial_truth.partner_truth(shape.vertices, shape.vertices * [-1.0, 1.0, 1.0], unit)
    assert 0.03 <= truth.unpartnered.mean() <= 0.05 and truth.partnered.mean() >= 0.9  # one leg's worth
    result = intrinsym.detect(shape, intrinsym.make_params(n_source=150, n_target=1500))
    scores = partial_truth.score_partial(result.symmetry_map(), shape, truth)
    assert scores.partnered_within_010 >= 0.9 and scores.unpartnered_unmapped >= 0.85, scores
