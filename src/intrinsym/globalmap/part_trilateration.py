"""A part's map into its whole trilaterated from the anchors on which it keeps its distances.

A partial functional map (or the extraction's) of a part into its whole is often right
on most of the part and wrong on a region of it: a leg sent to the other pair of legs,
the head turned onto the neck. Where it is right it keeps the part's geodesic distances,
and those right images locate every other vertex: each vertex of the part is sent to
the vertex of the whole whose distances to the right images best repeat its own
distances to their anchors (within :data:`TRILATERATION_REACH` of it). The right images
are found without the truth, as the largest set of farthest-point anchors whose
mutual distances the map keeps (:func:`anchor_core`). ``match`` keeps the trilaterated
map only where it changes fewer of the part's short distances than the map it comes
from (:func:`intrinsym.globalmap.part_map.choose_part_map`'s test).

Unlike :func:`intrinsym.globalmap.refine.trilaterate`, which descends from each image
to a nearby vertex of the same shape, the search here is global over the whole: a region
mapped wholly wrong has no right image nearby to descend to.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .._threads import map_ranges
from ..geodesics.geodesics import distances_from
from ..mesh.sampling import farthest_point_sampling
from ..surface import Surface, input_map, working_map
from .part_map import PART_MAP_CHANGE, least_distorted, refine_part_map

__all__ = [
    "CORE_AGREEMENT",
    "TRILATERATION_ANCHORS",
    "TRILATERATION_REACH",
    "TRILATERATION_ROUNDS",
    "anchor_core",
    "best_images",
    "polished_trilateration",
    "trilaterated_maps",
]

#: Farthest-point anchors spread over the part's mapped vertices (Euclidean, seed 0).
TRILATERATION_ANCHORS = 64
#: A vertex is located from the anchors within this geodesic distance of it on the part
#: (sqrt(area) of the whole, the pair's common unit), and two anchors are compared
#: when they lie this close: a cut or a hole lengthens the part's geodesics against the
#: whole's more the farther they reach. Set once, not tuned (docs/results.md gives
#: 0.35 and 0.70 beside it).
TRILATERATION_REACH = 0.5
#: An anchor stays in the core while the map keeps its distance to at least this share
#: of the core's anchors within reach (within ``PART_MAP_CHANGE``).
CORE_AGREEMENT = 0.9
#: A vertex with fewer core anchors within reach keeps its image.
MIN_ANCHORS = 3
#: Rounds of :func:`trilaterated_maps`, each from the previous round's core.
TRILATERATION_ROUNDS = 3
#: Vertices of the whole :func:`best_images` costs together (32 took 0.48x as long as
#: one at a time on holes_cat_shape_6's searches; 8, 16 and 64: 0.49-0.58x).
_BLOCK = 32


def anchor_core(part_distances: np.ndarray, whole_distances: np.ndarray, reach: float, change: float) -> np.ndarray:
    """The largest set of anchors whose mutual distances a map keeps, found greedily.

    Starting from every anchor, the one that keeps its distance (within ``change``) to
    the smallest share of the others within ``reach`` is dropped until every anchor
    keeps at least :data:`CORE_AGREEMENT` of them.

    Parameters
    ----------
    part_distances : (A, A) float
        Geodesic distances between the anchors on the part (``inf`` beyond ``reach``).
    whole_distances : (A, A) float
        Geodesic distances between their images on the whole.
    reach, change : float
        Pairs farther apart than ``reach`` on the part are not compared; a pair's distance
        is kept when the map changes it by at most ``change`` (graph length units).

    Returns
    -------
    (A,) bool
        The core; it keeps at least :data:`MIN_ANCHORS` anchors (all of them when there
        are fewer).
    """
    near = part_distances < reach
    np.fill_diagonal(near, False)
    kept = np.zeros_like(near)
    kept[near] = np.abs(part_distances[near] - whole_distances[near]) <= change
    core = np.ones(len(near), dtype=bool)
    while core.sum() > MIN_ANCHORS:
        members = np.flatnonzero(core)
        compared = near[np.ix_(members, members)].sum(axis=1)
        # an anchor with no other within reach keeps a share of 0 and goes first
        share = kept[np.ix_(members, members)].sum(axis=1) / np.maximum(compared, 1)
        worst = int(np.argmin(share))
        if share[worst] >= CORE_AGREEMENT:
            break
        core[members[worst]] = False
    return core


@nb.njit(cache=True, nogil=True)
def _best_images(lo, hi, part_distances, whole_distances, reach, start, out):  # pragma: no cover
    """Part vertices ``lo:hi`` of :func:`best_images`, into ``out``."""
    n_anchors = part_distances.shape[0]
    n_whole = whole_distances.shape[1]
    total = np.empty(_BLOCK)
    for x in range(lo, hi):
        column = part_distances[:, x]
        order = np.argsort(column)
        m = 0
        while m < n_anchors and column[order[m]] < reach:
            m += 1
        if m < MIN_ANCHORS:
            continue
        wanted = column[order[:m]]
        arg = start[x]
        best = np.inf
        if arg >= 0:
            best = 0.0
            for j in range(m):
                best += abs(whole_distances[order[j], arg] - wanted[j])
        for lo_w in range(0, n_whole, _BLOCK):
            size = min(_BLOCK, n_whole - lo_w)
            for k in range(size):
                total[k] = 0.0
            low = 0.0
            j = 0
            while j < m and low < best:
                row = whole_distances[order[j]]
                low = np.inf
                for k in range(size):
                    total[k] += abs(row[lo_w + k] - wanted[j])
                    low = min(low, total[k])
                j += 1
            if low >= best:
                continue
            for k in range(size):
                if total[k] < best:
                    best = total[k]
                    arg = lo_w + k
        out[x] = arg


def best_images(part_distances: np.ndarray, whole_distances: np.ndarray, reach: float, start: np.ndarray) -> np.ndarray:
    """Per part vertex, the whole's vertex whose distances to the anchors' images best
    repeat (least sum of absolute differences) the vertex's distances to the anchors
    within ``reach``.

    The start's own sum bounds the search from the outset. The whole's vertices are
    costed ``_BLOCK`` at a time, one anchor after another (nearest first), each term
    reading one contiguous stretch of a row, until every sum in the block reaches the
    best so far; a block that ends below it is then scanned in vertex order. The sums
    are those of the dense search, term for term. (Per vertex, stopping each sum once it
    reaches the best, took 2.0-2.1x as long on holes_cat_shape_6's and
    cuts_dog_shape_5's searches, the same images: about half the whole survives the
    first term, and the loop does not vectorise. Visiting the whole's vertices in the
    order of the first term's difference took 0.66-1.26x as long as that on
    holes_dog_shape_9's four searches.) The part's vertices are searched on
    :func:`intrinsym._threads.map_ranges`' threads, not in a ``prange`` loop, whose
    compilation cost 4.4 s on the first run after install.

    Parameters
    ----------
    part_distances : (A, N_part) float
        Geodesic distances from the anchors on the part (``inf`` beyond ``reach``).
    whole_distances : (A, N_whole) float
        From the anchors' images on the whole.
    reach : float
        Anchors at least this far from a vertex are not used.
    start : (N_part,) int
        Each vertex's current image (-1: none); it stays where fewer than
        :data:`MIN_ANCHORS` anchors are within reach.

    Returns
    -------
    (N_part,) int
        Ties go to ``start``, then to the lowest vertex: the dense argmin's answer.
    """
    out = start.copy()
    map_ranges(_best_images, part_distances.shape[1], part_distances, whole_distances, reach, start, out)
    return out


def trilaterated_maps(vertex_map: np.ndarray, part: Surface, whole: Surface) -> list[np.ndarray]:
    """A part's map into its whole trilaterated from its anchor core, round after round.

    Each round finds the core of the previous round's map (:func:`anchor_core`) and sends
    every vertex of the part to the vertex of the whole whose distances to the core's
    images best repeat its own to the core's anchors within :data:`TRILATERATION_REACH`.
    A right core grows from round to round (on holes_cat_shape_9: 16, 33, 41 of 64
    anchors); the caller keeps the round that changes the fewest of the part's distances.

    Parameters
    ----------
    vertex_map : (N_part_input,) int
        Input vertex of the whole of every input vertex of the part, -1 for none.
    part, whole : Surface
        Meshes prepared in one unit (:func:`intrinsym.surface.prepare_pair`). The
        distances are measured on their mesh edges and the chords across their edges
        (:func:`intrinsym.geodesics.geodesics.surface_graph` with ``rings=1``): the
        working graphs' longer chords cut across a coarse mesh's thin limbs and tails,
        and do so differently on the two meshes. A pair of anchors keeps its distance
        when the map changes it by at most ``PART_MAP_CHANGE``.

    Returns
    -------
    list of (N_part_input,) int64
        :data:`TRILATERATION_ROUNDS` maps (none when fewer than
        :data:`TRILATERATION_ANCHORS` of the part's vertices have an image). Each gives
        every vertex located from at least :data:`MIN_ANCHORS` core anchors an image, and
        the previous round's elsewhere (-1 where it has none).
    """
    if part.shape.faces is None or whole.shape.faces is None:
        raise ValueError("trilaterating a part's map needs two meshes, not point clouds")
    working = working_map(vertex_map, part, whole)
    mapped = np.flatnonzero(working >= 0)
    if len(mapped) < TRILATERATION_ANCHORS:
        return []
    part_graph, whole_graph = part.chord_graph, whole.chord_graph
    anchors = mapped[farthest_point_sampling(part.shape.vertices[mapped], TRILATERATION_ANCHORS)]
    on_part = distances_from(part_graph, anchors, limit=TRILATERATION_REACH)
    on_whole = np.empty((len(anchors), len(whole.shape.vertices)))
    images = np.full(len(anchors), -1)
    maps = []
    for _ in range(TRILATERATION_ROUNDS):
        # a vertex's image lies within reach of each anchor's image it is located from
        # (up to the change allowed); farther vertices of the whole are never candidates.
        # Only the anchors whose image the last round moved are searched from again.
        moved = working[anchors] != images
        images = working[anchors]
        on_whole[moved] = distances_from(whole_graph, images[moved], limit=2.0 * TRILATERATION_REACH)
        core = anchor_core(on_part[:, anchors], on_whole[:, images], TRILATERATION_REACH, PART_MAP_CHANGE)
        working = best_images(on_part[core], on_whole[core], TRILATERATION_REACH, working)
        maps.append(input_map(working, part, whole))
    return maps


def polished_trilateration(
    seed: np.ndarray, given: tuple[Surface, Surface], measured: tuple[Surface, Surface]
) -> np.ndarray | None:
    """A hypothesis's map made final: the round of its trilateration that changes the
    fewest of the part's distances, refined by ZoomOut.

    Parameters
    ----------
    seed : (N_part_input,) int
        Input vertex of the whole of every input vertex of the part, -1 for none.
    given : (Surface, Surface)
        The part and the whole prepared without refinement, on which the trilateration
        and the refinement are solved.
    measured : (Surface, Surface)
        The part and the whole on whose working meshes the rounds' distortion is measured.

    Returns
    -------
    (N_part_input,) int64 or None
        None when the seed maps too few vertices to trilaterate.
    """
    rounds = trilaterated_maps(seed, *given)
    if not rounds:
        return None
    return refine_part_map(rounds[least_distorted(rounds, *measured)[0]], *given)
