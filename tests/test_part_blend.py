"""A part's candidate maps blended vertex by vertex (globalmap/part_blend.py), on a flat
square whose two candidate maps are each the identity on one half and scrambled on the
other: the blend is the identity away from the seam."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import unit_square_grid
from intrinsym.globalmap.distortion import LOCAL_RADIUS, LOCAL_SPACING
from intrinsym.globalmap.part_blend import blended_map
from intrinsym.mesh.shape import from_arrays
from intrinsym.surface import prepare_pair


@pytest.fixture(scope="module")
def square():
    v, f = unit_square_grid(24)
    shape = from_arrays(v, f)
    return v, prepare_pair(shape, shape, 0, "larger")


def test_the_blend_keeps_each_half_where_it_is_right(square) -> None:
    v, (a, b) = square
    n = len(v)
    identity = np.arange(n)
    scrambled = np.random.default_rng(0).permutation(n)
    left = v[:, 0] < 0.5
    first, second = np.where(left, identity, scrambled), np.where(left, scrambled, identity)
    blend = blended_map([first, second], a, b)
    # a vertex is measured from its nearest sample (within the spacing) over the pairs
    # within LOCAL_RADIUS of it: beyond that from the seam, one half's pairs alone
    away = np.abs(v[:, 0] - 0.5) > LOCAL_RADIUS + LOCAL_SPACING
    assert away.sum() > n / 2
    assert np.array_equal(blend[away], identity[away])
    assert blend.dtype == np.int64 and np.all((blend == first) | (blend == second))


def test_ties_unmeasured_vertices_and_no_maps(square) -> None:
    v, (a, b) = square
    identity = np.arange(len(v))
    shifted = np.roll(identity, 1)
    # equal distortion everywhere: the first map
    assert np.array_equal(blended_map([identity, identity.copy()], a, b), identity)
    assert np.array_equal(blended_map([shifted], a, b), shifted)
    # a map with no image is never chosen over one that measures
    assert np.array_equal(blended_map([np.full(len(v), -1), identity], a, b), identity)
    with pytest.raises(ValueError, match="at least one"):
        blended_map([], a, b)
