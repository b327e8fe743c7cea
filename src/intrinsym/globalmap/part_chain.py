"""A part's vertex map into its whole, from the candidates to the map kept.

The order in which ``match`` builds and weighs a part's map (docs/method.md, "Matching a
part to its whole"): the extraction's map or the partial functional map, whichever
changes fewer of the part's distances (:func:`~intrinsym.globalmap.part_map.choose_part_map`);
its ZoomOut refinement; the least distorted round of its trilateration, polished; then
the hypotheses located from consistent clusters of descriptor matches
(:mod:`intrinsym.globalmap.part_hypothesis`), each trilaterated and polished; then the
blend of the map kept before the hypotheses and the hypotheses' maps, vertex by vertex
(:mod:`intrinsym.globalmap.part_blend`), trilaterated and polished. Each later map
replaces the one kept so far only where it changes fewer of the part's distances.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..surface import Surface
from .part_blend import blended_map
from .part_hypothesis import hypothesis_maps
from .part_map import (
    PartMapStats,
    blended_if_less_distorted,
    choose_part_map,
    hypothesis_if_less_distorted,
    part_descriptors,
    part_fmap_map,
    refine_part_map,
    refined_if_less_distorted,
    trilaterated_if_less_distorted,
    with_polish,
)
from .part_trilateration import polished_trilateration, trilaterated_maps

__all__ = ["part_vertex_map"]


def part_vertex_map(
    extraction_map: np.ndarray,
    part: Surface,
    whole: Surface,
    given: tuple[Surface, Surface],
    p: Params,
    marginals: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray | None, PartMapStats]:
    """The vertex map ``match`` keeps for a part (meshes, ``p.part_fmap`` on).

    Parameters
    ----------
    extraction_map : (N_part_input,) int
        The extraction's map: input vertex of the whole of every input vertex of the part.
    part, whole : Surface
        As ``match`` prepared them; the distortion is measured on their working meshes.
    given : (Surface, Surface)
        The part and the whole prepared without refinement (the meshes as given), on
        which the spectra, the descriptors, the refinements, the trilaterations and the
        hypotheses are solved.
    p : Params
        The spin images' parameters, ``part_hypotheses`` and ``part_proposals``.
    marginals : ((S, T) float, (S,) int, (T,) int) or None
        BP's marginals, their samples' input vertices of the part and their labels' of
        the whole; needed unless ``p.part_proposals`` is "descriptors".

    Returns
    -------
    vertex_map : (N_part_input,) int64 or None
        The kept map; None when the extraction's map stays.
    stats : PartMapStats
    """
    descriptors = part_descriptors(*given, p)
    image, stats = choose_part_map(extraction_map, part, whole, part_fmap_map(*given, descriptors))
    refined = refine_part_map(extraction_map if image is None else image, *given)
    better, stats = refined_if_less_distorted(refined, part, whole, stats)
    if better:
        image = refined
    kept = extraction_map if image is None else image
    located, stats = trilaterated_if_less_distorted(trilaterated_maps(kept, *given), part, whole, stats)
    if located is not None:
        image = refine_part_map(located, *given)
        stats = with_polish(image, part, whole, stats)
    on_given = None
    if marginals is not None:
        values, source, target = marginals
        on_given = (values, given[0].vertex_map[source], given[1].vertex_map[target])
    seeds = hypothesis_maps(*given, descriptors, p.part_hypotheses, marginals=on_given, proposals=p.part_proposals)
    finished = (polished_trilateration(seed, given, (part, whole)) for seed in seeds)
    polished = [m for m in finished if m is not None]
    before = extraction_map if image is None else image
    hypothesis, stats = hypothesis_if_less_distorted(polished, part, whole, stats)
    if hypothesis is not None:
        image = hypothesis
    if not polished:
        return image, stats
    blend = polished_trilateration(blended_map([before, *polished], *given), given, (part, whole))
    blended, stats = blended_if_less_distorted(blend, part, whole, stats)
    return (image if blended is None else blended), stats
