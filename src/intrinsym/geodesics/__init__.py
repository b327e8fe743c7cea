"""Geodesic distances: shortest paths in a graph on the surface (paper Sec. 3, the
distances d(x, y) of the pairwise term, Eq. 6, and of the extraction, Sec. 5.1).

:mod:`.geodesics` builds the graph (mesh edges plus short chords, or a point cloud's
neighbours) and answers distances from sources, between sample pairs and within balls;
its Numba kernels are :mod:`._dijkstra` (a bounded Dijkstra) and :mod:`._chords`.
"""

from __future__ import annotations

from . import geodesics
from .geodesics import *  # noqa: F403 (the names of its __all__)

__all__ = list(geodesics.__all__)
