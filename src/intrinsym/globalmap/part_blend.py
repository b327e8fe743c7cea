"""A part's candidate maps into its whole, blended vertex by vertex.

The map ``match`` keeps for a part and the hypotheses' maps
(:mod:`intrinsym.globalmap.part_hypothesis`) are each often right on a region of the part
and wrong on another: a torso placed right with a leg on the other leg, a leg right on a
body slid along its length. The test that weighs them whole
(:func:`intrinsym.globalmap.part_map.least_distorted`) keeps one of them, wrong region
included. The blend takes every vertex's image from the candidate that changes the part's
distances least around it: the local distortion of
:func:`intrinsym.globalmap.distortion.local_distortion_on_graph`, the mean change of the
distances within ``LOCAL_RADIUS`` of the vertex's nearest measured sample, as Kim, Lipman and
Funkhouser's blended intrinsic maps (SIGGRAPH 2011) weigh their conformal maps by their
local distortion. ``match`` then trilaterates and polishes the blend as it does a
hypothesis (:func:`intrinsym.globalmap.part_trilateration.polished_trilateration`): where
the pieces disagree at their seams the trilateration relocates the vertices from the
anchors the blend keeps consistent. The result is weighed against the map kept so far by
the same test.
"""

from __future__ import annotations

import numpy as np

from ..surface import Surface, input_map, working_map
from .distortion import local_distortion_on_graph

__all__ = ["blended_map"]


def blended_map(maps: list[np.ndarray], part: Surface, whole: Surface) -> np.ndarray:
    """Every vertex of a part sent where the candidate map least distorted around it sends it.

    Parameters
    ----------
    maps : list of (N_part_input,) int, at least one
        Input vertex of the whole of every input vertex of the part, -1 for none.
    part, whole : Surface
        Meshes prepared in one unit (:func:`intrinsym.surface.prepare_pair`); the local
        distortion is measured on their working graphs, from farthest-point samples
        ``LOCAL_SPACING`` apart (seed 0).

    Returns
    -------
    (N_part_input,) int64
        The blend; a vertex no candidate measures (no image, or no mapped pair around it)
        takes the first map's image. Ties go to the earlier map.
    """
    if not maps:
        raise ValueError("blending needs at least one map")
    working = np.array([working_map(m, part, whole) for m in maps])
    local = np.array(
        [local_distortion_on_graph(part.graph, part.shape.vertices, w, target_graph=whole.graph) for w in working]
    )
    local[np.isnan(local)] = np.inf
    choice = np.argmin(local, axis=0)
    return input_map(working[choice, np.arange(working.shape[1])], part, whole)
