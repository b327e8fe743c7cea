"""A part's map trilaterated from its anchor core (globalmap/part_trilateration.py): the
core on a hand-checked line of anchors, the search against its dense argmin, and a
region of the posed figure's part mapped at random located again."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import part_of, right_share
from intrinsym.globalmap import part_map, part_trilateration
from intrinsym.mesh.shape import from_arrays
from intrinsym.surface import prepare_pair


def test_the_core_drops_the_anchor_whose_image_breaks_its_distances() -> None:
    # ten anchors 0.1 apart on a line; anchor 4's image lies 0.2 off along it
    position = np.arange(10) * 0.1
    image = position.copy()
    image[4] += 0.2
    on_part = np.abs(position[:, None] - position[None])
    on_whole = np.abs(image[:, None] - image[None])
    on_part[on_part >= 0.35] = np.inf
    core = part_trilateration.anchor_core(on_part, on_whole, 0.35, 0.05)
    # anchor 4 keeps its distance to none of its six neighbours within reach; once it is
    # gone every other anchor keeps all of its own
    assert np.array_equal(np.flatnonzero(~core), [4])
    # with every image right, every anchor stays
    assert part_trilateration.anchor_core(on_part, np.abs(position[:, None] - position[None]), 0.35, 0.05).all()


def _dense_best(on_part, on_whole, reach, start):
    """The dense search: every vertex of the whole costed, ties to ``start``, then to the
    lowest vertex."""
    found = start.copy()
    for x in range(on_part.shape[1]):
        near = np.flatnonzero(on_part[:, x] < reach)
        if len(near) < part_trilateration.MIN_ANCHORS:
            continue
        cost = np.abs(on_whole[:, near] - on_part[near, x]).sum(axis=1)
        if not np.isfinite(cost.min()) or (start[x] >= 0 and cost[start[x]] <= cost.min()):
            continue
        found[x] = np.argmin(cost)
    return found


@pytest.mark.parametrize("step", [0.0, 0.125], ids=["continuous", "ties"])
@pytest.mark.parametrize(
    "n_whole", [9 * part_trilateration._BLOCK + 12, part_trilateration._BLOCK - 1], ids=["blocks", "one-block"]
)
def test_the_search_is_the_dense_argmin(step, n_whole) -> None:
    """Against the dense search, on random distances and on distances rounded to 1/8
    (many exact ties, and sums exact in any order); the whole's vertices a few blocks
    and a last partial one, or fewer than one block, each block's first and last
    vertices planted as the answer."""
    rng = np.random.default_rng(0)
    n_anchors, n_part, reach = 12, 60, 0.5
    on_part = rng.uniform(0.0, 0.8, (n_anchors, n_part))
    on_whole = rng.uniform(0.0, 1.0, (n_whole, n_anchors))
    if step:
        on_part, on_whole = np.round(on_part / step) * step, np.round(on_whole / step) * step
    on_part[on_part >= reach] = np.inf
    on_whole[rng.random(on_whole.shape) < 0.1] = np.inf  # beyond the whole's horizon
    # part vertices from 1 on repeat the distances of the whole's first vertex, of the two
    # either side of the first block's end and of its last vertex exactly: found at cost 0
    block = part_trilateration._BLOCK
    planted = np.unique([0, block - 1, block, n_whole - 1] if n_whole > block else [0, n_whole - 1])
    for x, y in enumerate(planted, start=1):
        on_whole[y, :4] = np.minimum(on_whole[y, :4], 0.25)  # at least four anchors within reach
        on_part[:, x] = np.where(on_whole[y] < reach, on_whole[y], np.inf)
    start = rng.integers(-1, n_whole, n_part)
    start[1 : len(planted) + 1] = (planted + 1) % n_whole
    found = part_trilateration.best_images(on_part, np.ascontiguousarray(on_whole.T), reach, start)
    assert np.array_equal(found[1 : len(planted) + 1], planted)
    assert np.array_equal(found, _dense_best(on_part, on_whole, reach, start))
    # a vertex with no image that only infinite costs could locate keeps none
    on_whole[:, 0] = np.inf
    on_part[:, 0] = 0.1
    alone = part_trilateration.best_images(on_part, np.ascontiguousarray(on_whole.T), reach, np.full(n_part, -1))
    assert alone[0] == -1 and np.array_equal(alone, _dense_best(on_part, on_whole, reach, np.full(n_part, -1)))


def test_a_region_mapped_at_random_is_located_again(figure_and_part) -> None:
    """The figure's part mapped by the truth except on the 60 vertices nearest one end,
    which go anywhere: the least distorted round puts the part back within 0.10 of a
    symmetry of the truth, trilaterated_if_less_distorted keeps it, and its polish keeps
    it there; the true map stays as it is."""
    figure, used = figure_and_part
    a, b = prepare_pair(part_of(figure, used), from_arrays(figure.vertices, figure.faces), 0, "auto")
    rng = np.random.default_rng(0)
    end = np.linalg.norm(figure.vertices[used] - figure.vertices[used[0]], axis=1).argsort()[:60]
    broken = used.copy()
    broken[end] = rng.integers(0, len(figure.vertices), len(end))
    # measured: 0.86 -> 1.00 (seeds 1-3 of the random images: 0.85-0.88 -> 1.00)
    assert right_share(figure, used, broken) < 0.87
    _, stats = part_map.choose_part_map(broken, a, b)
    rounds = part_trilateration.trilaterated_maps(broken, a, b)
    assert len(rounds) == part_trilateration.TRILATERATION_ROUNDS
    located, kept = part_map.trilaterated_if_less_distorted(rounds, a, b, stats)
    assert located is not None and kept.trilaterated and kept.final == "trilaterated"
    assert kept.distortion["trilaterated"] < kept.distortion["extraction"]
    assert kept.kept == 1.0 - kept.distortion["trilaterated"]
    assert right_share(figure, used, located) >= 0.97
    # polished by ZoomOut, it stays right, and its own share is the one the confidence takes
    polished_map = part_map.refine_part_map(located, a, b)
    polished = part_map.with_polish(polished_map, a, b, kept)
    assert polished.polished and polished.final == "polished" and polished.trilaterated
    assert polished.kept == 1.0 - polished.distortion["polished"]
    assert right_share(figure, used, polished_map) >= 0.97
    # the true map keeps every distance: no round replaces it, and nothing is polished
    _, stats = part_map.choose_part_map(used.copy(), a, b)
    rounds = part_trilateration.trilaterated_maps(used.copy(), a, b)
    located, kept = part_map.trilaterated_if_less_distorted(rounds, a, b, stats)
    assert located is None and not kept.trilaterated and kept.final == "extraction"
    with pytest.raises(ValueError, match="trilaterated"):
        part_map.with_polish(used.copy(), a, b, kept)
    # too few images for the anchors: nothing to trilaterate
    few = np.full(len(used), -1)
    few[:10] = used[:10]
    assert part_trilateration.trilaterated_maps(few, a, b) == []
    assert part_map.trilaterated_if_less_distorted([], a, b, stats) == (None, stats)
