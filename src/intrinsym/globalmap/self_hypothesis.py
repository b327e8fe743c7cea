"""A shape's partial symmetry from its own consistent descriptor matches, and "no partner"
where the map cannot keep the shape's distances.

Where ``detect`` finds no global symmetry (a side cut away, holes punched in: BP's
argmax keeps too few of the source edges for the trivial match to be removed), its map
is the extraction's dominant partial symmetry, often small or wrong. The hypotheses of
:mod:`intrinsym.globalmap.part_hypothesis` apply to a shape matched to itself once the
trivial matches are left out: each anchor is offered the samples nearest it in spin-image
space that lie farther than twice the trivial radius from it, and the replicator dynamics
select the largest geodesically consistent cluster, whose anchors locate every vertex.
That map is trilaterated and polished as a part's map is.

Such a map gives every vertex an image, the cut-away side's mirror too. Its residual
(:func:`map_residual`), how much it typically changes a vertex's distances to the
farthest-point anchors around it, is small where the symmetry holds and large where the vertex has no
partner: the map sends it into the missing part's place, among vertices at other
distances. The vertices whose residual exceeds :data:`SELF_RESIDUAL` get -1. A reflection
is its own inverse: the map kept gets -1 too where it does not return a vertex to
itself, as a global map does (:func:`~intrinsym.globalmap.globalmap.supported_map`).

A shape can also have near-isometries that are no symmetry. The trivial match keeps every
distance: a map under which most vertices stay within the trivial radius of themselves
(:func:`fixed_share` above :data:`TRIVIAL_SHARE`) is the identity, not a symmetry, even
when the extraction took it for a global one (a side cut away, and the map sends the
other side onto itself). On a nearly round body a slide keeps the distances almost
everywhere. A symmetry's images look like their
vertices, a slide's do not: a map counts only when, over its mapped vertices, the median
rank of the image's descriptor among all the samples' by likeness to the vertex's own
(:func:`likeness_ranks`) is at most :data:`SELF_LIKENESS` and it is not the trivial
match. :func:`self_symmetry_map` keeps, of the extraction's map and the hypotheses so
cut, the one that counts and maps the most of the shape; -1 everywhere when none counts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.distance import cdist

from ..geodesics.geodesics import distances_from
from ..mesh.sampling import farthest_point_sampling
from ..params import Params
from ..surface import Surface, working_map
from .globalmap import supported_map
from .part_hypothesis import HYPOTHESIS_SAMPLES, hypothesis_maps
from .part_map import PART_MAP_CHANGE, part_descriptors
from .part_trilateration import TRILATERATION_ANCHORS, TRILATERATION_REACH, polished_trilateration

__all__ = [
    "SELF_LIKENESS",
    "SELF_RESIDUAL",
    "SelfMapStats",
    "TRIVIAL_SHARE",
    "fixed_share",
    "likeness_ranks",
    "map_residual",
    "residual_cut",
    "self_symmetry_map",
]

#: A vertex whose median distance change to the anchors within reach exceeds this has
#: no partner under the map (sqrt(area) units): the change up to which a part's map keeps
#: a distance. On 20 SHREC'16 shapes the balanced score of the kept maps is 0.541-0.555
#: for limits from 0.03 to 0.05 (0.469 without the hypotheses), 0.504 at 0.06.
SELF_RESIDUAL = PART_MAP_CHANGE
#: A map counts as a symmetry when the median likeness rank of its images
#: (:func:`likeness_ranks`) is at most this: 0.004-0.057 for the hypotheses right
#: within 0.10 on at least half of 20 SHREC'16 shapes, 0.002-0.011 for the generated
#: partial shape's limb swap, 0.29-0.32 for the slide of its body the hypotheses find
#: there; 0.5 for a random map.
SELF_LIKENESS = 0.15
#: A self-map is the trivial match when more than this share of the vertices it maps stay
#: within the trivial radius of themselves (:func:`fixed_share`): the majority. A
#: reflection keeps only a band along its fixed curve there.
TRIVIAL_SHARE = 0.5


@dataclass(frozen=True)
class SelfMapStats:
    """Which map ``detect`` kept for a shape without a global symmetry (``run.json``:
    ``self_map``).

    Attributes
    ----------
    source : str
        "extraction", "hypothesis 1", "hypothesis 2", ... or "none" (no candidate counts).
    mapped : dict of str to float
        Each candidate's share of the input vertices it maps after the residual cut.
    likeness : dict of str to float or None
        Each candidate's median likeness rank there (None: it maps no vertex); above
        :data:`SELF_LIKENESS` it does not count.
    fixed : dict of str to float
        Each candidate's :func:`fixed_share` there; above :data:`TRIVIAL_SHARE` it is the
        trivial match and does not count.
    trivial_global : float or None
        The :func:`fixed_share` of the global map the run had found, when that map was
        the trivial match (then the extraction's candidate is its widest partial
        symmetry); None when it found none.
    """

    source: str
    mapped: dict[str, float] = field(default_factory=dict)
    likeness: dict[str, float | None] = field(default_factory=dict)
    fixed: dict[str, float] = field(default_factory=dict)
    trivial_global: float | None = None


def map_residual(vertex_map: np.ndarray, surface: Surface) -> np.ndarray:
    """How far a self-map changes each vertex's distances to the anchors around it.

    The median over the farthest-point anchors (:data:`~intrinsym.globalmap.part_trilateration.TRILATERATION_ANCHORS`
    of the mapped vertices) within ``TRILATERATION_REACH`` of a vertex v of
    ``|d(T v, T a) - d(v, a)|``, each term clipped at ``TRILATERATION_REACH``; distances on
    the mesh edges and the chords across them (``surface.chord_graph``).

    Parameters
    ----------
    vertex_map : (N_input,) int
        Input vertex of every input vertex, -1 for none.
    surface : Surface
        A mesh; the map's domain and codomain.

    Returns
    -------
    (N_input,) float64
        NaN where the vertex has no image or no anchor lies within reach.
    """
    if surface.shape.faces is None:
        raise ValueError("a map's residual needs a mesh, not a point cloud")
    working = working_map(vertex_map, surface, surface)
    mapped = np.flatnonzero(working >= 0)
    out = np.full(len(surface.vertex_map), np.nan)
    if not len(mapped):
        return out
    anchors = mapped[farthest_point_sampling(surface.shape.vertices[mapped], min(TRILATERATION_ANCHORS, len(mapped)))]
    graph = surface.chord_graph
    on_shape = distances_from(graph, anchors, limit=TRILATERATION_REACH)
    on_image = distances_from(graph, working[anchors], limit=2.0 * TRILATERATION_REACH)
    near = np.isfinite(on_shape) & (working >= 0)[None, :]
    with np.errstate(invalid="ignore"):  # inf - inf off ``near``
        change = np.minimum(np.abs(on_image[:, np.maximum(working, 0)] - on_shape), TRILATERATION_REACH)
    change[~near] = np.nan
    residual = np.full(len(working), np.nan)
    measured = near.any(axis=0)
    residual[measured] = np.nanmedian(change[:, measured], axis=0)
    return residual[surface.vertex_map]


def residual_cut(vertex_map: np.ndarray, residual: np.ndarray, limit: float = SELF_RESIDUAL) -> np.ndarray:
    """``vertex_map`` with -1 where ``residual`` exceeds ``limit`` or is NaN, (N,) int64."""
    keep = np.nan_to_num(residual, nan=np.inf) <= limit
    return np.where(keep, np.asarray(vertex_map, dtype=np.int64), -1)


def likeness_ranks(vertex_map: np.ndarray, surface: Surface, descriptors: np.ndarray) -> np.ndarray:
    """How much each vertex's image looks like it, as a rank among the shape's samples.

    For a vertex v with image T v: the share of the ``HYPOTHESIS_SAMPLES`` farthest-point
    samples of the working mesh whose descriptors lie nearer to v's than T v's does. A
    vertex's mirror partner has nearly its descriptor (ranks near 0); a random image
    ranks about 0.5.

    Parameters
    ----------
    vertex_map : (N_input,) int
        Input vertex of every input vertex, -1 for none.
    surface : Surface
    descriptors : (N_working, D) float
        Per working vertex (:func:`~intrinsym.globalmap.part_map.part_descriptors`).

    Returns
    -------
    (N_input,) float64 in [0, 1]
        NaN where the vertex has no image.
    """
    working = working_map(vertex_map, surface, surface)
    mapped = np.flatnonzero(working >= 0)
    ranks = np.full(len(working), np.nan)
    if len(mapped):
        vertices = surface.shape.vertices
        samples = farthest_point_sampling(vertices, min(HYPOTHESIS_SAMPLES, len(vertices)))
        own = np.linalg.norm(descriptors[mapped] - descriptors[working[mapped]], axis=1)
        ranks[mapped] = (cdist(descriptors[mapped], descriptors[samples]) < own[:, None]).mean(axis=1)
    return ranks[surface.vertex_map]


def fixed_share(vertex_map: np.ndarray, surface: Surface, radius: float) -> float:
    """The share of a self-map's mapped vertices whose image lies within ``radius`` of them.

    Estimated on ``HYPOTHESIS_SAMPLES`` farthest-point samples of the mapped working
    vertices, by the geodesic on the mesh edges and the chords across them
    (``surface.chord_graph``).

    Parameters
    ----------
    vertex_map : (N_input,) int
        Input vertex of every input vertex, -1 for none.
    surface : Surface
        A mesh; the map's domain and codomain.
    radius : float
        sqrt(area) units (``trivial_radius``).

    Returns
    -------
    float in [0, 1]; 0 for a map with no image.
    """
    working = working_map(vertex_map, surface, surface)
    mapped = np.flatnonzero(working >= 0)
    if not len(mapped):
        return 0.0
    samples = mapped[farthest_point_sampling(surface.shape.vertices[mapped], min(HYPOTHESIS_SAMPLES, len(mapped)))]
    near = distances_from(surface.chord_graph, samples, limit=radius)
    return float(np.mean(near[np.arange(len(samples)), working[samples]] <= radius))


def self_symmetry_map(
    extraction_map: np.ndarray, given: Surface, p: Params, count: int
) -> tuple[np.ndarray, SelfMapStats]:
    """The partial symmetry map ``detect`` keeps for a shape without a global symmetry.

    Parameters
    ----------
    extraction_map : (N_input,) int
        The extraction's map of the dominant symmetry, -1 off its parts.
    given : Surface
        The mesh prepared without refinement (the mesh as given), on which the
        descriptors, hypotheses, trilaterations, refinements and residuals are solved.
    p : Params
        The spin images' parameters and ``trivial_radius``.
    count : int
        Hypotheses to draw.

    Returns
    -------
    vertex_map : (N_input,) int64
        Of the extraction's map and the hypotheses, each with -1 where its residual
        exceeds :data:`SELF_RESIDUAL`, the one that maps the most input vertices (the
        extraction's on a tie) among those whose median likeness rank is at most
        :data:`SELF_LIKENESS` and whose :func:`fixed_share` is at most
        :data:`TRIVIAL_SHARE`, then with -1 where it does not return a vertex to itself
        (:func:`~intrinsym.globalmap.globalmap.supported_map`, as the global map); -1
        everywhere when there is none.
    stats : SelfMapStats
    """
    descriptors = part_descriptors(given, given, p)
    # the extraction's map is not trilaterated: grown from a right core over a shape whose
    # other parts are nearly isometric to it (a round body), it maps them too
    candidates = {"extraction": np.asarray(extraction_map, dtype=np.int64)}
    trivial = min(2.0 * p.trivial_radius, 0.5 * TRILATERATION_REACH)
    for k, seed in enumerate(hypothesis_maps(given, given, descriptors, count, trivial), start=1):
        polished = polished_trilateration(seed, (given, given), (given, given))
        if polished is not None:
            candidates[f"hypothesis {k}"] = polished
    cut = {name: residual_cut(m, map_residual(m, given)) for name, m in candidates.items()}
    mapped = {name: float(np.mean(m >= 0)) for name, m in cut.items()}
    likeness: dict[str, float | None] = {}
    for name, m in cut.items():
        ranks = likeness_ranks(m, given, descriptors[0])[m >= 0]
        likeness[name] = float(np.median(ranks)) if len(ranks) else None
    fixed = {name: fixed_share(m, given, p.trivial_radius) for name, m in cut.items()}
    counts = {
        name: mapped[name] if (rank is not None and rank <= SELF_LIKENESS and fixed[name] <= TRIVIAL_SHARE) else 0.0
        for name, rank in likeness.items()
    }
    best = max(counts, key=lambda name: (counts[name], name == "extraction"))
    source = best if counts[best] > 0.0 else "none"
    stats = SelfMapStats(source, mapped, likeness, fixed)
    if source == "none":
        return np.full(len(extraction_map), -1, dtype=np.int64), stats
    return supported_map(cut[best], given.input_vertices, given.scale), stats
