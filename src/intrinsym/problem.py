"""The sampled problem: what every stage after sampling reads.

:func:`sampled` turns two prepared surfaces (one, twice, for :func:`intrinsym.detect`)
and their samples into a :class:`Problem`: the source graph between the source samples
(the MRF's edges) with its geodesic lengths, and the target spacing that sets the
pairwise term's width. The pipeline's stages (:mod:`intrinsym.pipeline`) take it
instead of the ten arrays and surfaces it holds.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .errors import ParameterError
from .geodesics import geodesics
from .mesh import sampling
from .params import Params
from .surface import Surface

__all__ = ["Problem", "sampled", "source_graph"]


@dataclass(frozen=True)
class Problem:
    """Two prepared surfaces, the samples on each and the source graph between the source samples.

    Attributes
    ----------
    src, tgt : Surface
        The source and target working surfaces (one surface twice when self-matching).
    ps, pt : (S,), (T,) int64
        Working vertices of the source and target samples.
    edges : (E, 2) int64
        Source samples with adjacent geodesic Voronoi cells.
    edge_length : (E,) float64
        Their geodesic lengths (normalised units).
    t_spacing : float
        Target sample spacing (normalised units): ``target_spacing`` or the spacing of
        ``len(pt)`` samples on the target's area (unit area but for a part).
    self_match : bool
        The shape matched to itself (:func:`intrinsym.detect`).
    """

    src: Surface
    tgt: Surface
    ps: np.ndarray
    pt: np.ndarray
    edges: np.ndarray
    edge_length: np.ndarray
    t_spacing: float
    self_match: bool

    @cached_property
    def source_points(self) -> np.ndarray:
        """(S, 3) float64: the source samples, normalised coordinates."""
        return self.src.shape.vertices[self.ps]

    @cached_property
    def target_points(self) -> np.ndarray:
        """(T, 3) float64: the target samples, normalised coordinates."""
        return self.tgt.shape.vertices[self.pt]

    @cached_property
    def source_vertex(self) -> np.ndarray:
        """(S,) int64: the input vertex of the source shape nearest each source sample."""
        return self.src.nearest_input_vertex(self.source_points)

    @cached_property
    def target_vertex(self) -> np.ndarray:
        """(T,) int64: the input vertex of the target shape nearest each target sample."""
        return self.tgt.nearest_input_vertex(self.target_points)


def source_graph(src: Surface, ps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The source graph: (E, 2) int64 edges between samples with adjacent geodesic
    Voronoi cells, and their (E,) geodesic lengths."""
    edges = geodesics.voronoi_adjacency(src.graph, ps)
    if len(edges) == 0:
        raise ParameterError(f"{src.shape.path or 'shape'}: the source samples form no neighbourhood graph")
    return edges, geodesics.pair_distances(src.graph, ps[edges])


def sampled(
    src: Surface,
    tgt: Surface,
    ps: np.ndarray,
    pt: np.ndarray,
    p: Params,
    self_match: bool,
    target_area: float = 1.0,
) -> Problem:
    """The :class:`Problem` of samples ``ps`` on ``src`` and ``pt`` on ``tgt`` under ``p``;
    ``target_area``: the target's area in the normalised unit (below 1 for a part)."""
    t_spacing = p.target_spacing or sampling.spacing_for_count(target_area, len(pt))
    edges, edge_length = source_graph(src, ps)
    return Problem(src, tgt, ps, pt, edges, edge_length, t_spacing, self_match)
