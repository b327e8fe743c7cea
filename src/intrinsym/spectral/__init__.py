"""The Laplace-Beltrami spectrum and the spectral self-maps built on it.

:mod:`.laplacian` gives the operator and its smallest eigenpairs (the WKS / HKS unary,
:mod:`intrinsym.unary`, and the functional maps); :mod:`.spectral` finds the dominant
intrinsic self-symmetry from the eigenfunctions and refines a seeded map by functional
maps / ZoomOut (the candidates of the dense global map, :mod:`intrinsym.globalmap`);
:mod:`.neighbours` is their exact nearest-neighbour search in an embedding.
"""

from __future__ import annotations

from .laplacian import eigenpairs, laplace_beltrami, two_grid_eigenpairs
from .neighbours import nearest_rows, row_index, search_rows
from .spectral import seeded_functional_maps, seeded_symmetry, spectral_symmetry, symmetry_candidates, zoomout

__all__ = [
    "eigenpairs",
    "laplace_beltrami",
    "nearest_rows",
    "row_index",
    "search_rows",
    "seeded_functional_maps",
    "seeded_symmetry",
    "spectral_symmetry",
    "symmetry_candidates",
    "two_grid_eigenpairs",
    "zoomout",
]
