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
    unary: np.ndarray, source_target_dist: np.ndarray, radius: float, floor: float, weight: float = 0.0
) -> np.ndarray:
    """Weaken the trivial (identity) match of a self-matching unary.

    The targets within geodesic ``radius`` of the source sample (the identity's mode)
    are scaled so that their largest value is ``weight`` times the row's largest value
    beyond ``radius`` (never raised, never below ``floor``); ``weight`` 0 puts them at
    the floor, i.e. removes the identity (DESIGN.md, "Identity").

    With 0 < ``weight`` < 1 the identity stays in the model as the answer "no symmetric
    partner": a consistent field like any symmetry, which a symmetry's consistent field
    of better descriptor matches outbids, but which outbids the self-maps that BP
    otherwise invents where a shape has no symmetry (every row must put its mass
    somewhere, and the truncated pairwise term rewards any map that keeps short
    distances) - and a true symmetry, too, where its descriptor matches are weak
    (``intrinsym.Params.trivial_weight``).

    Parameters
    ----------
    unary : (S, T) array
    source_target_dist : (S, T) array
        Geodesic distance from every source sample to every target (np.inf beyond the
        range that was computed).
    radius : float
    floor : float
    weight : float
        In [0, 1).

    Returns
    -------
    (S, T) array, a modified copy.
    """
    unary = np.asarray(unary)
    near = np.asarray(source_target_dist) <= radius
    far_max = np.where(near, 0.0, unary).max(axis=1)
    near_max = np.where(near, unary, 0.0).max(axis=1)
    scale = np.minimum(1.0, weight * far_max / np.maximum(near_max, np.finfo(np.float64).tiny))
    return np.where(near, np.maximum(unary * scale[:, None], floor), unary).astype(unary.dtype, copy=False)


def suppress_peaks(
    unary: np.ndarray, marginals: np.ndarray, targets: SparseDistances, radius: float, floor: float
) -> np.ndarray:
    """Remove the mode a BP pass settled on from the unary, for the next pass.

    Loopy BP keeps about one mode of a multi-modal posterior (one symmetry of a star,
    the left/right swap of two frames but not the identity). As the trivial match is
    removed before the first pass, every target within ``radius`` of each row's argmax
    gets the unary's floor, and BP run again settles on another mode.

    Parameters
    ----------
    unary : (S, T) array
    marginals : (S, T) array
        The marginals of the pass.
    targets : SparseDistances
        Target-target geodesics; must reach ``radius``.
    radius : float
    floor : float

    Returns
    -------
    (S, T) array, a modified copy.
    """
    if targets.radius < radius:
        raise ValueError(f"target distances reach {targets.radius:.4g}, the suppression needs {radius:.4g}")
    out = np.array(unary, copy=True)
    for s, peak in enumerate(np.argmax(marginals, axis=1)):
        row = slice(targets.indptr[peak], targets.indptr[peak + 1])
        out[s, targets.indices[row][targets.dist[row] <= radius]] = floor
    return out


def descriptor_scale(distance: np.ndarray, k: int = 7, near: np.ndarray | None = None) -> float:
    """Typical descriptor distance of a true match at the sampling offset.

    With ``near``, the median of ``distance[s, near[s]]``: the distances from each
    calibration point to the targets that lie nearest it on the surface, true matches
    (the identity) displaced by the sampling offset. Without it, the median distance
    from each source sample to its ``k`` nearest targets in descriptor space, a proxy
    that shrinks on shapes with many exact symmetries (their images all lie at about
    zero distance, so the spread of the offset is not measured).

    Parameters
    ----------
    distance : (S, T) array
        Descriptor distances, >= 0.
    k : int
        Number of nearest targets per source sample, 1 <= k <= T (without ``near``).
    near : (S, m) int array, optional
        Targets nearest each row's point on the surface; -1 entries are ignored.

    Returns
    -------
    float, > 0 (a tiny positive number when the descriptor is constant).
    """
    d = np.asarray(distance, dtype=np.float64)
    if near is not None:
        values = _near_values(d, near).compressed()
        if values.size == 0:
            raise ValueError("no calibration pair: every entry of near is -1")
    else:
        if not 1 <= k <= d.shape[1]:
            raise ValueError(f"k must lie in [1, {d.shape[1]}], got {k}")
        values = np.partition(d, k - 1, axis=1)[:, :k]
    return max(float(np.median(values)), np.finfo(np.float64).tiny)


def row_scales(distance: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Each row's own spread on true matches: the median of ``distance[s, near[s]]``.

    Parameters
    ----------
    distance : (S, T) array
    near : (S, m) int array
        Targets nearest each row's point on the surface; -1 entries are ignored.

    Returns
    -------
    (S,) float64, 0 for a row without a calibration target.
    """
    return np.ma.median(_near_values(distance, near), axis=1).filled(0.0)


def _near_values(distance: np.ndarray, near: np.ndarray) -> np.ma.MaskedArray:
    """(S, m) ``distance[s, near[s]]``, masked where ``near`` is -1."""
    near = np.asarray(near)
    d = np.take_along_axis(np.asarray(distance, dtype=np.float64), np.maximum(near, 0), axis=1)
    return np.ma.masked_array(d, mask=near < 0)


def calibrated_potential(distances: list[np.ndarray], scales: list, floor: float = 1e-3) -> np.ndarray:
    """Unary from descriptor distances, calibrated per descriptor; products combine them.

    ``Phi = max(prod_i exp(-d_i^2 / (2 sigma_i^2)), floor)`` with ``sigma_i`` the
    measured spread of the i-th descriptor on true matches (:func:`descriptor_scale`).
    Unlike Eq. 5 with a fixed gamma, a true match at the sampling offset keeps a
    potential near 1 whatever the descriptor's units; the floor keeps every message
    bounded below (DESIGN.md, "Division trick").

    Parameters
    ----------
    distances : list of (S, T) arrays
        One descriptor-distance matrix per factor, >= 0.
    scales : list of float or (S, 1) arrays
        sigma_i of each factor, > 0, in the units of its distances (per row as a column).
    floor : float
        Smallest potential, in (0, 1).

    Returns
    -------
    (S, T) float64 array, values in [floor, 1].
    """
    if not distances or len(scales) != len(distances):
        raise ValueError("give one scale per distance matrix, and at least one")
    if not 0 < floor < 1:
        raise ValueError(f"floor must lie in (0, 1), got {floor}")
    exponent = np.zeros(np.shape(distances[0]), dtype=np.float64)
    for d, sigma in zip(distances, scales):
        exponent += np.asarray(d, dtype=np.float64) ** 2 / (2.0 * sigma**2)
    return np.maximum(np.exp(-exponent), floor)
