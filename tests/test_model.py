"""Unary (Eq. 5) and pairwise (Eq. 6) terms on hand-checked values."""

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from intrinsym.geodesics.geodesics import SparseDistances
from intrinsym.mrf.model import (
    condition_on_images,
    lambda_for_tolerance,
    pairwise_dense,
    suppress_peaks,
    suppress_trivial,
    truncation_width,
)
from intrinsym.spectral.laplacian import eigenpairs
from intrinsym.unary.descriptors import wave_kernel_signature, wks_energies
from intrinsym.unary.unary import calibrated_potential, descriptor_scale, nmi_potential, potential_floor, row_scales


def test_nmi_potential_paper_values():
    phi = nmi_potential(np.array([1.0, 0.0, 0.9]), gamma=0.01)
    assert phi[0] == 1.0
    assert phi[1] == pytest.approx(1 / 101)
    assert phi[2] == pytest.approx(0.5)  # (1 - 0.9)^2 / 0.01 = 1
    assert potential_floor(0.01) == pytest.approx(1 / 101)
    with pytest.raises(ValueError):
        nmi_potential(np.ones(2), gamma=0.0)


def test_truncation_ring_width():
    rho = 0.4
    lam = lambda_for_tolerance(0.02, rho)
    assert truncation_width(lam, rho) == pytest.approx(0.02)
    d = np.array([[0.1 + 0.02]])
    # psi equals the truncation exactly at the ring's edge
    assert pairwise_dense(0.1, d, lam, rho)[0, 0] == pytest.approx(rho**2)
    assert pairwise_dense(0.1, np.array([[0.1]]), lam, rho)[0, 0] == 1.0
    assert truncation_width(0.0, rho) == np.inf


def test_suppress_trivial():
    unary = np.full((2, 3), 0.5)
    dist = np.array([[0.0, 0.04, 0.2], [np.inf, 0.1, 0.01]])
    out = suppress_trivial(unary, dist, 0.05, 0.01)
    assert out.tolist() == [[0.01, 0.01, 0.5], [0.5, 0.5, 0.01]]
    assert unary[0, 0] == 0.5  # input untouched


def test_weighted_trivial_match_peaks_at_the_weight_times_the_rows_best_elsewhere():
    unary = np.array([[0.9, 0.6, 0.4, 0.2], [0.1, 0.3, 0.8, 0.05]])
    dist = np.array([[0.0, 0.03, 0.2, 0.3], [0.01, 0.3, 0.2, np.inf]])
    out = suppress_trivial(unary, dist, 0.05, 0.01, weight=0.5)
    # row 0: the identity's peak 0.9 goes to 0.5 * 0.4, its shape kept (0.6 -> 0.1333)
    assert out[0] == pytest.approx([0.2, 0.6 * 0.2 / 0.9, 0.4, 0.2])
    # row 1: 0.1 is below 0.5 * 0.8 already, and it is never raised
    assert out[1] == pytest.approx(unary[1])
    low = suppress_trivial(unary, dist, 0.05, 0.15, weight=0.5)
    assert low[0, 1] == 0.15  # not below the floor


def _line_targets() -> SparseDistances:
    """Targets on a line at 0, 0.03, 0.06, 0.1, 0.3; distances kept up to 0.12."""
    x = np.array([0.0, 0.03, 0.06, 0.1, 0.3])
    d = np.abs(x[:, None] - x[None, :])
    ptr, idx, dist = [0], [], []
    for row in d:
        keep = np.flatnonzero(row <= 0.12)
        keep = keep[np.argsort(row[keep], kind="stable")]
        idx.extend(keep)
        dist.extend(row[keep])
        ptr.append(len(idx))
    return SparseDistances(np.array(ptr), np.array(idx), np.array(dist), 0.12)


def test_suppress_peaks_floors_the_targets_near_each_rows_argmax():
    targets = _line_targets()
    unary = np.full((2, 5), 0.5)
    marg = np.array([[0.1, 0.5, 0.2, 0.1, 0.1], [0.0, 0.1, 0.1, 0.2, 0.6]])
    out = suppress_peaks(unary, marg, targets, 0.05, 0.01)
    assert out.tolist() == [[0.01, 0.01, 0.01, 0.5, 0.5], [0.5, 0.5, 0.5, 0.5, 0.01]]
    assert np.all(unary == 0.5)  # input untouched
    with pytest.raises(ValueError, match="suppression needs"):
        suppress_peaks(unary, marg, targets, 0.2, 0.01)


def test_condition_on_images_keeps_each_row_near_its_image_by_hand():
    targets = _line_targets()
    unary = np.array([[0.5, 0.002, 0.4, 0.8, 0.9], [0.2, 0.2, 0.2, 0.2, 0.2], [0.3, 0.1, 0.6, 0.7, 0.9]])
    out = condition_on_images(unary, np.array([1, 4, -1]), targets, 0.03, 0.01)
    g = np.exp(-0.5 * (np.array([0.03, 0.0, 0.03, 0.07]) / 0.03) ** 2)
    beyond = np.exp(-0.5 * (0.12 / 0.03) ** 2)  # 0.3 lies beyond the reach 0.12 of target 1
    # row 0: the floor 0.01 lifts 0.002 first, then each target's Gaussian of its distance from 0.03
    assert out[0] == pytest.approx([0.5 * g[0], 0.01 * g[1], 0.4 * g[2], 0.8 * g[3], 0.9 * beyond])
    assert out[1] == pytest.approx([0.2 * beyond] * 4 + [0.2])  # only target 4 lies within 0.12 of 0.3
    assert out[2].tolist() == unary[2].tolist()  # no image: kept
    assert unary[0, 1] == 0.002  # input untouched
    narrow = condition_on_images(unary.astype(np.float32), np.array([1, 4, -1]), targets, 0.001, 0.01)
    assert narrow.dtype == np.float32 and narrow.min() == np.finfo(np.float32).tiny  # exp(-1800) underflows
    with pytest.raises(ValueError, match="width"):
        condition_on_images(unary, np.array([1, 4, -1]), targets, 0.0, 0.01)
    with pytest.raises(ValueError, match="one image per row"):
        condition_on_images(unary, np.array([1, 4]), targets, 0.03, 0.01)


def test_row_scales_are_each_rows_median_over_its_near_targets():
    d = np.array([[5.0, 1.0, 2.0, 9.0], [0.5, 7.0, 3.0, 4.0], [1.0, 1.0, 1.0, 1.0]])
    near = np.array([[1, 3, 2], [0, -1, 2], [-1, -1, -1]])
    assert row_scales(d, near).tolist() == [2.0, 1.75, 0.0]


def test_descriptor_scale_is_median_of_k_nearest():
    d = np.array([[5.0, 1.0, 2.0, 9.0], [0.5, 7.0, 3.0, 4.0]])
    # 2 nearest per row: {1, 2} and {0.5, 3} -> median of 0.5, 1, 2, 3 = 1.5
    assert descriptor_scale(d, 2) == pytest.approx(1.5)
    assert descriptor_scale(d, 1) == pytest.approx(0.75)
    assert descriptor_scale(np.zeros((2, 3)), 1) > 0
    with pytest.raises(ValueError):
        descriptor_scale(d, 5)


def test_descriptor_scale_from_nearest_targets_on_the_surface():
    d = np.array([[5.0, 1.0, 2.0, 9.0], [0.5, 7.0, 3.0, 4.0]])
    # row 0 pairs with targets 0 and 3, row 1 with target 2 only: median of 5, 9, 3 = 5
    assert descriptor_scale(d, near=np.array([[0, 3], [2, -1]])) == pytest.approx(5.0)
    # the k nearest in descriptor space would say 1.5: many exact images at distance ~0
    # shrink that proxy, the surface neighbours do not depend on them
    with pytest.raises(ValueError):
        descriptor_scale(d, near=np.full((2, 1), -1))


def test_calibrated_potential_values_products_and_floor():
    d = np.array([[0.0, 1.0, 2.0, 10.0]])
    phi = calibrated_potential([d], [1.0], floor=1e-3)
    np.testing.assert_allclose(phi[0, :3], np.exp(-np.array([0.0, 0.5, 2.0])))
    assert phi[0, 3] == 1e-3  # exp(-50) floored
    # Units do not matter when the scale is measured in them.
    np.testing.assert_allclose(
        calibrated_potential([d * 1e4], [descriptor_scale(d * 1e4, 3)]),
        calibrated_potential([d], [descriptor_scale(d, 3)]),
    )
    # A product of two terms is the product of their potentials (above the floor).
    both = calibrated_potential([d, 2 * d], [1.0, 2.0], floor=1e-9)
    np.testing.assert_allclose(both[0, :3], calibrated_potential([d], [1.0], 1e-9)[0, :3] ** 2)
    with pytest.raises(ValueError):
        calibrated_potential([], [])
    with pytest.raises(ValueError):
        calibrated_potential([d], [1.0, 2.0])
    with pytest.raises(ValueError):
        calibrated_potential([d], [1.0], floor=0.0)


def test_calibrated_wks_unary_peaks_at_the_mirror_of_a_generated_shape(mirror):
    # Calibration on a generated shape with an exact mirror map: every 7th vertex is a
    # source, every vertex a target. With the trivial match removed (radius 0.3), the
    # unary's argmax must be the true mirror for every point farther than 0.3 from the
    # symmetry plane, and only a few percent of targets may reach half the row maximum.
    v, f, sym = mirror
    evals, evecs = eigenpairs(v, f, 60)
    energies, sigma = wks_energies(evals, 60)
    ps, pt = np.arange(0, len(v), 7), np.arange(len(v))
    a = wave_kernel_signature(evals, evecs[ps], energies, sigma)
    b = wave_kernel_signature(evals, evecs[pt], energies, sigma)
    dist = cdist(a, b)  # the broadcast norm's distances (to 4e-15), without its 450 MB temporary
    unary = calibrated_potential([dist], [descriptor_scale(dist, 7)], floor=1e-3)
    euclid = cdist(v[ps], v[pt])
    unary = suppress_trivial(unary, euclid, 0.3, 1e-3)
    off_plane = np.abs(v[ps, 0]) > 0.3
    err = np.linalg.norm(v[np.argmax(unary, axis=1)] - v[sym[ps]], axis=1)
    assert np.all(err[off_plane] < 0.2)
    assert np.mean(unary >= 0.5 * unary.max(axis=1, keepdims=True)) < 0.1
