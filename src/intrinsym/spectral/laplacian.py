"""The Laplace-Beltrami operator of a mesh or point cloud and its smallest eigenpairs.

:func:`laplace_beltrami` builds the robust cotangent Laplacian (Sharp & Crane 2020);
:func:`eigenpairs` solves ``L phi = lambda M phi`` for the smallest eigenpairs, which the
WKS / HKS unary terms and the seeded ZoomOut are built on. On a large mesh it solves
first on a decimated copy and carries the result back (:func:`two_grid_eigenpairs`):
ARPACK's own work grows with the vertex count times its Lanczos basis (about 2k
vectors) and dominates the direct solve on large meshes.

A shape of several connected components has one zero eigenvalue per component (its
indicator function). Both solvers leave all but one out: they solve in the complement of
the indicators and put the constant function first, so the eigenfunctions are those of a
connected shape, whatever the number of components (a scan's floating islands, the
separate eyes and teeth of TOSCA's gorilla), and every consumer reads the non-trivial
ones from column 1.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from cholespy import CholeskySolverD, MatrixType
from scipy.linalg import eigh
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import LinearOperator, eigsh
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from .._threads import one_blas_thread

__all__ = [
    "COARSE_EXTRA",
    "COARSE_PER_PAIR",
    "FINE_PER_COARSE",
    "POLISH_STEPS",
    "eigenpairs",
    "laplace_beltrami",
    "two_grid_eigenpairs",
]

#: Eigenpairs solved on the decimated mesh beyond the ``k`` asked for: the subspace
#: carried back is larger than the one kept, so that its last wanted vectors converge.
COARSE_EXTRA = 20
#: The decimated mesh must have at least this many vertices per eigenpair solved on it
#: (else the fine mesh is solved directly): the 120th eigenfunction of a TOSCA shape
#: varies over about 1 / sqrt(120) of sqrt(area), which 40 vertices per pair resolve.
COARSE_PER_PAIR = 40
#: The two-grid solve is used on meshes of more than this many times the coarse size;
#: below, it gains little over the direct solve (0.8x on TOSCA's centaur, 15,768
#: vertices; docs/notes/2026-11-28-speed-behind-the-defaults.md), so smaller meshes keep their exact eigenpairs.
FINE_PER_COARSE = 2
#: Inverse iterations on the fine mesh, each followed by a Rayleigh-Ritz projection:
#: three bring the eigenvalues of TOSCA meshes within about 2e-3 of the direct solve's,
#: which leaves BP's marginals unchanged (fewer moved the maps; docs/notes/2026-11-28-speed-behind-the-defaults.md).
POLISH_STEPS = 3
#: Coarse vertices each fine vertex is interpolated from (inverse squared distance).
_PROLONGATION_NEIGHBOURS = 3


def laplace_beltrami(vertices: np.ndarray, faces: np.ndarray | None = None) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Cotangent stiffness and lumped mass matrices of a mesh or a point cloud.

    Uses the intrinsic-Delaunay "robust" Laplacian of Sharp & Crane (2020): for a mesh
    it tolerates non-manifold and badly shaped triangles, and for a point cloud
    (``faces`` None) it builds local tufted triangulations from 30 nearest neighbours.

    Parameters
    ----------
    vertices : (N, 3) float array
        Positions (length unit of the shape).
    faces : (F, 3) int array or None
        Triangles; None for a point cloud.

    Returns
    -------
    stiffness : (N, N) scipy.sparse.csr_matrix
        Symmetric positive semi-definite weak Laplacian (dimensionless).
    mass : (N, N) scipy.sparse.csr_matrix
        Diagonal lumped mass (area per vertex, length^2).
    """
    import robust_laplacian

    v = np.ascontiguousarray(vertices, dtype=np.float64)
    if faces is None:
        stiffness, mass = robust_laplacian.point_cloud_laplacian(v)
    else:
        stiffness, mass = robust_laplacian.mesh_laplacian(v, np.ascontiguousarray(faces, dtype=np.int64))
    return sp.csr_matrix(stiffness), sp.csr_matrix(mass)


def _shifted_factor(stiffness: sp.csr_matrix, mass: sp.csr_matrix) -> tuple[CholeskySolverD, float]:
    """Sparse Cholesky factor of ``L - sigma M`` (cholespy, CHOLMOD's supernodal
    factorisation: 4x faster solves than SuperLU's LU on TOSCA meshes) and the shift.

    The shift, -1e-3 eigenvalues of the unit-area shape, lies far below the first
    non-zero eigenvalue (~25 for a unit-area sphere) yet makes the singular ``L``
    regular.
    """
    shift = -1e-3 / float(mass.sum())
    a = (stiffness - shift * mass).tocoo()
    factor = CholeskySolverD(stiffness.shape[0], a.row.astype(np.int32), a.col.astype(np.int32), a.data, MatrixType.COO)
    return factor, shift


def _indicators(stiffness: sp.csr_matrix, mass: sp.csr_matrix) -> sp.csr_matrix | None:
    """(N, C) M-orthonormal indicator functions of the C connected components of the
    stiffness matrix's graph (the null space of ``L``), None for a connected shape."""
    graph = stiffness.copy()
    graph.eliminate_zeros()
    n_components, label = connected_components(graph, directed=False)
    if n_components == 1:
        return None
    area = np.bincount(label, weights=mass.diagonal(), minlength=n_components)
    n = len(label)
    return sp.csr_matrix((1.0 / np.sqrt(area[label]), (np.arange(n), label)), shape=(n, n_components))


def _deflate(x: np.ndarray, indicators: sp.csr_matrix | None, mass: sp.csr_matrix) -> np.ndarray:
    """``x`` (N,) or (N, m) without its components along the indicators (M-orthogonal
    projection); ``x`` itself for a connected shape."""
    if indicators is None:
        return x
    return x - indicators @ (indicators.T @ (mass @ x))


def _with_constant(evals: np.ndarray, evecs: np.ndarray, mass: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """The M-normalised constant function (eigenvalue 0) put before deflated eigenpairs."""
    constant = np.full((len(evecs), 1), 1.0 / np.sqrt(float(mass.sum())))
    return np.concatenate([[0.0], evals]), np.hstack([constant, evecs])


def _zero_constant_modes(evals: np.ndarray, area: float) -> np.ndarray:
    # the constant modes come out at +-1e-15: exactly zero far below the unit 1 / area
    return np.where(evals < 1e-8 / area, 0.0, evals)


def _check_k(n: int, k: int) -> None:
    if not 2 <= k < n:
        raise ValueError(f"k must lie in [2, {n - 1}] for {n} points; got {k}")


@one_blas_thread
def eigenpairs(
    vertices: np.ndarray, faces: np.ndarray | None, k: int, coarse: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest Laplace-Beltrami eigenpairs, ``L phi = lambda M phi``.

    Solved by shift-invert Lanczos (ARPACK) about a small negative shift, which keeps
    ``L - sigma M`` positive definite although ``L`` is singular; its solves use a sparse
    Cholesky factor. The start vector is fixed, so the result is deterministic. With
    ``coarse`` > 0, a mesh of more than ``FINE_PER_COARSE`` times ``coarse`` vertices is solved by
    :func:`two_grid_eigenpairs` instead, when ``coarse`` holds ``COARSE_PER_PAIR``
    vertices for each of the ``k + COARSE_EXTRA`` pairs solved on it.

    Parameters
    ----------
    vertices : (N, 3) float array
    faces : (F, 3) int array or None
        None for a point cloud (always solved directly).
    k : int
        Number of eigenpairs, 2 <= k < N.
    coarse : int
        Vertices of the decimated mesh of the two-grid solve; 0 never decimates.

    Returns
    -------
    evals : (k,) float64
        Eigenvalues in ascending order, in 1 / length^2 (the first is ~0).
    evecs : (N, k) float64
        M-orthonormal eigenfunctions (unit: 1 / length).
    """
    n = len(vertices)
    _check_k(n, k)
    if faces is not None and n > FINE_PER_COARSE * coarse and coarse >= COARSE_PER_PAIR * (k + COARSE_EXTRA):
        return two_grid_eigenpairs(vertices, faces, k, coarse)
    stiffness, mass = laplace_beltrami(vertices, faces)
    factor, shift = _shifted_factor(stiffness, mass)
    indicators = _indicators(stiffness, mass)

    def solve(b: np.ndarray) -> np.ndarray:
        x = np.empty(n)
        factor.solve(np.ascontiguousarray(b, dtype=np.float64).reshape(n), x)
        # the indicators are eigenvectors of the shifted inverse: their complement is
        # invariant, and the deflated operator keeps ARPACK's M-symmetry
        return _deflate(x, indicators, mass)

    inverse = LinearOperator((n, n), matvec=solve, dtype=np.float64)
    v0 = _deflate(np.random.default_rng(0).standard_normal(n), indicators, mass)
    wanted = k if indicators is None else k - 1
    evals, evecs = eigsh(stiffness, k=wanted, M=mass, sigma=shift, which="LM", v0=v0, OPinv=inverse)
    order = np.argsort(evals)
    evals, evecs = evals[order], evecs[:, order]
    if indicators is not None:
        evals, evecs = _with_constant(evals, evecs, mass)
    return _zero_constant_modes(evals, float(mass.sum())), evecs


def two_grid_eigenpairs(vertices: np.ndarray, faces: np.ndarray, k: int, coarse: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`eigenpairs` of a large mesh, solved on a decimated copy and refined on it.

    The mesh is decimated to ``coarse`` vertices (quadric error metric,
    fast-simplification), whose ``k + COARSE_EXTRA`` smallest eigenpairs are solved
    directly and interpolated back to the mesh (each vertex from its three nearest coarse
    vertices). ``POLISH_STEPS`` inverse iterations with the mesh's own shifted Cholesky
    factor, each followed by a Rayleigh-Ritz projection onto the iterated subspace, then
    remove the interpolation's and the decimation's error, which lies at frequencies far
    above the ``k``-th (a two-grid scheme, Xu & Zhou 2001). The eigenvalues are Ritz
    values of the mesh's own operator, so they bound the exact ones from above.

    Parameters
    ----------
    vertices : (N, 3) float array
    faces : (F, 3) int array
    k : int
        Number of eigenpairs, 2 <= k < N.
    coarse : int
        Vertices of the decimated mesh, more than ``k + COARSE_EXTRA``.

    Returns
    -------
    evals : (k,) float64
    evecs : (N, k) float64
        As :func:`eigenpairs`.
    """
    import fast_simplification

    v = np.array(vertices, dtype=np.float64)
    n = len(v)
    _check_k(n, k)
    m = k + COARSE_EXTRA
    if not m < coarse < n:
        raise ValueError(f"coarse must lie in ({m}, {n}) for {k} eigenpairs of {n} vertices; got {coarse}")
    coarse_v, coarse_f = fast_simplification.simplify(v, np.array(faces, dtype=np.int64), 1.0 - coarse / n)
    m = min(m, len(coarse_v) - 1)
    basis = eigenpairs(coarse_v, coarse_f, m)[1]
    stiffness, mass = laplace_beltrami(v, faces)
    indicators = _indicators(stiffness, mass)
    if indicators is not None:
        basis = basis[:, 1:]  # the coarse constant: the mesh's comes back below
    dist, near = cKDTree(coarse_v).query(v, k=_PROLONGATION_NEIGHBOURS)
    weight = 1.0 / np.maximum(dist, 1e-12) ** 2
    weight /= weight.sum(axis=1, keepdims=True)
    rows = np.arange(0, near.size + 1, _PROLONGATION_NEIGHBOURS)
    x = sp.csr_matrix((weight.ravel(), near.ravel(), rows), shape=(n, len(coarse_v))) @ basis
    factor, _ = _shifted_factor(stiffness, mass)
    for _ in range(POLISH_STEPS):
        b = np.ascontiguousarray(mass @ x)
        x = np.empty_like(b)
        factor.solve(b, x)
        x = _deflate(x, indicators, mass)
        reduced_l, reduced_m = x.T @ (stiffness @ x), x.T @ (mass @ x)
        # OpenBLAS's threads slow these down on two cores (michael1: 0.21 s -> 0.007 s for
        # the three eigh, 0.34 -> 0.17 s for the rotations)
        with threadpool_limits(1, user_api="blas"):
            evals, ritz = eigh((reduced_l + reduced_l.T) / 2, (reduced_m + reduced_m.T) / 2)
            x = x @ ritz
    if indicators is None:
        return _zero_constant_modes(evals[:k], float(mass.sum())), x[:, :k]
    evals, evecs = _with_constant(evals[: k - 1], x[:, : k - 1], mass)
    return _zero_constant_modes(evals, float(mass.sum())), evecs
