"""Partial functional maps: a part's map into its whole (Rodolà et al., CGF 2017).

A part M of a whole N (a shape with a side cut away, a scan with holes) sees only some
of N's eigenfunctions: M's Laplace-Beltrami spectrum is that of a smaller surface, and
the functional map between the two bases is a slanted diagonal, of slope about
area(M) / area(N). The partial functional map finds that map ``C`` together with a soft
indicator ``eta`` of M's counterpart on N, alternating

    E(C, v) = 1/q sum_j || C A_j - B_j(eta) ||_2          (descriptors, an L2,1 norm)
              + MU_W || W o C ||_F^2                        (the slanted diagonal)
              + MU_DC sum_f || C F_f - G_f C ||_F^2         (descriptor commutativity)
              + MU_A (1 - int eta / area(M))^2              (eta as large as M)
              + MU_P int |grad eta| / sqrt(area(N))         (its boundary short)

with ``eta = (tanh(2v - 1) + 1) / 2``, ``A_j`` and ``B_j(eta)`` the coefficients of the
j-th descriptor on M and of the same descriptor times ``eta`` on N, and
``W_ij = (lambda^N_i - lambda^M_j) / lambda^N_max``. The C-step is iteratively
reweighted least squares, the v-step L-BFGS-B. The vertex map is then refined by ZoomOut
restricted to the counterpart (``eta > 1/2``), the bases growing along the slope.

The descriptors are given as functions on both meshes (local ones, which a cut far
away leaves alone: :func:`intrinsym.globalmap.part_map.part_descriptors`), each scaled
to unit L2 norm on the whole and by the same factor on the part. The constants below
were chosen on 10 of the 125 SHREC'16 partial shapes, with wave-kernel densities as the
descriptors, and held on the other 115 and with the spin images (docs/results.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.optimize import minimize
from scipy.sparse.linalg import LinearOperator, cg

from .._threads import one_blas_thread
from ..spectral.neighbours import nearest_rows

__all__ = ["PartialMap", "gradient_operator", "partial_functional_map", "restricted_zoomout"]

#: Eigenpairs each shape brings (the constant one included).
EIGENPAIRS = 121
#: The whole's basis size of the alternating solve; the part's follows the slope.
BASIS = 60
#: Descriptors the commutativity term uses (evenly spread over the given ones).
COMMUTING = 15
#: Weights of the slanted diagonal, the commutativity, the area and the boundary.
MU_W, MU_DC, MU_A, MU_P = 10.0, 3.0, 5.0, 0.02
#: The C-step's conjugate gradients: relative residual and iteration cap.
CG_RTOL, CG_ITERATIONS = 1e-10, 2000
#: Alternations; reweightings per C-step; L-BFGS-B iterations per v-step.
ROUNDS, REWEIGHTINGS, V_ITERATIONS = 3, 3, 80
#: ZoomOut: the whole's basis grows to this size in these steps, fitted on this many of
#: the part's vertices (a fixed subsample: seed 0).
ZOOMOUT_BASIS, ZOOMOUT_STEP, ZOOMOUT_VERTICES = 100, 10, 2000


@dataclass(frozen=True)
class PartialMap:
    """A part's vertex map into its whole, from :func:`partial_functional_map`.

    Attributes
    ----------
    images : (N_part,) int64
        Vertex of the whole of every vertex of the part.
    indicator : (N_whole,) float64 in [0, 1]
        ``eta``: where on the whole the part lies.
    C : (k_whole, k_part) float64
        The partial functional map of the last alternation (push-forward, part to whole).
    """

    images: np.ndarray
    indicator: np.ndarray
    C: np.ndarray


def gradient_operator(vertices: np.ndarray, faces: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """The per-face gradient of piecewise-linear functions on a triangle mesh.

    Written here rather than taken from a mesh library: a sparse operator whose rows
    are laid out for the boundary term's gradient (``G.T``) is all that is needed.

    Parameters
    ----------
    vertices : (N, 3) float array
    faces : (F, 3) int array

    Returns
    -------
    G : (3F, N) scipy.sparse.csr_matrix
        ``(G @ f).reshape(3, F).T`` is the gradient of the vertex function ``f`` on
        every face (units of f per length); degenerate faces get zero rows.
    face_areas : (F,) float64
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    normal = np.cross(p1 - p0, p2 - p0)
    twice_area = np.linalg.norm(normal, axis=1)
    areas = twice_area / 2
    safe = np.where(twice_area > 0, twice_area, 1.0)
    unit = normal / safe[:, None]
    # grad phi_i = n x (opposite edge, counter-clockwise) / (2 area)
    grads = [np.cross(unit, b - a) / safe[:, None] for a, b in ((p1, p2), (p2, p0), (p0, p1))]
    grads = [np.where(twice_area[:, None] > 0, g, 0.0) for g in grads]
    n_f = len(f)
    rows = np.concatenate([np.arange(n_f) + axis * n_f for axis in range(3) for _ in range(3)])
    cols = np.concatenate([f[:, corner] for _ in range(3) for corner in range(3)])
    vals = np.concatenate([grads[corner][:, axis] for axis in range(3) for corner in range(3)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * n_f, len(v))), areas


def _eta(v: np.ndarray) -> np.ndarray:
    return 0.5 * (np.tanh(2 * v - 1) + 1)


def _part_basis(evals_part: np.ndarray, evals_whole: np.ndarray, k_whole: int) -> int:
    """The part's basis size whose largest eigenvalue is the whole's ``k_whole``-th (the slope)."""
    k = np.searchsorted(evals_part, evals_whole[k_whole - 1], side="right")
    return int(np.clip(k, 5, len(evals_part)))


def _scaled(descriptors: tuple[np.ndarray, np.ndarray], mass_whole: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The part's and the whole's descriptor functions, each column scaled to unit L2
    norm on the whole, the same factor on the part."""
    part, whole = (np.asarray(d, dtype=np.float64) for d in descriptors)
    norm = np.sqrt((mass_whole[:, None] * whole**2).sum(axis=0))
    scale = 1.0 / np.maximum(norm, np.finfo(np.float64).tiny)
    return part * scale, whole * scale


def _multipliers(
    part: tuple[np.ndarray, np.ndarray, np.ndarray], whole: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """The multiplication operators ``F_f`` (on the part's basis) and ``G_f`` (on the
    whole's) of ``COMMUTING`` descriptors, each scaled by its largest value on the whole.
    ``part`` and ``whole``: (basis, mass, descriptors).

    Returns
    -------
    F : (COMMUTING, k_part, k_part) float64
    G : (COMMUTING, k_whole, k_whole) float64
    """
    phi, m_part, d_part = part
    psi, m_whole, d_whole = whole
    cols = np.unique(np.linspace(0, d_whole.shape[1] - 1, COMMUTING).round().astype(int))
    s = 1.0 / np.abs(d_whole[:, cols]).max(axis=0)
    f = np.stack([phi.T @ ((m_part * d_part[:, c] * sc)[:, None] * phi) for c, sc in zip(cols, s)])
    g = np.stack([psi.T @ ((m_whole * d_whole[:, c] * sc)[:, None] * psi) for c, sc in zip(cols, s)])
    return f, g


def commutativity_gradient(c: np.ndarray, f: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Half the gradient of ``mean_f ||C F_f - G_f C||_F^2`` (symmetric ``F_f``, ``G_f``):
    ``mean_f (C F_f - G_f C) F_f - G_f (C F_f - G_f C)``, the term's quadratic form
    applied to ``C`` (k_whole, k_part)."""
    r = c @ f - g @ c  # (n, k_w, k_p)
    return np.mean(r @ f - g @ r, axis=0)


def _solve_normal_equations(
    gram: np.ndarray,
    w_sq: np.ndarray,
    mult: tuple[np.ndarray, np.ndarray],
    rhs: np.ndarray,
    inverses: np.ndarray,
    c: np.ndarray | None,
) -> np.ndarray:
    """``C gram + MU_W W^2 o C + MU_DC Q(C) = rhs`` by conjugate gradients from ``c``,
    preconditioned by the inverses of the row blocks, (k_whole, k_part, k_part)."""
    k_w, k_p = rhs.shape
    n = k_w * k_p

    def apply(x: np.ndarray) -> np.ndarray:
        x = x.reshape(k_w, k_p)
        return (x @ gram + MU_W * w_sq * x + MU_DC * commutativity_gradient(x, *mult)).ravel()

    def precondition(x: np.ndarray) -> np.ndarray:
        return np.einsum("ijk,ik->ij", inverses, x.reshape(k_w, k_p)).ravel()

    operator = LinearOperator((n, n), matvec=apply, dtype=np.float64)
    preconditioner = LinearOperator((n, n), matvec=precondition, dtype=np.float64)
    x0 = None if c is None else c.ravel()
    solution, _ = cg(operator, rhs.ravel(), x0=x0, rtol=CG_RTOL, atol=0.0, maxiter=CG_ITERATIONS, M=preconditioner)
    return solution


def _c_step(
    a: np.ndarray, b: np.ndarray, w_sq: np.ndarray, mult: tuple[np.ndarray, np.ndarray], c: np.ndarray | None
) -> np.ndarray:
    """IRLS for ``min_C 1/q sum_j ||C a_j - b_j|| + MU_W sum W_ij^2 C_ij^2 + MU_DC mean_f ||C F_f - G_f C||^2``.

    Each reweighting solves its normal equations, ``C gram + MU_W W^2 o C + MU_DC Q(C) =
    rhs``, by conjugate gradients from the last ``C``, preconditioned by their blocks of
    one row of ``C`` each: the dense system, (k_whole k_part)^2, took 0.3-1 s per solve.
    """
    k_p, n_d = a.shape
    k_w = b.shape[0]
    f, g = mult
    f_sq = np.mean(f @ f, axis=0)
    g_sq_diag = np.mean(np.einsum("nij,nji->ni", g, g), axis=0)  # (G_f^2)_ii, averaged
    g_diag = g[:, np.arange(k_w), np.arange(k_w)]  # (n, k_w)
    for _ in range(REWEIGHTINGS):
        if c is None:
            weight = np.ones(n_d)
        else:
            res = np.linalg.norm(c @ a - b, axis=0)
            weight = 1.0 / np.maximum(res, 1e-6 * max(res.max(), 1e-12))
        gram = (a * weight) @ a.T / (2 * n_d)
        rhs = (b * weight) @ a.T / (2 * n_d)

        # row i's diagonal block: gram + MU_W diag(W_i^2) + MU_DC mean_f (F^2 + (G^2)_ii - 2 G_ii F)
        blocks = (
            gram
            + MU_W * w_sq[:, :, None] * np.eye(k_p)
            + MU_DC * (f_sq + g_sq_diag[:, None, None] * np.eye(k_p) - 2 * np.einsum("ni,njk->ijk", g_diag, f) / len(f))
        )
        solution = _solve_normal_equations(gram, w_sq, mult, rhs, np.linalg.inv(blocks), c)
        c = solution.reshape(k_w, k_p)
    assert c is not None
    return c


def _v_step(
    v0: np.ndarray,
    ca: np.ndarray,
    psi: np.ndarray,
    mass: np.ndarray,
    d_whole: np.ndarray,
    area_part: float,
    grad: sp.csr_matrix,
    face_areas: np.ndarray,
) -> np.ndarray:
    """L-BFGS-B on ``v`` for a fixed ``C`` (``ca`` = C A)."""
    n_d = d_whole.shape[1]
    unit = np.sqrt(mass.sum())
    eps = 1e-3 / unit

    def energy(v: np.ndarray) -> tuple[float, np.ndarray]:
        t = np.tanh(2 * v - 1)
        e = 0.5 * (t + 1)
        residual = psi.T @ ((mass * e)[:, None] * d_whole) - ca
        norms = np.sqrt((residual**2).sum(axis=0) + 1e-20)
        g_data = mass * (d_whole * (psi @ (residual / norms))).sum(axis=1) / n_d
        cover = (mass * e).sum() / area_part
        g_area = -2 * MU_A * (1 - cover) * mass / area_part
        gr = (grad @ e).reshape(3, -1).T
        gn = np.sqrt((gr**2).sum(axis=1) + eps**2)
        g_per = MU_P * (grad.T @ ((face_areas / gn)[:, None] * gr).T.ravel()) / unit
        value = norms.sum() / n_d + MU_A * (1 - cover) ** 2 + MU_P * (face_areas * gn).sum() / unit
        return value, (g_data + g_area + g_per) * (1 - t**2)

    return minimize(energy, v0, jac=True, method="L-BFGS-B", options={"maxiter": V_ITERATIONS}).x


def restricted_zoomout(
    images: np.ndarray,
    part: tuple[np.ndarray, np.ndarray],
    whole: tuple[np.ndarray, np.ndarray],
    keep: np.ndarray,
) -> np.ndarray:
    """ZoomOut from the whole's ``BASIS`` to ``ZOOMOUT_BASIS`` functions, the part's basis
    following the slope, images only among the whole's vertices ``keep``. The map is the
    pull-back fitted on a fixed subsample of the part.

    Parameters
    ----------
    images : (N_part,) int
        The whole's vertex of every vertex of the part: the map to refine.
    part, whole : tuple (evals, evecs)
        Ascending Laplace-Beltrami eigenvalues (K,) and M-orthonormal eigenfunctions
        (N, K) of each; the whole's K >= ``ZOOMOUT_BASIS``.
    keep : (N_whole,) bool
        The whole's vertices the images may take.

    Returns
    -------
    (N_part,) int64
    """
    evals_p, phi = part
    evals_w, psi = whole
    rng = np.random.default_rng(0)
    sub = np.sort(rng.choice(len(phi), size=min(ZOOMOUT_VERTICES, len(phi)), replace=False))
    candidates = np.flatnonzero(keep)
    sub_images = images[sub]
    levels = list(range(BASIS, ZOOMOUT_BASIS + 1, ZOOMOUT_STEP))
    for level, k_w in enumerate(levels):
        k_p = _part_basis(evals_p, evals_w, k_w)
        c = np.linalg.lstsq(phi[sub, :k_p], psi[sub_images, :k_w], rcond=None)[0]  # (k_p, k_w)
        embedded = psi[candidates, :k_w] @ c.T
        if level == len(levels) - 1:
            return candidates[nearest_rows(phi[:, :k_p], embedded)]
        sub_images = candidates[nearest_rows(phi[sub, :k_p], embedded)]
    return images


# (N, 60) products a few hundred times: OpenBLAS's threads made them 2.9x slower
# (13.5 s against 4.7 s on a SHREC'16 pair, the 2-core Xeon VM)
@one_blas_thread
def partial_functional_map(
    part: tuple[np.ndarray, np.ndarray, np.ndarray],
    whole: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    descriptors: tuple[np.ndarray, np.ndarray],
) -> PartialMap:
    """Map a part of a shape into the whole shape (Rodolà et al. 2017, see the module).

    Both shapes in one length unit (so that their areas compare).

    Parameters
    ----------
    part : tuple (evals, evecs, mass)
        The part's ascending Laplace-Beltrami eigenvalues (K,), M-orthonormal
        eigenfunctions (N_part, K) and lumped vertex areas (N_part,); K >= ``BASIS``.
    whole : tuple (evals, evecs, mass, vertices, faces)
        The same of the whole (K >= ``ZOOMOUT_BASIS``), with its mesh (N_whole, 3) and (F, 3).
    descriptors : pair of (N_part, Q) and (N_whole, Q) float arrays
        The same Q descriptor functions on the part and on the whole.

    Returns
    -------
    PartialMap
    """
    evals_p, evecs_p, mass_p = part
    evals_w, evecs_w, mass_w, vertices, faces = whole
    grad, face_areas = gradient_operator(vertices, faces)
    d_part, d_whole = _scaled(descriptors, mass_w)
    k_w = min(BASIS, len(evals_w))
    k_p = _part_basis(evals_p, evals_w, k_w)
    # contiguous copies: the v-step multiplies by them a few hundred times
    psi, phi = np.ascontiguousarray(evecs_w[:, :k_w]), np.ascontiguousarray(evecs_p[:, :k_p])
    a = phi.T @ (mass_p[:, None] * d_part)
    w_sq = ((evals_w[:k_w, None] - evals_p[None, :k_p]) / evals_w[k_w - 1]) ** 2
    mult = _multipliers((phi, mass_p, d_part), (psi, mass_w, d_whole))
    area_p = float(mass_p.sum())
    v = np.full(len(mass_w), 2.0)  # eta ~ 0.98: all of the whole at first
    c = None
    for round_ in range(ROUNDS):
        b = psi.T @ ((mass_w * _eta(v))[:, None] * d_whole)
        c = _c_step(a, b, w_sq, mult, c)
        if round_ == 0:
            # start eta from the part's indicator pushed forward to the whole
            pushed = psi @ (c @ (phi.T @ mass_p))
            pushed = np.clip(pushed / max(np.percentile(pushed, 99), 1e-9), 0.02, 0.98)
            v = np.clip(np.arctanh(np.clip(2 * pushed - 1, -0.96, 0.96)) / 2 + 0.5, -3, 3)
        v = _v_step(v, c @ a, psi, mass_w, d_whole, area_p, grad, face_areas)
    eta = _eta(v)
    c = _c_step(a, psi.T @ ((mass_w * eta)[:, None] * d_whole), w_sq, mult, c)
    keep = eta > 0.5
    if keep.sum() < 10:
        keep = np.ones(len(eta), dtype=bool)
    candidates = np.flatnonzero(keep)
    images = candidates[nearest_rows(phi, psi[candidates] @ c)]
    images = restricted_zoomout(images, (evals_p, evecs_p), (evals_w, evecs_w), keep)
    return PartialMap(images.astype(np.int64), eta, c)
