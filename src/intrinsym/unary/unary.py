"""The unary term: descriptors of source samples and targets turned into potentials.

:func:`unary_potentials` computes one descriptor distance matrix per term of
``Params.unary`` (spin-image NMI of Eq. 2-4, WKS, HKS) and maps them to potentials,
either by Eq. 5 (:func:`nmi_potential`), by calibrated Gaussians whose widths are
measured on the shape itself (:func:`descriptor_scale`, :func:`row_scales`,
:func:`calibrated_potential`), or by Gaussians of each row's own spread
(:func:`row_potential`, a part matched to a whole).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial.distance import cdist

from ..geodesics import geodesics
from ..mesh import sampling
from ..params import OFFSET_TARGETS, Params
from ..surface import Surface, sample
from . import descriptors

#: Laplace-Beltrami eigenvalues (K,) and eigenfunctions (N, K) of a surface.
Spectrum = tuple[np.ndarray, np.ndarray]

#: Smallest descriptor scale: the square root of the smallest normal float, so that
#: sigma**2 in :func:`calibrated_potential` stays positive (a constant descriptor, as on
#: a thin needle, has scale 0, and 0 / 0 would make the potentials NaN).
SMALLEST_SCALE = float(np.sqrt(np.finfo(np.float64).tiny))


#: Support radii of the multi-scale spin image, in multiples of ``spin_radius``.
SPIN_SCALES = (0.5, 1.0, 2.0)


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
    float, >= :data:`SMALLEST_SCALE` (equal to it when the descriptor is constant).
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
    return max(float(np.median(values)), SMALLEST_SCALE)


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
    bounded below, so that BP's division by the old message stays finite.

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


def row_potential(distances: list[np.ndarray], width: float, floor: float = 1e-3) -> np.ndarray:
    """Unary from each source sample's own ranking of the targets; products combine
    descriptors.

    ``Phi = max(prod_i exp(-(d_i - m_i)^2 / (2 (width (h_i - m_i))^2)), floor)`` with
    ``m_i`` and ``h_i`` the smallest and the median distance of the row. Between a part
    and a whole in another pose, a true match's spin image lies only a little nearer than
    the rest (on SHREC'16 cuts_cat_shape_1 the row's largest
    :func:`calibrated_potential` is a median 1.4 times its median one): a width measured
    on true matches leaves the unary flat, and BP's marginals with it. Measured from the
    row's own spread the nearest targets stand out whatever the descriptor's units and
    the pose.

    Parameters
    ----------
    distances : list of (S, T) arrays
        One descriptor-distance matrix per factor, >= 0.
    width : float
        The Gaussian's width in units of the row's spread, > 0.
    floor : float
        Smallest potential, in (0, 1).

    Returns
    -------
    (S, T) float64 array, values in [floor, 1]; 1 at each row's nearest target of a
    single factor, and everywhere on a row whose distances are all equal.
    """
    if not width > 0:
        raise ValueError(f"width must be positive, got {width}")
    shifted, scales = [], []
    for d in distances:
        d = np.asarray(d, dtype=np.float64)
        nearest = d.min(axis=1, keepdims=True)
        shifted.append(d - nearest)
        scales.append(width * np.maximum(np.median(d, axis=1, keepdims=True) - nearest, SMALLEST_SCALE))
    return calibrated_potential(shifted, scales, floor)


def spin_images_at(surface: Surface, vertices: np.ndarray, radius: float, p: Params) -> np.ndarray:
    """Spin images of working vertices with support ``radius``, built from
    ``p.spin_cloud`` area-uniform surface points (seed ``p.seed``; the shape's own points
    for a cloud), ``p.spin_bins`` bins per side.

    Returns
    -------
    (n, bins, bins) float32, each image summing to 1 (or all 0).
    """
    shape = surface.shape
    if shape.faces is None:
        cloud = shape.vertices
    else:
        cloud = sampling.area_uniform_points(shape.vertices, shape.faces, p.spin_cloud, seed=p.seed)[0]
    return descriptors.spin_images(shape.vertices[vertices], surface.normals[vertices], cloud, radius, p.spin_bins)


def spin_descriptors(surface: Surface, vertices: np.ndarray, radius: float, p: Params) -> np.ndarray:
    """:func:`spin_images_at` quantised to ``p.spin_levels`` intensity levels.

    Returns
    -------
    (n, bins^2) uint8
    """
    return descriptors.quantize(spin_images_at(surface, vertices, radius, p), p.spin_levels)


def spectrum(surface: Surface, k: int, coarse: int) -> Spectrum:
    """Laplace-Beltrami eigenpairs of the working shape: (K,) values, (N, K) vectors,
    K = ``k`` (at most N - 1); ``coarse`` as :func:`intrinsym.spectral.laplacian.eigenpairs`.
    Solved once per surface (:meth:`intrinsym.surface.Surface.eigenpairs`)."""
    return surface.eigenpairs(min(k, len(surface.shape.vertices) - 1), coarse)


def spectra(src: Surface, tgt: Surface, p: Params, self_match: bool) -> tuple[Spectrum, Spectrum] | None:
    """Eigenpairs of source and target, computed once for the unary's "wks" / "hks"
    terms (``p.eigenpairs``) and the seeded ZoomOut (``p.zoomout_final`` + 1 at least);
    None when neither needs them."""
    spectral_terms = bool({"wks", "hks"} & set(p.unary_terms))
    if not spectral_terms and not (self_match and p.zoomout):
        return None
    a = spectrum(src, p.eigenpairs if spectral_terms else p.zoomout_final + 1, p.eigen_coarse)
    return a, (a if tgt is src else spectrum(tgt, p.eigenpairs, p.eigen_coarse))


def term_distances(
    term: str,
    queries: list[tuple[Surface, np.ndarray]],
    tgt: Surface,
    pt: np.ndarray,
    p: Params,
    spectrum_of: Callable[[Surface], Spectrum],
) -> list[np.ndarray]:
    """Descriptor distances of one unary term from each query point set to the targets.

    1 - NMI' for spin images (averaged over radii ``SPIN_SCALES`` for "spin-multi"), the
    Euclidean distance of log signatures for "wks" and "hks", on the energy / time grid
    of the first query's surface (the source), so that two shapes' signatures compare.

    Returns
    -------
    list of (len(points), T) float64, one per ``(surface, points)`` of ``queries``.
    """
    if term in ("spin", "spin-multi"):
        radii = [p.spin_radius * c for c in (SPIN_SCALES if term == "spin-multi" else (1.0,))]
        images = [spin_descriptors(tgt, pt, r, p) for r in radii]
        return [
            1.0
            - np.mean(
                [
                    descriptors.nmi(spin_descriptors(surface, points, r, p), b, p.spin_levels)
                    for r, b in zip(radii, images)
                ],
                axis=0,
            ).astype(np.float64)
            for surface, points in queries
        ]
    grid = spectrum_of(queries[0][0])[0]
    if term == "wks":
        energies, sigma = descriptors.wks_energies(grid, p.energies)

        def signature(surface: Surface, points: np.ndarray) -> np.ndarray:
            ev, phi = spectrum_of(surface)
            return descriptors.wave_kernel_signature(ev, phi[points], energies, sigma)
    else:
        times = descriptors.hks_times(grid, p.energies)

        def signature(surface: Surface, points: np.ndarray) -> np.ndarray:
            ev, phi = spectrum_of(surface)
            return descriptors.heat_kernel_signature(ev, phi[points], times)

    b = signature(tgt, pt)
    return [cdist(signature(surface, points), b) for surface, points in queries]


def near_targets(surface: Surface, points: np.ndarray, pt: np.ndarray, radius: float) -> np.ndarray:
    """(len(points), T) geodesic distances from working vertices to the targets, inf
    beyond ``radius``."""
    return geodesics.distances_to(surface.graph, points, pt, radius)


def nearest_targets(dist: np.ndarray, k: int) -> np.ndarray:
    """(m, k) the k targets nearest each row of ``dist`` ((m, T), inf where unknown);
    -1 where fewer than k are within reach."""
    k = min(k, dist.shape[1])
    near = np.argpartition(dist, k - 1, axis=1)[:, :k]
    return np.where(np.isfinite(np.take_along_axis(dist, near, axis=1)), near, -1)


def offset_calibrated(p: Params) -> bool:
    """Whether the unary's widths use the "offset" rule (alone or in "both")."""
    return p.potential == "calibrated" and p.calibration not in ("descriptor", "row")


def unary_potentials(
    src: Surface,
    tgt: Surface,
    ps: np.ndarray,
    pt: np.ndarray,
    p: Params,
    spectra: tuple[Spectrum, Spectrum] | None,
    spacing: float,
    near_source: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Unary potentials of the terms named by ``p.unary`` and their floor.

    Each term gives an (S, T) descriptor distance (:func:`term_distances`; "wks" and
    "hks" use ``spectra``, the eigenpairs of source and target, see :func:`spectra`);
    ``p.potential`` maps them to potentials. The "offset" calibration measures each
    term's spread on true matches: from calibration points on the target shape (the
    source samples when self-matching, else a Poisson sample of the same size) to the
    ``OFFSET_TARGETS`` targets nearest them on the surface, ``spacing`` apart. When
    self-matching, ``near_source`` ((S, T), from :func:`near_targets` out to at least
    ``(OFFSET_TARGETS + 2) * spacing``) gives the source samples' distances to them.

    Returns
    -------
    unary : (S, T) float64
    floor : float
        The smallest value the potential map can take.
    """

    def spectrum_of(surface: Surface) -> Spectrum:
        assert spectra is not None
        return spectra[0] if surface is src else spectra[1]

    offset = offset_calibrated(p)
    queries = [(src, ps)]
    if offset and tgt is not src:
        queries.append((tgt, sample(tgt, len(ps), None, p.seed + 2)))
    per_term = [term_distances(term, queries, tgt, pt, p, spectrum_of) for term in p.unary_terms]
    distances = [d[0] for d in per_term]
    if p.potential == "paper":
        return nmi_potential(1.0 - distances[0], p.gamma), potential_floor(p.gamma)
    if p.calibration == "row":
        return row_potential(distances, p.row_width, p.unary_floor), p.unary_floor
    scales: list = [0.0] * len(distances)
    near = None
    if offset:
        if near_source is None or tgt is not src:
            near_source = near_targets(tgt, queries[-1][1], pt, (OFFSET_TARGETS + 2) * spacing)
        near = nearest_targets(near_source, OFFSET_TARGETS)
        scales = [descriptor_scale(d[-1], near=near) for d in per_term]
    if p.calibration != "offset":
        scales = [max(s, descriptor_scale(d, p.calibration_k)) for s, d in zip(scales, distances)]
    if p.calibration == "local" and tgt is src and near is not None:
        scales = [np.maximum(s, row_scales(d, near))[:, None] for s, d in zip(scales, distances)]
    return calibrated_potential(distances, scales, p.unary_floor), p.unary_floor
