"""End to end on generated shapes with known symmetry, at small size (issue 4).

Each star arm should find every other arm: the unary does, the BP marginals do not
(measured: loopy BP, serial or flooding, tolerance 0.5 or 1.5, 10 or 100 iterations,
keeps about one peak per source sample where the unary has about seven; it settles on
one of the star's 19 symmetries, or a blend of several). The failing properties are
strict xfails, so that a fix of BP shows up as XPASS.
"""

import numpy as np
import pytest

import intrinsym
from intrinsym import shapes

SMALL = dict(n_source=60, n_target=600, eigenpairs=40, spin_cloud=10000, iterations=10)


@pytest.fixture(scope="module")
def star():
    shape = shapes.star(5, resolution=4)
    return shape, intrinsym.detect((shape.vertices, shape.faces), **SMALL)


def best_on_arms(potentials: np.ndarray, result: intrinsym.Result, labels: np.ndarray) -> np.ndarray:
    """(k, k): row i holds, for the source sample farthest out on arm i, the largest
    value of its max-normalised row on each arm."""
    arm_s, arm_t = labels[result.source_vertex], labels[result.target_vertex]
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


@pytest.mark.xfail(strict=True, reason="loopy BP collapses the marginals onto one symmetry")
def test_star_extraction_maps_every_arm_onto_every_other(star):
    shape, result = star
    arm_s, arm_t = shape.labels[result.source_vertex], shape.labels[result.target_vertex]
    found = set()
    for sym in result.extraction.symmetries:
        for k in range(1, 6):
            images = arm_t[sym.target[arm_s[sym.source] == k]]
            counts = np.bincount(images, minlength=6)[1:]
            found |= {(k, j + 1) for j in np.flatnonzero(counts >= 0.5 * np.sum(arm_s == k))}
    missing = {(i, j) for i in range(1, 6) for j in range(1, 6) if i != j} - found
    assert not missing, f"arm pairs not found: {sorted(missing)}"
