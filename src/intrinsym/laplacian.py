"""The Laplace-Beltrami operator of a mesh or point cloud and its smallest eigenpairs.

:func:`laplace_beltrami` builds the robust cotangent Laplacian (Sharp & Crane 2020);
:func:`eigenpairs` solves ``L phi = lambda M phi`` for the smallest eigenpairs, which the
WKS / HKS unary terms and the seeded ZoomOut are built on. On a large mesh it solves
first on a decimated copy and carries the result back (:func:`two_grid_eigenpairs`):
ARPACK's own work grows with the vertex count times its Lanczos basis (about 2k
vectors) and dominates the direct solve on large meshes.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from cholespy import CholeskySolverD, MatrixType
from scipy.linalg import eigh
from scipy.sparse.linalg import LinearOperator, eigsh
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

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
#: below, it is barely faster than the direct solve (docs/benchmarks.md), so smaller
#: meshes keep their exact eigenpairs.
FINE_PER_COARSE = 5
#: Inverse iterations on the fine mesh, each followed by a Rayleigh-Ritz projection:
#: three bring the eigenvalues of TOSCA meshes within about 2e-3 of the direct solve's,
#: which leaves BP's marginals unchanged (fewer moved the maps; docs/benchmarks.md).
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


def _zero_constant_modes(evals: np.ndarray, area: float) -> np.ndarray:
    # the constant modes come out at +-1e-15: exactly zero far below the unit 1 / area
    return np.where(evals < 1e-8 / area, 0.0, evals)


def _check_k(n: int, k: int) -> None:
    if not 2 <= k < n:
        raise ValueError(f"k must lie in [2, {n - 1}] for {n} points; got {k}")


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

    def solve(b: np.ndarray) -> np.ndarray:
        x = np.empty(n)
        factor.solve(np.ascontiguousarray(b, dtype=np.float64).reshape(n), x)
        return x

    inverse = LinearOperator((n, n), matvec=solve, dtype=np.float64)
    v0 = np.random.default_rng(0).standard_normal(n)
    evals, evecs = eigsh(stiffness, k=k, M=mass, sigma=shift, which="LM", v0=v0, OPinv=inverse)
    order = np.argsort(evals)
    return _zero_constant_modes(evals[order], float(mass.sum())), evecs[:, order]


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
    dist, near = cKDTree(coarse_v).query(v, k=_PROLONGATION_NEIGHBOURS)
    weight = 1.0 / np.maximum(dist, 1e-12) ** 2
    weight /= weight.sum(axis=1, keepdims=True)
    rows = np.arange(0, near.size + 1, _PROLONGATION_NEIGHBOURS)
    x = sp.csr_matrix((weight.ravel(), near.ravel(), rows), shape=(n, len(coarse_v))) @ basis
    stiffness, mass = laplace_beltrami(v, faces)
    factor, _ = _shifted_factor(stiffness, mass)
    for _ in range(POLISH_STEPS):
        b = np.ascontiguousarray(mass @ x)
        x = np.empty_like(b)
        factor.solve(b, x)
        reduced_l, reduced_m = x.T @ (stiffness @ x), x.T @ (mass @ x)
        # OpenBLAS's threads slow these down on two cores (michael1: 0.21 s -> 0.007 s for
        # the three eigh, 0.34 -> 0.17 s for the rotations)
        with threadpool_limits(1, user_api="blas"):
            evals, ritz = eigh((reduced_l + reduced_l.T) / 2, (reduced_m + reduced_m.T) / 2)
            x = x @ ritz
    return _zero_constant_modes(evals[:k], float(mass.sum())), x[:, :k]
