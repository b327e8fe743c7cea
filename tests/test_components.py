"""Shapes of several connected components: a real scan's floating islands, two copies of one object."""

import numpy as np
import pytest

import intrinsym
from intrinsym.errors import ParameterError
from intrinsym.mesh import generated as shapes
from intrinsym.spectral import laplacian
from intrinsym.unary import descriptors


def copies(shape: shapes.GeneratedShape, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``k`` copies of ``shape`` side by side along x, far apart."""
    v, f = shape.vertices, shape.faces
    step = 3 * np.ptp(v, axis=0).max()
    return np.vstack([v + [step * i, 0, 0] for i in range(k)]), np.vstack([f + len(v) * i for i in range(k)])


@pytest.mark.parametrize("k", [2, 3])
def test_spectral_signatures_finite_with_several_components(k):
    star = shapes.star(arms=4, resolution=6)
    # whole eigenspaces only: each of the copy's first m eigenvalues k times, m where its
    # spectrum has a gap (the signatures of identical copies are equal then)
    one = laplacian.eigenpairs(star.vertices, star.faces, 12)[0]
    m = max(i for i in range(1, 9) if one[i + 1] > one[i] * (1 + 1e-6))
    v, f = copies(star, k)
    evals, evecs = laplacian.eigenpairs(v, f, 1 + k * m)
    assert descriptors.constant_modes(evals) == 1  # the components' constants but one left out
    energies, sigma = descriptors.wks_energies(evals, 20)
    wks = descriptors.wave_kernel_signature(evals, evecs, energies, sigma)
    hks = descriptors.heat_kernel_signature(evals, evecs, descriptors.hks_times(evals, 20))
    assert np.isfinite(energies).all() and np.isfinite(sigma) and np.isfinite(wks).all() and np.isfinite(hks).all()
    # identical copies have identical signatures
    n = len(v) // k
    np.testing.assert_allclose(wks[:n], wks[n : 2 * n], atol=1e-6)


def test_more_components_than_eigenpairs():
    # the eigenpairs leave the components' constants out: three copies, three pairs
    v, f = copies(shapes.star(arms=4, resolution=6), 3)
    evals, _ = laplacian.eigenpairs(v, f, 3)
    assert evals[0] == 0.0 and (evals[1:] > 0).all()
    assert descriptors.constant_modes(evals) == 1
    # a spectrum given as it is (another solver's) says when it has nothing but constants
    with pytest.raises(ParameterError, match="--eigenpairs"):
        descriptors.constant_modes(np.array([0.0, 0.0, 0.0]))


def test_detect_finds_the_symmetry_between_two_separate_copies():
    star = shapes.star(arms=5, resolution=6)
    v, f = copies(star, 2)
    n = len(star.vertices)
    result = intrinsym.detect((v, f), n_source=40, n_target=400, seed=0)
    assert np.isfinite(result.unary).all() and (result.unary > 0).all()
    # symmetric parts are found both ways, each within one copy and onto the other
    sv, tv = result.source_point_vertex, result.target_point_vertex
    sides = {(bool((sv[s.source] < n).all()), bool((tv[s.target] < n).all())) for s in result.extraction.symmetries}
    assert {(True, False), (False, True)} <= sides
    # the global symmetry sends the first copy's samples onto the second by one of the star's symmetries
    sym = result.global_symmetry
    src, dst = sv[sym.source], tv[sym.target]
    if (src >= n).all():
        src, dst = dst, src
    assert (src < n).all() and (dst >= n).all()
    size = np.ptp(star.vertices, axis=0).max()
    maps = np.vstack([np.arange(n), star.symmetries])
    near = [np.mean(np.linalg.norm(star.vertices[dst - n] - star.vertices[g[src]], axis=1) < 0.1 * size) for g in maps]
    assert max(near) > 0.8
    # and the global map carries the first copy onto the second
    assert np.mean(result.symmetry_map()[:n] >= n) > 0.9
