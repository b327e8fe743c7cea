"""Unary (Eq. 5) and pairwise (Eq. 6) terms on hand-checked values."""

import numpy as np
import pytest

from intrinsym.model import (
    lambda_for_tolerance,
    nmi_potential,
    pairwise_dense,
    potential_floor,
    suppress_trivial,
    truncation_width,
)


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
