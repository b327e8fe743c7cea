"""The choice among a part's candidate maps into its whole (globalmap/part_map.py), on
hand-made candidates whose right choice is known: a flat square's left three quarters
mapped into the square by isometries (which change none of the part's distances), by a
map torn along a seam and by a random map."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import cut_mesh, unit_square_grid
from intrinsym.globalmap import part_map
from intrinsym.mesh.shape import from_arrays
from intrinsym.surface import prepare_pair

#: The square's grid: (N + 1) x (N + 1) vertices, vertex i * (N + 1) + j at (i / N, j / N).
N = 12


@pytest.fixture(scope="module")
def square_part():
    """The part (the columns i <= 8 of the square's grid, 117 vertices) and the whole (the
    square, 169), prepared, and candidate maps of the part's vertices into the whole's:

    - ``mirror``: (x, y) -> (x, 1 - y), an isometry of the square that maps the part onto
      itself, and ``shift``: (x, y) -> (x + 1/N, y), a translation that stays in the
      square; on the flat, convex grid both keep every distance, so they change none of
      the part's pairs (share exactly 0);
    - ``torn``: the part's lower half (j < N/2) translated 3 columns, the upper half left
      in place: the distances within each half are kept, those across the seam grow by up
      to 3/N = 0.25, far beyond ``PART_MAP_CHANGE``, so some of the pairs change (share
      above 0), yet no more than the pairs within ``PART_MAP_RADIUS`` of the seam;
    - ``random``: random images, which change most pairs;
    - ``none``: no image at all (its share NaN: it keeps nothing).
    """
    v, f = unit_square_grid(N)
    i, j = np.divmod(np.arange(len(v)), N + 1)
    part, used = cut_mesh(v, f, i <= 8)
    assert len(used) == 9 * (N + 1)
    a, b = prepare_pair(part, from_arrays(v, f), 0, "auto")
    lower = j[used] < N // 2
    maps = {
        "mirror": i[used] * (N + 1) + (N - j[used]),
        "shift": used + (N + 1),
        "torn": np.where(lower, used + 3 * (N + 1), used),
        "random": np.random.default_rng(0).integers(0, len(v), len(used)),
        "none": np.full(len(used), -1),
    }
    return a, b, maps


def test_least_distorted_picks_the_candidate_that_changes_the_fewest_distances(square_part) -> None:
    """least_distorted returns the candidate that changes the fewest of the part's
    distances: the isometry (share 0, whatever its place in the list) over the torn and
    the random map, the torn map over the random one, and a map with images over one with
    none (whose share counts as infinite); where no candidate gives an image, the first
    with share inf. A pick of the largest share instead returns the random map or the
    imageless one."""
    a, b, maps = square_part
    candidates = [maps[name] for name in ("random", "torn", "mirror", "none")]
    assert part_map.least_distorted(candidates, a, b) == (2, 0.0)
    assert part_map.least_distorted(candidates[::-1], a, b) == (1, 0.0)
    index, torn = part_map.least_distorted([maps["none"], maps["random"], maps["torn"]], a, b)
    assert index == 2 and 0.0 < torn < 0.5
    index, random = part_map.least_distorted([maps["none"], maps["random"]], a, b)
    assert index == 1 and torn < random < 1.0
    assert part_map.least_distorted([maps["none"], maps["none"]], a, b) == (0, np.inf)


def test_choose_part_map_replaces_the_extraction_only_by_a_less_distorted_map(square_part) -> None:
    """choose_part_map keeps the partial functional map's candidate only when it changes
    fewer of the part's distances than the extraction's: an isometry replaces a torn map,
    a torn map does not replace an isometry, and of two isometries (both share 0, a tie)
    the extraction's stays. Picking the more distorted candidate fails the first two."""
    a, b, maps = square_part
    image, stats = part_map.choose_part_map(maps["torn"], a, b, maps["mirror"])
    assert stats.source == "partial_fmap" and image is not None and np.array_equal(image, maps["mirror"])
    torn = stats.distortion["extraction"]
    assert torn is not None and torn > 0.0 and stats.distortion["partial_fmap"] == 0.0
    image, stats = part_map.choose_part_map(maps["mirror"], a, b, maps["torn"])
    assert image is None and stats == part_map.PartMapStats("extraction", {"extraction": 0.0, "partial_fmap": torn})
    image, stats = part_map.choose_part_map(maps["shift"], a, b, maps["mirror"])
    assert image is None and stats == part_map.PartMapStats("extraction", {"extraction": 0.0, "partial_fmap": 0.0})
