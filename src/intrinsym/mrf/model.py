"""The Markov random field of the paper: unary (Eq. 5) and truncated pairwise (Eq. 6) terms.

All lengths are in the units of the normalised shape (unit square root of surface area)
unless a docstring says otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geodesics.geodesics import SparseDistances


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
    the floor, i.e. removes the identity.

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


def condition_on_images(
    unary: np.ndarray, images: np.ndarray, targets: SparseDistances, width: float, floor: float
) -> np.ndarray:
    """The unary of BP conditioned on one answer: each row kept near the answer's image.

    Loopy BP settles on about one mode, and not always on a right one; given a map (a
    mode of the match), BP run on this unary gives the marginals of that mode: each
    target's floored unary times the Gaussian exp(-d^2 / (2 width^2)) of its geodesic
    distance d from the row's image, d taken as the reach of ``targets`` beyond it, and
    never below the smallest normal number of ``unary``'s dtype (BP takes only positive
    potentials). Rows without an image (-1) are kept as they are.

    Parameters
    ----------
    unary : (S, T) array
    images : (S,) int
        Target of every source sample under the answer, -1 for none.
    targets : SparseDistances
        Target-target geodesics.
    width : float
        Positive, in the units of ``targets``.
    floor : float
        The unary's floor: every target keeps at least it before the Gaussian.

    Returns
    -------
    (S, T) array of ``unary``'s dtype, a new array.
    """
    if not width > 0:
        raise ValueError(f"width must be positive, got {width}")
    unary = np.asarray(unary)
    images = np.asarray(images)
    if images.shape != (unary.shape[0],):
        raise ValueError(f"need one image per row ({unary.shape[0]}), got shape {images.shape}")
    beyond = np.exp(-0.5 * (targets.radius / width) ** 2)
    tiny = np.finfo(unary.dtype).tiny
    out = np.array(unary, copy=True)
    for s in np.flatnonzero(images >= 0):
        row = slice(targets.indptr[images[s]], targets.indptr[images[s] + 1])
        prior = np.full(unary.shape[1], beyond)
        prior[targets.indices[row]] = np.exp(-0.5 * (targets.dist[row] / width) ** 2)
        out[s] = np.maximum(np.maximum(unary[s].astype(np.float64), floor) * prior, tiny)
    return out
