"""A part's map from a consistent cluster of descriptor matches
(globalmap/part_hypothesis.py): the payoffs by hand, a planted cluster among random
matches found by the replicator dynamics, a marginal's peaks by hand, and the posed
figure's part located from its spin images and from marginals alone."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import part_of, right_share
from intrinsym.globalmap import part_hypothesis, part_map
from intrinsym.mesh.shape import from_arrays
from intrinsym.params import Params
from intrinsym.surface import prepare_pair


def test_the_payoffs_by_hand() -> None:
    # anchors at 0, 0.1 and 0.9 on a line (reach 0.5); matches: anchor 0 -> 0.0,
    # anchor 1 -> 0.12 and -> 0.3, anchor 2 -> 0.12 (anchor 1's first target)
    at = np.array([0.0, 0.1, 0.9])
    on_part = np.abs(at[:, None] - at[None])
    on_part[on_part >= 0.5] = np.inf
    anchor_of = np.array([0, 1, 1, 2])
    target_of = np.array([10, 11, 12, 11])
    image = np.array([0.0, 0.12, 0.3, 0.12])
    on_whole = np.abs(image[:, None] - image[None])
    payoff = part_hypothesis.match_payoffs(on_part, on_whole, anchor_of, target_of, 0.5, 0.05).toarray()
    expected = np.zeros((4, 4))
    # 0.1 against 0.12 pays exp(-0.08); 0.1 against 0.3 differs by four widths: nothing
    expected[0, 1] = expected[1, 0] = np.exp(-0.5 * (0.02 / 0.05) ** 2)
    # anchor 2 lies beyond reach of both others; 1 and 2 share an anchor, 1 and 3 a target
    np.testing.assert_allclose(payoff, expected)


def test_the_dynamics_find_a_planted_cluster() -> None:
    """40 anchors in a unit square, each with its image under a reflection and seven
    random images in a square nine times as large (the whole): the cluster is a patch
    of the reflection's matches, one per anchor. Only anchors within reach pay each other,
    so the dynamics settle on a patch whose pairs are mostly within reach (12-18 matches
    over seeds 0-7, every one right), not on all 40: the trilateration grows it."""
    rng = np.random.default_rng(0)
    n, k = 40, 8
    anchors = rng.uniform(0.0, 1.0, (n, 2))
    anchor_of = np.repeat(np.arange(n), k)
    images = rng.uniform(0.0, 3.0, (n * k, 2))
    right = np.arange(n) * k + rng.integers(0, k, n)
    images[right] = anchors * [-1.0, 1.0] + [2.0, 1.0]
    on_part = np.linalg.norm(anchors[:, None] - anchors[None], axis=2)
    on_part[on_part >= 0.5] = np.inf
    on_whole = np.linalg.norm(images[:, None] - images[None], axis=2)
    payoff = part_hypothesis.match_payoffs(on_part, on_whole, anchor_of, np.arange(n * k), 0.5, 0.05)
    assert (payoff != payoff.T).nnz == 0
    population = part_hypothesis.replicator_dynamics(payoff)
    assert population.sum() == pytest.approx(1.0)
    chosen = part_hypothesis.consistent_matches(population, anchor_of)
    assert len(chosen) >= 10 and np.isin(chosen, right).all()
    assert len(np.unique(anchor_of[chosen])) == len(chosen)
    # nothing pays anything: no population, no cluster
    empty = part_hypothesis.replicator_dynamics(payoff * 0.0)
    assert not empty.any() and len(part_hypothesis.consistent_matches(empty, anchor_of)) == 0


def test_a_hypothesis_locates_the_figures_part(figure_and_part) -> None:
    """The posed figure's part (one limb's end cut away), located from the first cluster
    of its spin-image matches alone, before any trilateration."""
    figure, used = figure_and_part
    a, b = prepare_pair(part_of(figure, used), from_arrays(figure.vertices, figure.faces), 0, "auto")
    descriptors = part_map.part_descriptors(a, b, Params())
    maps = part_hypothesis.hypothesis_maps(a, b, descriptors, 2)
    assert len(maps) == 2 and not np.array_equal(maps[0], maps[1])
    assert all(m.shape == used.shape and m.max() < len(figure.vertices) for m in maps)
    first = maps[0]
    assert np.array_equal(part_hypothesis.hypothesis_maps(a, b, descriptors, 1)[0], first)
    assert part_hypothesis.hypothesis_maps(a, b, descriptors, 0) == []
    assert (first >= 0).mean() >= 0.95
    assert right_share(figure, used, first) >= 0.9
    cloud = from_arrays(figure.vertices[used])
    with pytest.raises(ValueError, match="two meshes"):
        part_hypothesis.hypothesis_maps(*prepare_pair(cloud, from_arrays(figure.vertices), 0, "auto"), (None, None), 1)


def test_a_marginals_peaks_by_hand(figure_and_part) -> None:
    figure, used = figure_and_part
    a, b = prepare_pair(part_of(figure, used), from_arrays(figure.vertices, figure.faces), 0, "auto")
    on_whole = b.shape.vertices
    near, far = 288, 1  # vertex 0's nearest other vertex, and one past a match's tolerance
    gap = np.linalg.norm(on_whole[[near, far]] - on_whole[0], axis=1)
    assert gap[0] < part_map.PART_MAP_CHANGE < gap[1]
    source = np.array([10, 200])  # working vertices of the part
    marginals = np.zeros((2, len(on_whole)))
    marginals[0, [0, near, far]] = [1.0, 0.9, 0.8]
    marginals[1, [far, 0]] = [1.0, 0.5]
    labels = np.arange(len(on_whole))
    anchors = np.array([200, 10, 11])  # 11 lies nearest sample 10
    peaks = part_hypothesis.marginal_peaks(marginals, source, labels, a, b, anchors, 2)
    assert peaks.tolist() == [[far, 0], [0, far], [0, far]]
    # the labels 0 and ``near`` are one place: the row repeats it
    few = part_hypothesis.marginal_peaks(marginals[:, [0, near]], source, np.array([0, near]), a, b, anchors[:1], 3)
    assert few.tolist() == [[0, 0, 0]]


def test_a_hypothesis_from_marginals_alone(figure_and_part) -> None:
    """Marginals that put each sample's mass about its true image locate the figure's
    part without its descriptors."""
    figure, used = figure_and_part
    a, b = prepare_pair(part_of(figure, used), from_arrays(figure.vertices, figure.faces), 0, "auto")
    source = np.arange(0, len(used), 6)  # input vertices of the part
    labels = np.arange(len(figure.vertices))  # of the whole
    truth = b.shape.vertices[b.vertex_map[used[source]]]
    gaps = np.linalg.norm(truth[:, None, :] - b.shape.vertices[b.vertex_map[labels]][None, :, :], axis=2)
    marginals = np.exp(-0.5 * (gaps / 0.03) ** 2)
    marginals /= marginals.sum(axis=1, keepdims=True)
    given = (marginals, a.vertex_map[source], b.vertex_map[labels])
    maps = part_hypothesis.hypothesis_maps(a, b, (None, None), 1, marginals=given, proposals="marginals")
    assert len(maps) == 1 and (maps[0] >= 0).mean() >= 0.95
    assert right_share(figure, used, maps[0]) >= 0.9
    descriptors = part_map.part_descriptors(a, b, Params())
    both = part_hypothesis.hypothesis_maps(a, b, descriptors, 1, marginals=given, proposals="both")
    assert len(both) == 2 and np.array_equal(both[1], maps[0])
    assert np.array_equal(both[0], part_hypothesis.hypothesis_maps(a, b, descriptors, 1)[0])
    with pytest.raises(ValueError, match="needs the marginals"):
        part_hypothesis.hypothesis_maps(a, b, (None, None), 1, proposals="both")
    with pytest.raises(ValueError, match="proposals must be"):
        part_hypothesis.hypothesis_maps(a, b, (None, None), 1, marginals=given, proposals="peaks")
