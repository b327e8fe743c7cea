"""Symmetries from the marginals: peak tracking and region growing (paper Sec. 5.1), then
completion, refinement and the identity decision.

:mod:`.extract` finds the peaks of the marginals, grows consistent regions from them and
decides whether the result is the identity; its Numba kernels are :mod:`._kernels`.
:mod:`.symmetry` holds the records (:class:`ExtractParams`, :class:`Symmetry`,
:class:`Extraction`); :mod:`.support` what extraction needs beside the marginals;
:mod:`.reflection` tests whether a self-map acts as a reflection (the global/partial
decision); :mod:`.records` writes the symmetries in input-vertex indices.
"""

from __future__ import annotations

from .extract import consistency, extract_from_support, is_identity, mapped_symmetry, query, query_from_support
from .records import part_mask, part_vertices
from .support import SourceGraph, Support
from .symmetry import Extraction, ExtractParams, Symmetry

__all__ = [
    "ExtractParams",
    "Extraction",
    "SourceGraph",
    "Support",
    "Symmetry",
    "consistency",
    "extract_from_support",
    "is_identity",
    "mapped_symmetry",
    "part_mask",
    "part_vertices",
    "query",
    "query_from_support",
]
