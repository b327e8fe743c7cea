"""Laplace-Beltrami eigenpairs: the analytic sphere, and the two-grid solve against the direct one."""

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from conftest import unit_sphere
from intrinsym.mesh import generated as shapes
from intrinsym.spectral import laplacian
from intrinsym.spectral.laplacian import COARSE_EXTRA, COARSE_PER_PAIR, FINE_PER_COARSE, eigenpairs, two_grid_eigenpairs


def test_sphere_eigenvalues_are_the_spherical_harmonic_ones():
    v, f = unit_sphere()
    evals, evecs = eigenpairs(v, f, 16)
    # Unit-area sphere, R^2 = 1 / (4 pi): lambda_l = l (l + 1) 4 pi with multiplicity 2l + 1.
    expected = np.repeat([l * (l + 1) * 4 * np.pi for l in range(4)], [1, 3, 5, 7])
    assert evals[0] == pytest.approx(0.0, abs=1e-8)
    np.testing.assert_allclose(evals[1:], expected[1:], rtol=0.01)
    mass = laplacian.laplace_beltrami(v, f)[1]
    np.testing.assert_allclose(evecs.T @ mass @ evecs, np.eye(16), atol=1e-8)


def test_point_cloud_spectrum_approximates_the_mesh_one():
    v, f = unit_sphere()
    mesh_evals = eigenpairs(v, f, 9)[0]
    cloud_evals = eigenpairs(v, None, 9)[0]
    np.testing.assert_allclose(cloud_evals[1:], mesh_evals[1:], rtol=0.05)


def test_eigenpairs_rejects_bad_k():
    v, f = unit_sphere(1)
    with pytest.raises(ValueError, match="k must"):
        eigenpairs(v, f, len(v))


def _span_miss(exact: np.ndarray, approx: np.ndarray, mass) -> np.ndarray:
    """Per exact M-orthonormal vector, 1 - the squared norm of its projection onto the
    span of the approximate ones (0 where it lies in that span)."""
    projection = exact.T @ (mass @ approx)
    return 1.0 - (projection**2).sum(axis=1)


def test_two_grid_matches_the_direct_solve_on_a_sphere():
    # 10,242 vertices decimated to 2,500; l <= 5 is 36 modes, whole eigenspaces, so
    # the subspaces compare exactly.
    v, f = unit_sphere(5)
    exact_vals, exact_vecs = eigenpairs(v, f, 36)
    vals, vecs = two_grid_eigenpairs(v, f, 36, 2500)
    mass = laplacian.laplace_beltrami(v, f)[1]
    np.testing.assert_allclose(vecs.T @ mass @ vecs, np.eye(36), atol=1e-8)
    assert vals[0] == 0.0
    np.testing.assert_allclose(vals[1:], exact_vals[1:], rtol=1e-5)
    assert _span_miss(exact_vecs, vecs, mass).max() < 1e-6
    expected = np.repeat([l * (l + 1) * 4 * np.pi for l in range(6)], [1, 3, 5, 7, 9, 11])
    np.testing.assert_allclose(vals[1:], expected[1:], rtol=0.01)


def test_two_grid_matches_the_direct_solve_on_a_figure():
    # A limbed shape without repeated eigenvalues: each Ritz value bounds its exact
    # eigenvalue from above and lies within 1e-3 of it.
    g = shapes.figure(30)
    k = 40
    exact_vals, exact_vecs = eigenpairs(g.vertices, g.faces, k)
    vals, vecs = two_grid_eigenpairs(g.vertices, g.faces, k, 3000)
    mass = laplacian.laplace_beltrami(g.vertices, g.faces)[1]
    assert np.all(vals[1:] >= exact_vals[1:] * (1 - 1e-9))
    np.testing.assert_allclose(vals[1:], exact_vals[1:], rtol=1e-3)
    assert _span_miss(exact_vecs[:, : k // 2], vecs, mass).max() < 1e-4


def test_eigenpairs_decimates_only_large_meshes_with_room_for_the_pairs():
    v, f = unit_sphere(4)  # 2,562 vertices: more than FINE_PER_COARSE times `enough` (1,120)
    k = 8
    enough = COARSE_PER_PAIR * (k + COARSE_EXTRA)
    assert len(v) > FINE_PER_COARSE * enough
    direct = eigenpairs(v, f, k)[0]
    # no more than FINE_PER_COARSE times the coarse size, too few coarse vertices per pair, a point
    # cloud, no coarse size: solved directly
    for faces, coarse in ((f, len(v) // FINE_PER_COARSE + 1), (f, enough - 1), (None, enough), (f, 0)):
        expected = direct if faces is not None else eigenpairs(v, None, k)[0]
        np.testing.assert_array_equal(eigenpairs(v, faces, k, coarse)[0], expected)
    two_grid = eigenpairs(v, f, k, enough)[0]
    np.testing.assert_array_equal(two_grid, two_grid_eigenpairs(v, f, k, enough)[0])
    assert not np.array_equal(two_grid, direct)


def test_two_grid_rejects_a_coarse_size_out_of_range():
    v, f = unit_sphere(3)
    with pytest.raises(ValueError, match="coarse must"):
        two_grid_eigenpairs(v, f, 16, 30)
    with pytest.raises(ValueError, match="coarse must"):
        two_grid_eigenpairs(v, f, 16, len(v))


def _copies(v: np.ndarray, f: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``k`` copies of a mesh side by side, far apart: ``k`` connected components."""
    step = 3 * np.ptp(v, axis=0).max()
    return np.vstack([v + [step * i, 0, 0] for i in range(k)]), np.vstack([f + len(v) * i for i in range(k)])


def _union_spectrum(evals: np.ndarray, copies: int, k: int) -> np.ndarray:
    """The k smallest eigenvalues of ``copies`` copies of a connected shape whose own are
    ``evals``, with one constant mode: each non-zero one repeated ``copies`` times."""
    return np.concatenate([[0.0], np.repeat(evals[1:], copies)])[:k]


@pytest.mark.parametrize("copies", [2, 3])
def test_several_components_give_one_constant_and_the_union_of_the_spectra(copies):
    # the spectrum of a disjoint union is the union of the spectra: each component's
    # non-constant eigenvalues, and its constant functions left out but one
    g = shapes.figure(10)
    one = eigenpairs(g.vertices, g.faces, 12)[0]
    v, f = _copies(g.vertices, g.faces, copies)
    evals, evecs = eigenpairs(v, f, 12)
    np.testing.assert_allclose(evals, _union_spectrum(one, copies, 12), rtol=1e-8, atol=1e-10)
    stiffness, mass = laplacian.laplace_beltrami(v, f)
    np.testing.assert_allclose(evecs.T @ mass @ evecs, np.eye(12), atol=1e-8)
    np.testing.assert_allclose(stiffness @ evecs, (mass @ evecs) * evals, atol=1e-8)
    np.testing.assert_allclose(evecs[:, 0], evecs[0, 0])  # the constant function, on every copy


@pytest.mark.slow  # a direct solve of 40 pairs on 27,000 vertices (CI: -m slow)
def test_two_grid_on_several_components_matches_the_direct_solve():
    g = shapes.figure(30)
    v, f = _copies(g.vertices, g.faces, 2)
    k = 40
    exact_vals, exact_vecs = eigenpairs(v, f, k)
    vals, vecs = two_grid_eigenpairs(v, f, k, 6000)
    mass = laplacian.laplace_beltrami(v, f)[1]
    assert vals[0] == 0.0 and np.count_nonzero(vals == 0.0) == 1
    np.testing.assert_allclose(vecs.T @ mass @ vecs, np.eye(k), atol=1e-8)
    np.testing.assert_allclose(vals[1:], exact_vals[1:], rtol=1e-3)
    assert _span_miss(exact_vecs[:, : k // 2], vecs, mass).max() < 1e-4


def test_eigenpairs_are_the_same_on_one_blas_thread_and_on_two():
    """ARPACK's sums split over OpenBLAS's threads: on the 10,242-vertex icosphere, whose
    eigenvalues repeat, two threads turn the eigenfunctions within their eigenspaces (by
    up to 1.2 at a vertex, measured with the solve unpinned); pinned, the caller's thread
    count changes no bit."""
    vertices, faces = unit_sphere(5)
    solved = []
    for threads in (1, 2):
        with threadpool_limits(threads, user_api="blas"):
            solved.append(eigenpairs(vertices, faces, 10))
            assert {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"} == {threads}
    assert np.array_equal(solved[0][0], solved[1][0]) and np.array_equal(solved[0][1], solved[1][1])
