"""A part's map from a consistent cluster of descriptor matches
(globalmap/part_hypothesis.py): the payoffs by hand, a planted cluster among random
matches found by the replicator dynamics, and the posed figure's part located from its
spin images."""

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
