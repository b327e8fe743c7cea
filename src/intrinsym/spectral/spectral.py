"""Spectral baseline: the dominant intrinsic self-symmetry from Laplace-Beltrami eigenfunctions.

Not the paper's method: a comparison for the global map that :mod:`intrinsym.extract.extract`
reads off the BP marginals. Two published steps:

1. Sign search (Ovsjanikov, Sun and Guibas, "Global intrinsic symmetries of shapes",
   SGP 2008). An intrinsic symmetry ``T`` maps every eigenfunction of a non-repeated
   eigenvalue onto itself or its negative, ``phi_i o T = s_i phi_i``. Among the sign
   vectors ``s`` other than all-plus (the identity), the ones whose sign-flipped spectral
   embedding ``s * phi(x)`` lands closest to the unflipped embedding (mean
   nearest-neighbour distance over evenly spread samples) are the candidates.
2. ZoomOut (Melzi et al., "ZoomOut: spectral upsampling for efficient shape
   correspondence", SIGGRAPH Asia 2019), used as a self-map: alternate the functional
   map ``C`` of the point map in the first ``k`` eigenfunctions (least squares,
   ``phi_k[T(x)] ~ phi_k[x] C``) and the point map ``T(x)`` = nearest neighbour of
   ``phi_k[x] C``, growing ``k`` by one each time. It iterates on farthest-point
   samples; the last ``C`` then maps every vertex.

Near-repeated eigenvalues: within a cluster of (nearly) equal eigenvalues a symmetry
acts by an orthogonal mixing, not by a sign, so the sign search uses only eigenfunctions
whose eigenvalue lies at least ``min_gap`` (relative) from both neighbours; ZoomOut
estimates the full ``C`` and handles the clusters.

Choosing among candidates: several near-symmetries can tie in the sign search on the
first eigenfunctions (a human is nearly front/back symmetric at low frequencies, so
left/right, front/back and their composition come out within a factor of three), and
the nearest-neighbour residual does not penalise a map that folds the shape onto part
of itself. So the best ``n_candidates`` sign vectors are all refined, and the refined
map that best keeps the commute-time distances ``|phi(x)/sqrt(lambda) -
phi(y)/sqrt(lambda)|`` (which an intrinsic isometry preserves exactly) wins. A candidate
that ZoomOut turns back into all-plus signs on the sign-search eigenfunctions has become
the identity (zero distortion) and is dropped.

:func:`seeded_symmetry` skips the sign search: sparse correspondences of a known
symmetry (the pipeline's global symmetry from the BP marginals) fit the first ``C`` and
ZoomOut refines it, so the correspondences choose the symmetry and ZoomOut gives the
precision.

Everything is scale-free (eigenvalue gaps and distortions are relative, nearest
neighbours do not depend on the embedding's scale) and deterministic (fixed start
vector for the eigensolver, fixed farthest-point seed). An exactly symmetric shape with
several symmetries (an ellipsoid with three distinct axes) ties between them, and which
one is returned may then change with rounding (for example when the shape is scaled).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist
from threadpoolctl import threadpool_limits

from ..mesh import sampling
from . import laplacian, neighbours

#: A seed pair whose residual under the seed's functional map exceeds this many times
#: the median residual of the pairs kept is left out of the fit (:func:`seed_map`).
SEED_TRIM = 3.0
#: Most refits of :func:`seed_map`; it stops earlier once the pairs kept stay the same.
SEED_TRIM_ROUNDS = 3

__all__ = [
    "SEED_TRIM",
    "SEED_TRIM_ROUNDS",
    "distortion",
    "isolated_eigenvalues",
    "map_points",
    "nearest_images",
    "seed_map",
    "seeded_functional_maps",
    "seeded_symmetry",
    "sign_candidates",
    "spectral_symmetry",
    "symmetry_candidates",
    "zoomout",
]


def isolated_eigenvalues(evals: np.ndarray, count: int, min_gap: float = 0.05) -> np.ndarray:
    """The first ``count`` eigenvalues separated from both neighbours by ``min_gap``.

    Parameters
    ----------
    evals : (K,) float array
        Ascending positive eigenvalues (the constant mode left out), any unit.
    count : int
        How many to return at most.
    min_gap : float
        Smallest relative gap ``|lambda_j - lambda_i| / max(lambda_i, lambda_j)`` to the
        previous and the next eigenvalue. The last one has no known next neighbour and
        is never chosen.

    Returns
    -------
    (m,) int64
        Indices into ``evals``, ascending, ``m <= count``.
    """
    lam = np.asarray(evals, dtype=np.float64)
    gap = np.diff(lam) / lam[1:]
    left = np.r_[np.inf, gap]
    right = np.r_[gap, -np.inf]
    return np.flatnonzero((left >= min_gap) & (right >= min_gap))[:count].astype(np.int64)


def sign_candidates(embedding: np.ndarray, n_candidates: int) -> tuple[np.ndarray, np.ndarray]:
    """Sign vectors whose flipped embedding best matches the embedding, best first.

    Every sign vector in ``{-1, +1}^m`` except all-plus is tried: the residual of ``s``
    is the mean over the points ``x`` of ``min_y |s * E[x] - E[y]|``.

    Parameters
    ----------
    embedding : (S, m) float array
        Eigenfunctions of non-repeated eigenvalues (columns) at evenly spread points,
        1 <= m <= 12 (all 2^m - 1 flipped copies are queried at once).
    n_candidates : int
        How many sign vectors to return.

    Returns
    -------
    signs : (n, m) float64
        Sign vectors (entries +-1), smallest residual first, ``n = min(n_candidates,
        2^m - 1)``.
    residuals : (n,) float64
        Their residuals, in the embedding's unit.
    """
    points = np.asarray(embedding, dtype=np.float64)
    m = points.shape[1]
    if not 1 <= m <= 12:
        raise ValueError(f"the sign search needs 1 to 12 eigenfunctions, got {m}")
    bits = np.arange(1, 2**m)
    signs = 1.0 - 2.0 * ((bits[:, None] >> np.arange(m)) & 1)
    distance = cKDTree(points).query((points * signs[:, None]).reshape(-1, m))[0]
    residuals = distance.reshape(len(signs), -1).mean(axis=1)
    best = np.argsort(residuals, kind="stable")[:n_candidates]
    return signs[best], residuals[best]


def nearest_images(
    source: np.ndarray, target: np.ndarray | neighbours.RowIndex, C: np.ndarray, device: str = "cpu"
) -> np.ndarray:
    """The point map of a functional map: each source row to the nearest target row.

    Parameters
    ----------
    source : (S, K) float array
        Basis (eigenfunctions) at the points being mapped, K >= k.
    target : (T, K) float array, or neighbours.RowIndex
        The same basis at the candidate images, or its index
        (:func:`intrinsym.spectral.neighbours.row_index`, built once for several searches).
    C : (k, k) float array
        Functional map in the first k basis functions (``target[T(x), :k] ~ source[x, :k] C``).
    device : {"cpu", "gpu"}
        Where the search runs (:func:`intrinsym.spectral.neighbours.nearest_leading_rows`).

    Returns
    -------
    (S,) int64
        Row of ``target`` nearest to ``source[x, :k] C`` for every source row x (exact).
    """
    k = len(C)
    return neighbours.nearest_leading_rows(np.asarray(source, dtype=np.float64)[:, :k] @ C, target, device)


def zoomout(
    source: np.ndarray,
    target: np.ndarray | neighbours.RowIndex,
    images: np.ndarray,
    k_start: int,
    involution: bool = False,
    device: str = "cpu",
) -> tuple[np.ndarray, np.ndarray]:
    """ZoomOut refinement of a point map between two sets of basis rows.

    For ``k = k_start, ..., K``: ``C`` (k, k) is the least-squares solution of
    ``target[images, :k] ~ source[:, :k] C``, then every source row's image becomes the
    target row nearest to ``source[:, :k] C``. For a self-map, ``source`` and ``target``
    are the eigenfunctions at two vertex subsets of the same shape.

    With ``involution`` (a self-map that is its own inverse, such as a reflection), every
    pair ``x -> T(x)`` also gives ``T(x) -> x``: both enter the least squares, which then
    fits a ``C`` that maps the images back onto the points as well.

    Parameters
    ----------
    source : (S, K) float array
        Basis (eigenfunctions, ascending eigenvalue, constant mode left out) at the
        points being mapped, S >= K.
    target : (T, K) float array, or neighbours.RowIndex
        The same basis at the candidate images, or its index
        (:func:`intrinsym.spectral.neighbours.search_rows`); every level searches the one index.
    images : (S,) int array
        Initial image (row of ``target``) of every source row.
    k_start : int
        Number of basis functions of the first iteration, 1 <= k_start <= K.
    involution : bool
        Fit the reversed pairs too (self-maps only: ``source`` and ``target`` rows of
        one basis).
    device : {"cpu", "gpu"}
        Where the nearest-row searches run (:func:`nearest_images`).

    Returns
    -------
    images : (S,) int64
        Refined image (row of ``target``) of every source row.
    C : (K, K) float64
        Functional map of the last iteration.
    """
    src = np.asarray(source, dtype=np.float64)
    rows = neighbours.search_rows(target, device)
    tgt = rows.basis if isinstance(rows, neighbours.RowIndex) else rows
    images = np.asarray(images, dtype=np.int64)
    if involution:
        for k in range(k_start, src.shape[1] + 1):
            a, b = src[:, :k], tgt[images, :k]
            C = np.linalg.lstsq(np.vstack([a, b]), np.vstack([b, a]), rcond=None)[0]
            images = nearest_images(src, rows, C, device)
        return images, C
    # source[:, :k] = Q[:, :k] R[:k, :k] for every k, and the leading block of the
    # triangular R^-1 is the inverse of R's: one QR serves all the levels
    q, r = np.linalg.qr(src)
    r_inv = solve_triangular(r, np.eye(len(r)))
    for k in range(k_start, src.shape[1] + 1):
        C = r_inv[:k, :k] @ (q[:, :k].T @ tgt[images, :k])
        images = nearest_images(src, rows, C, device)
    return images, C


def distortion(embedding: np.ndarray, images: np.ndarray) -> float:
    """How far a point map is from preserving the distances of an embedding.

    Parameters
    ----------
    embedding : (S, K) float array
        Embedded points, e.g. the commute-time embedding ``phi_i / sqrt(lambda_i)``
        whose distances an intrinsic isometry preserves.
    images : (S, K) float array
        The embedded images of the same points.

    Returns
    -------
    float
        Mean ``| |e_x - e_y| - |i_x - i_y| |`` over all pairs relative to the mean
        ``|e_x - e_y|`` (dimensionless, 0 for an isometry of the embedding).
    """
    before = pdist(np.asarray(embedding, dtype=np.float64))
    after = pdist(np.asarray(images, dtype=np.float64))
    return float(np.abs(after - before).mean() / before.mean())


def _spread(vertices: np.ndarray, n_samples: int, n_targets: int, n_final: int) -> tuple[np.ndarray, int]:
    """Farthest-point targets of ZoomOut, the first ``n_samples`` of them its samples.

    Returns the (n_targets,) int64 target vertices and ``n_samples``, both clamped to the
    vertex count (farthest-point sampling is greedy: a prefix is evenly spread too).
    Raises ValueError when fewer than ``n_final`` samples are left.
    """
    n_targets = min(max(n_targets, n_samples), len(vertices))
    n_samples = min(n_samples, n_targets)
    if n_samples < n_final:
        raise ValueError(f"n_samples ({n_samples}) must be at least n_final ({n_final})")
    return sampling.farthest_point_sampling(vertices, n_targets), n_samples


def spectral_symmetry(
    vertices: np.ndarray,
    faces: np.ndarray | None,
    n_signs: int = 8,
    n_final: int = 50,
    n_candidates: int = 4,
    n_samples: int = 500,
    n_targets: int = 3000,
    min_gap: float = 0.05,
) -> np.ndarray:
    """The dominant non-identity intrinsic self-symmetry as a vertex map.

    Sign search over the first ``n_signs`` eigenfunctions of non-repeated eigenvalue on
    ``n_samples`` farthest-point samples, ZoomOut of the best ``n_candidates`` sign
    vectors from those samples into ``n_targets`` farthest-point samples up to
    ``n_final`` eigenfunctions, and the point map of the least distorted one (see the
    module docstring) for every vertex.

    Parameters
    ----------
    vertices : (N, 3) float array
        Positions, any length unit.
    faces : (F, 3) int array or None
        Triangles of a connected surface (every vertex in one; see
        :func:`intrinsym.mesh.shape.clean`); None for a point cloud.
    n_signs : int
        Eigenfunctions in the sign search (2^n_signs - 1 sign vectors), at most 12.
    n_final : int
        Eigenfunctions (besides the constant) of the last ZoomOut level, < N.
    n_candidates : int
        Sign vectors refined by ZoomOut.
    n_samples : int
        Points of the sign search and of ZoomOut's least squares, at least ``n_final``
        (or all N vertices).
    n_targets : int
        Candidate images during ZoomOut (the first ``n_samples`` of them are the
        samples); the final map uses every vertex.
    min_gap : float
        Smallest relative eigenvalue gap of an eigenfunction in the sign search
        (:func:`isolated_eigenvalues`).

    Returns
    -------
    (N,) int64
        Image of every vertex.

    Raises
    ------
    ValueError
        If no eigenvalue below ``n_final`` is isolated by ``min_gap``, the sizes are out
        of range, or every candidate refines to the identity (no symmetry found).
    """
    v = np.asarray(vertices, dtype=np.float64)
    evals, evecs = laplacian.eigenpairs(v, faces, n_final + 1)
    maps, distortions = symmetry_candidates(
        v, evals, evecs, n_signs, n_final, n_candidates, n_samples, n_targets, min_gap
    )
    if not maps:
        raise ValueError(f"all {n_candidates} candidate sign vectors refine to the identity")
    phi = evecs[:, 1 : n_final + 1]
    return nearest_images(phi, phi, maps[int(np.argmin(distortions))])


def symmetry_candidates(
    vertices: np.ndarray,
    evals: np.ndarray,
    evecs: np.ndarray,
    n_signs: int = 8,
    n_final: int = 50,
    n_candidates: int = 4,
    n_samples: int = 500,
    n_targets: int = 3000,
    min_gap: float = 0.05,
) -> tuple[list[np.ndarray], list[float]]:
    """The candidate symmetries of :func:`spectral_symmetry` as functional maps.

    The best ``n_candidates`` sign vectors, each refined by ZoomOut; the candidates that
    fall back to the identity are dropped.

    Parameters
    ----------
    vertices : (N, 3) float array
    evals, evecs : (K,), (N, K) float arrays
        Laplace-Beltrami eigenpairs, ascending, the constant mode first, K > ``n_final``
        (fewer: ``n_final`` is clamped to K - 1).
    n_signs, n_final, n_candidates, n_samples, n_targets, min_gap
        As in :func:`spectral_symmetry`.

    Returns
    -------
    maps : list of (n_final, n_final) float64
        Functional maps ``C``: vertex x maps to the vertex whose ``evecs[:, 1:n_final+1]``
        row is nearest to ``evecs[x, 1:n_final+1] @ C`` (:func:`nearest_images`).
    distortions : list of float
        Their commute-time distortion (:func:`distortion`), in the same order.

    Raises
    ------
    ValueError
        If no eigenvalue below ``n_final`` is isolated by ``min_gap`` or the sizes are
        out of range.
    """
    n_final = min(n_final, evecs.shape[1] - 1)
    spread, n_samples = _spread(np.asarray(vertices, dtype=np.float64), n_samples, n_targets, n_final)
    phi = np.asarray(evecs, dtype=np.float64)[:, 1 : n_final + 1]
    lam = np.asarray(evals, dtype=np.float64)[1 : n_final + 1]
    chosen = isolated_eigenvalues(lam, n_signs, min_gap)
    if len(chosen) == 0:
        raise ValueError(f"no eigenvalue among the first {n_final} is isolated by {min_gap}")
    targets = phi[spread]
    samples = targets[:n_samples]
    signs, _ = sign_candidates(samples[:, chosen], n_candidates)
    commute = targets * np.divide(1.0, np.sqrt(lam), out=np.zeros_like(lam), where=lam > 0)  # 0 per extra part
    tree = cKDTree(targets[:, chosen])
    maps, distortions = [], []
    for s in signs:
        images = tree.query(samples[:, chosen] * s)[1]
        images, C = zoomout(samples, targets, images, int(chosen[-1]) + 1)
        # back to all-plus on the sign-search eigenfunctions: ZoomOut fell into the
        # identity, whose distortion is zero
        if np.all(np.diag(C)[chosen] > 0):
            continue
        maps.append(C)
        distortions.append(distortion(commute[:n_samples], commute[images]))
    return maps, distortions


def seed_map(
    source: np.ndarray, target: np.ndarray, trim: float = SEED_TRIM, rounds: int = SEED_TRIM_ROUNDS
) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares functional map of seed pairs, refitted without the pairs it
    cannot explain.

    ``C`` solves ``target ~ source C``; each pair's residual is the norm of its row of
    ``source C - target``, and the pairs above ``trim`` times the median residual of the
    pairs kept are left out of the next fit, up to ``rounds`` refits. A few wrong pairs
    that agree with each other pull the low-frequency fit, and ZoomOut then keeps their
    error: on a reflection, the true image of a thin part on the mirror plane (a cat's
    tail) lies inside the trivial disc the model removes, so BP maps the whole part
    elsewhere, and those pairs stand out with residuals several times the median
    (measured in docs/notes/2026-11-28-results-behind-the-defaults.md).

    Parameters
    ----------
    source, target : (P, k) float arrays
        Eigenfunctions at the pairs' sources and targets, P >= k.
    trim : float
        Residual factor over the median; 0 for the plain least squares.
    rounds : int
        Most refits.

    Returns
    -------
    C : (k, k) float64
    kept : (P,) bool
        The pairs of the last fit.
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    kept = np.ones(len(source), dtype=bool)
    C = np.linalg.lstsq(source, target, rcond=None)[0]
    for _ in range(rounds if trim > 0 else 0):
        residual = np.linalg.norm(source @ C - target, axis=1)
        inliers = residual <= trim * np.median(residual[kept])
        if np.array_equal(inliers, kept) or inliers.sum() < source.shape[1]:
            break
        kept = inliers
        C = np.linalg.lstsq(source[kept], target[kept], rcond=None)[0]
    return C, kept


def seeded_functional_maps(
    vertices: np.ndarray,
    evecs: np.ndarray,
    source: np.ndarray,
    target: np.ndarray,
    k_seed: int = 16,
    n_final: int = 50,
    n_samples: int = 500,
    n_targets: int = 3000,
    involutions: tuple[bool, ...] = (False,),
    target_vertices: np.ndarray | None = None,
    target_evecs: np.ndarray | None = None,
    trim: float = SEED_TRIM,
    device: str = "cpu",
) -> list[np.ndarray]:
    """The functional map of :func:`seeded_symmetry`, before its last point map: one per
    entry of ``involutions`` (the samples and the seed shared).

    Parameters
    ----------
    vertices, evecs, source, target, k_seed, n_final, n_samples, n_targets
        As in :func:`seeded_symmetry`.
    involutions : tuple of bool
        One ZoomOut per entry; True: the symmetry is its own inverse and ZoomOut fits
        the reversed pairs too (:func:`zoomout`; self-maps only).
    target_vertices, target_evecs
        As in :func:`seeded_symmetry`.
    trim : float
        The seed's functional map leaves out the pairs whose residual exceeds ``trim``
        times the median (:func:`seed_map`); 0 keeps every pair.
    device : {"cpu", "gpu"}
        Where ZoomOut's nearest-row searches run (:func:`nearest_images`).

    Returns
    -------
    list of (n_final, n_final) float64
        ``C``: vertex x maps to the vertex whose ``evecs[:, 1:n_final+1]`` row (of the
        target shape) is nearest to ``evecs[x, 1:n_final+1] @ C``; ``n_final`` clamped
        to the eigenfunctions there are.
    """
    n_final = min(n_final, evecs.shape[1] - 1)
    source = np.asarray(source, dtype=np.int64)
    target = np.asarray(target, dtype=np.int64)
    if not 1 <= k_seed <= n_final or len(source) < k_seed or len(source) != len(target):
        raise ValueError(
            f"need 1 <= k_seed ({k_seed}) <= n_final ({n_final}) and at least k_seed pairs, "
            f"got {len(source)} sources and {len(target)} targets"
        )
    if (target_vertices is None) != (target_evecs is None):
        raise ValueError("give both target_vertices and target_evecs, or neither")
    if any(involutions) and target_evecs is not None:
        raise ValueError("involution applies to self-maps only")
    if target_evecs is not None:
        n_final = min(n_final, target_evecs.shape[1] - 1)
    spread, n_samples = _spread(np.asarray(vertices, dtype=np.float64), n_samples, n_targets, n_final)
    phi = np.asarray(evecs, dtype=np.float64)[:, 1 : n_final + 1]
    if target_evecs is None:
        psi, target_spread = phi, spread
    else:
        psi = np.asarray(target_evecs, dtype=np.float64)[:, 1 : n_final + 1]
        target_spread = _spread(np.asarray(target_vertices, dtype=np.float64), n_samples, n_targets, n_final)[0]
    C = seed_map(phi[source, :k_seed], psi[target, :k_seed], trim)[0]
    samples = phi[spread[:n_samples]]
    targets = neighbours.search_rows(psi[target_spread], device)
    start = nearest_images(samples, targets, C, device)
    with threadpool_limits(1, user_api="blas"):  # (500, k) products: OpenBLAS's threads only slow them
        return [zoomout(samples, targets, start, k_seed, involution, device)[1] for involution in involutions]


def seeded_symmetry(
    vertices: np.ndarray,
    evecs: np.ndarray,
    source: np.ndarray,
    target: np.ndarray,
    k_seed: int = 16,
    n_final: int = 50,
    n_samples: int = 500,
    n_targets: int = 3000,
    points: np.ndarray | None = None,
    candidates: np.ndarray | None = None,
    target_vertices: np.ndarray | None = None,
    target_evecs: np.ndarray | None = None,
) -> np.ndarray:
    """A map from sparse correspondences, refined by ZoomOut to vertex precision: a
    self-map, or with ``target_vertices`` / ``target_evecs`` a map into another shape.

    The correspondences choose the symmetry, ZoomOut gives the precision: the functional
    map ``C`` (k_seed x k_seed) is the least-squares solution of ``phi[target, :k_seed]
    ~ phi[source, :k_seed] C`` without the pairs it cannot explain (:func:`seed_map`),
    it maps the ``n_samples`` farthest-point samples into
    the ``n_targets`` farthest-point targets, ZoomOut refines from ``k_seed`` to
    ``n_final`` eigenfunctions (:func:`zoomout`), and its last ``C``
    (:func:`seeded_functional_maps`) maps every vertex.
    A small ``k_seed`` averages out the correspondences' errors (a few wrong pairs, or
    images only as precise as a sampling) but must resolve the symmetry.

    Parameters
    ----------
    vertices : (N, 3) float array
        Positions, any length unit.
    evecs : (N, K) float array
        Laplace-Beltrami eigenfunctions, ascending eigenvalue, the constant mode first
        (as :func:`intrinsym.spectral.laplacian.eigenpairs` returns them), K > k_seed.
    source, target : (P,) int arrays
        Vertex pairs ``source[i] -> target[i]`` of the symmetry, P >= k_seed.
    k_seed : int
        Eigenfunctions (besides the constant) of the seed's functional map.
    n_final : int
        Eigenfunctions of the last ZoomOut level, at most K - 1 (fewer are clamped).
    n_samples, n_targets : int
        As in :func:`spectral_symmetry`.
    points, candidates : int arrays, optional
        Vertices to map (default: all) and the vertices their images are chosen from
        (default: all). The last map costs len(points) x len(candidates) products: on
        a subdivided working mesh, the input's own vertices are enough.
    target_vertices, target_evecs : (M, 3), (M, K) float arrays, optional
        A second shape: the map then goes from the first shape into this one (two-shape
        matching; ``target`` and ``candidates`` index its vertices).

    Returns
    -------
    (len(points),) int64
        Image of every mapped vertex (a vertex of ``candidates``) under the seeded
        symmetry, at vertex precision; raises ValueError if there are fewer pairs than
        ``k_seed`` or the sizes are out of range.
    """
    [C] = seeded_functional_maps(
        vertices,
        evecs,
        source,
        target,
        k_seed,
        n_final,
        n_samples,
        n_targets,
        target_vertices=target_vertices,
        target_evecs=target_evecs,
    )
    return map_points(C, evecs, points, candidates, target_evecs)


def map_points(
    C: np.ndarray,
    evecs: np.ndarray,
    points: np.ndarray | None = None,
    candidates: np.ndarray | None = None,
    target_evecs: np.ndarray | None = None,
    device: str = "cpu",
) -> np.ndarray:
    """The point map of a functional map ``C`` (k, k) in the eigenfunctions 1..k
    (:func:`nearest_images`, on ``device``), from ``points`` (default: all vertices) onto
    ``candidates`` (default: all vertices of the target shape, ``target_evecs`` or the
    same one).

    Returns
    -------
    (len(points),) int64
        A vertex of ``candidates`` for every point.
    """
    k = len(C)
    phi = np.asarray(evecs, dtype=np.float64)[:, 1 : k + 1]
    psi = phi if target_evecs is None else np.asarray(target_evecs, dtype=np.float64)[:, 1 : k + 1]
    points = np.arange(len(phi)) if points is None else np.asarray(points, dtype=np.int64)
    candidates = np.arange(len(psi)) if candidates is None else np.asarray(candidates, dtype=np.int64)
    return candidates[nearest_images(phi[points], psi[candidates], C, device)]
