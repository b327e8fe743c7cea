"""The Markov random field of the paper: unary (Eq. 5) and truncated pairwise (Eq. 6) terms.

All lengths are in the units of the normalised shape (unit square root of surface area)
unless a docstring says otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geodesics import SparseDistances


@dataclass(frozen=True)
class MRF:
    """A pairwise MRF over correspondences source sample -> target sample (paper Eq. 1).

    Attributes
    ----------
    unary : (S, T) float array
        Phi_s(f_s) > 0 for every source sample s and target label f_s.
    edges : (E, 2) int64
        Undirected source-graph edges (i < j), indices into the source samples.
    edge_length : (E,) float64
        Geodesic length d(s, q) of every edge.
    targets : SparseDistances
        Target-target geodesics up to ``targets.radius``, each row sorted ascending.
        Must reach at least ``edge_length.max() + delta`` for the sparse message to be
        exact.
    lam, rho : float
        Pairwise parameters of Eq. 6: psi = exp(-lam (d(s,q) - d(fs,fq))^2),
        Psi = max(psi, rho^2).
    """

    unary: np.ndarray
    edges: np.ndarray
    edge_length: np.ndarray
    targets: SparseDistances
    lam: float
    rho: float

    @property
    def n_source(self) -> int:
        return int(self.unary.shape[0])

    @property
    def n_target(self) -> int:
        return int(self.unary.shape[1])

    @property
    def delta(self) -> float:
        """Half-width of the ring where psi exceeds its truncation rho^2."""
        return truncation_width(self.lam, self.rho)


def nmi_potential(similarity: np.ndarray, gamma: float) -> np.ndarray:
    """Robust unary of Eq. 5 on the similarity NMI' = NMI - 1 in [0, 1].

    Phi = 1 / (1 + (1 - NMI')^2 / gamma): identical descriptors give 1, unrelated ones
    ``potential_floor(gamma)`` (about 1/101 for the paper's gamma = 0.01).

    Parameters
    ----------
    similarity : (S, T) array, values in [0, 1]
    gamma : float > 0

    Returns
    -------
    (S, T) float64 array
    """
    if gamma <= 0:
        raise ValueError(f"gamma must be positive, got {gamma}")
    s = np.clip(np.asarray(similarity, dtype=np.float64), 0.0, 1.0)
    return 1.0 / (1.0 + (1.0 - s) ** 2 / gamma)


def potential_floor(gamma: float) -> float:
    """Smallest value of Eq. 5, reached at NMI' = 0."""
    return 1.0 / (1.0 + 1.0 / gamma)


def truncation_width(lam: float, rho: float) -> float:
    """delta = sqrt(ln(1/rho^2) / lam): psi > rho^2 iff |d(s,q) - d(fs,fq)| < delta."""
    if lam <= 0:
        return np.inf
    if not 0 < rho < 1:
        raise ValueError(f"rho must lie in (0, 1), got {rho}")
    return float(np.sqrt(np.log(1.0 / rho**2) / lam))


def lambda_for_tolerance(delta: float, rho: float) -> float:
    """The lambda of Eq. 6 whose truncation ring has half-width ``delta``."""
    if delta <= 0:
        raise ValueError(f"the pairwise tolerance must be positive, got {delta}")
    if not 0 < rho < 1:
        raise ValueError(f"rho must lie in (0, 1), got {rho}")
    return float(np.log(1.0 / rho**2) / delta**2)


def pairwise_dense(d_edge: float, target_dist: np.ndarray, lam: float, rho: float) -> np.ndarray:
    """Paper-literal pairwise table Psi(fs, fq) of Eq. 6 for one edge (dense oracle only).

    Parameters
    ----------
    d_edge : float
        Geodesic length d(s, q) of the source edge.
    target_dist : (T, T) array
        All target-target geodesic distances.

    Returns
    -------
    (T, T) float64 array, Psi[fs, fq].
    """
    psi = np.exp(-lam * (d_edge - np.asarray(target_dist, dtype=np.float64)) ** 2)
    return np.maximum(psi, rho**2)


def suppress_trivial(
    unary: np.ndarray, source_target_dist: np.ndarray, radius: float, floor: float
) -> np.ndarray:
    """Remove the trivial (identity) match from a self-matching unary.

    Every target within geodesic ``radius`` of the source sample gets the unary's floor,
    so the identity is no longer favoured by the data term (DESIGN.md, "Identity").

    Parameters
    ----------
    unary : (S, T) array
    source_target_dist : (S, T) array
        Geodesic distance from every source sample to every target (np.inf beyond the
        range that was computed).
    radius : float
    floor : float

    Returns
    -------
    (S, T) array, a modified copy.
    """
    out = np.array(unary, copy=True)
    out[np.asarray(source_target_dist) <= radius] = floor
    return out


def descriptor_scale(distance: np.ndarray, k: int = 7) -> float:
    """Typical descriptor distance between a source sample and its nearest targets.

    The median, over all source samples, of the distances to their ``k`` nearest
    targets in descriptor space. In self-matching these are mostly the targets around
    the point itself, so the scale measures how much the descriptor changes over the
    sampling offset: the spread a true match must be allowed.

    Parameters
    ----------
    distance : (S, T) array
        Descriptor distances, >= 0.
    k : int
        Number of nearest targets per source sample, 1 <= k <= T.

    Returns
    -------
    float, > 0 (a tiny positive number when the descriptor is constant).
    """
    d = np.asarray(distance, dtype=np.float64)
    if not 1 <= k <= d.shape[1]:
        raise ValueError(f"k must lie in [1, {d.shape[1]}], got {k}")
    nearest = np.partition(d, k - 1, axis=1)[:, :k]
    return max(float(np.median(nearest)), np.finfo(np.float64).tiny)


def calibrated_potential(distances: list[np.ndarray], k: int = 7, floor: float = 1e-3) -> np.ndarray:
    """Unary from descriptor distances, calibrated per descriptor; products combine them.

    ``Phi = max(prod_i exp(-d_i^2 / (2 sigma_i^2)), floor)`` with ``sigma_i`` the
    :func:`descriptor_scale` of the i-th distance matrix. Unlike Eq. 5 with a fixed
    gamma, the width follows the measured spread of each descriptor, so a true match at
    the sampling offset keeps a potential near 1 whatever the descriptor's units; the
    floor keeps every message bounded below (DESIGN.md, "Division trick").

    Parameters
    ----------
    distances : list of (S, T) arrays
        One descriptor-distance matrix per factor, >= 0.
    k : int
        Nearest targets per source sample that set each sigma.
    floor : float
        Smallest potential, in (0, 1).

    Returns
    -------
    (S, T) float64 array, values in [floor, 1].
    """
    if not distances:
        raise ValueError("give at least one distance matrix")
    if not 0 < floor < 1:
        raise ValueError(f"floor must lie in (0, 1), got {floor}")
    exponent = np.zeros(np.shape(distances[0]), dtype=np.float64)
    for d in distances:
        exponent += np.asarray(d, dtype=np.float64) ** 2 / (2.0 * descriptor_scale(d, k) ** 2)
    return np.maximum(np.exp(-exponent), floor)
