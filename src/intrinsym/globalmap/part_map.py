"""A part's vertex map into its whole: the extraction's, or a partial functional map's.

``match`` of a part (a shape with a side cut away, holes) to its whole extracts a map
from the marginals, and on such pairs that map is often wrong: the part's descriptors
are not the whole's near the cuts, and BP settles on a consistent but shifted map. A
partial functional map (:mod:`intrinsym.globalmap.partial_fmap`) is right on other pairs.
The marginals do not tell which (a part's are nearly flat, docs/limitations.md); the
maps' own geodesic distortion does: a right map keeps the part's short distances, a
wrong one tears them. The map that changes fewer of them is kept, and the share it
keeps is the score the part's confidence is calibrated on
(:data:`intrinsym.globalmap.confidence.PART_CALIBRATION`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from ..mesh.sampling import area_uniform_points
from ..params import Params
from ..spectral import laplacian
from ..surface import Surface, working_map
from ..unary.unary import spin_images_at
from .distortion import graph_map_distortion
from .partial_fmap import EIGENPAIRS, partial_functional_map, restricted_zoomout

__all__ = [
    "PART_MAP_CHANGE",
    "PART_MAP_RADIUS",
    "PartMapStats",
    "blended_if_less_distorted",
    "choose_part_map",
    "hypothesis_if_less_distorted",
    "least_distorted",
    "part_descriptors",
    "part_fmap_map",
    "refine_part_map",
    "refined_if_less_distorted",
    "spin_functions",
    "trilaterated_if_less_distorted",
    "with_polish",
]

#: Pairs of the part within this geodesic distance (sqrt(area) of the whole) are compared...
PART_MAP_RADIUS = 0.25
#: ...and count as changed when the map moves them apart or together by more than this.
#: On the 125 SHREC'16 pairs the share of changed pairs ranks the right maps (within
#: 0.10 on >= 0.80 of the vertices) above the wrong ones (< 0.50) with an AUC of 0.999.
PART_MAP_CHANGE = 0.05
#: Only the share of pairs changed by more than PART_MAP_CHANGE is read: a change
#: clipped at twice that decides it as exactly, and the whole's distances are then
#: needed only to PART_MAP_RADIUS + 2 PART_MAP_CHANGE, not to the radius + 0.25 that
#: the full distortion curve takes.
_CHANGE_CLIP = np.array([PART_MAP_CHANGE, 2.0 * PART_MAP_CHANGE])
#: A refined part's map (:func:`refine_part_map`) keeps its images within this
#: geodesic distance (sqrt(area) of the whole) of the map's own; set once, not tuned.
REFINE_REACH = 0.15
#: The partial functional map's descriptors are spin images at this many area-uniform
#: points of each shape (every vertex taking its nearest point's)...
SPIN_POINTS = 1500
#: ...projected onto this many principal components of the whole's (both set once, not
#: tuned: the 125 SHREC'16 pairs were measured at these values alone).
SPIN_COMPONENTS = 30


@dataclass(frozen=True)
class PartMapStats:
    """How a part's map into its whole was chosen (``match``, the source the part).

    Attributes
    ----------
    source : {"extraction", "partial_fmap"}
        The vertex map kept: the extraction's, or the partial functional map's
        (:func:`intrinsym.globalmap.partial_fmap.partial_functional_map`).
    distortion : dict of str to float
        Per candidate, the share of the part's vertex pairs within ``PART_MAP_RADIUS``
        whose geodesic distance the map changes by more than ``PART_MAP_CHANGE`` (None
        for a map that gives no image); the lower one is kept. Without a partial
        functional map (``part_fmap`` off, a point cloud) the extraction's alone;
        "refined": the kept map's refinement, when measured.
    refined : bool
        The kept map was replaced by its refinement (:func:`refine_part_map`,
        :func:`refined_if_less_distorted`).
    trilaterated : bool
        The kept (or refined) map was then replaced by one of its trilaterations
        (:func:`intrinsym.globalmap.part_trilateration.trilaterated_maps`,
        :func:`trilaterated_if_less_distorted`; ``distortion["trilaterated"]``: the least
        distorted round's share).
    polished : bool
        The trilaterated map was then refined by ZoomOut once more (:func:`refine_part_map`,
        :func:`with_polish`; ``distortion["polished"]``: its share), as it always is: the
        trilateration's searches are vertex-exact but coarse.
    hypothesis : bool
        The map kept so far was then replaced by a map located from a consistent cluster
        of descriptor matches, trilaterated and polished
        (:func:`intrinsym.globalmap.part_hypothesis.hypothesis_maps`,
        :func:`hypothesis_if_less_distorted`; ``distortion["hypothesis"]``: the least
        distorted hypothesis's share).
    blended : bool
        The map kept so far was then replaced by the blend of the candidates (the map
        kept before the hypotheses and the hypotheses' maps) vertex by vertex, trilaterated
        and polished (:func:`intrinsym.globalmap.part_blend.blended_map`,
        :func:`blended_if_less_distorted`; ``distortion["blended"]``: its share).
    """

    source: str
    distortion: dict[str, float | None] = field(default_factory=dict)
    refined: bool = False
    trilaterated: bool = False
    polished: bool = False
    hypothesis: bool = False
    blended: bool = False

    @property
    def final(self) -> str:
        """The key of ``distortion`` that measures the map kept in the end."""
        if self.blended:
            return "blended"
        if self.hypothesis:
            return "hypothesis"
        if self.polished:
            return "polished"
        return "trilaterated" if self.trilaterated else "refined" if self.refined else self.source

    @property
    def kept(self) -> float:
        """The share of the part's vertex pairs within ``PART_MAP_RADIUS`` whose distance
        the kept map keeps within ``PART_MAP_CHANGE`` (0 for a map that gives no image)."""
        share = self.distortion.get(self.final)
        return 0.0 if share is None else 1.0 - share


def _spectrum(surface: Surface) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eigenvalues, eigenfunctions and lumped vertex areas of a surface's working mesh."""
    shape = surface.shape
    evals, evecs = _eigenpairs(surface)
    _, mass = laplacian.laplace_beltrami(shape.vertices, shape.faces)
    return evals, evecs, np.asarray(mass.diagonal()).ravel()


def _eigenpairs(surface: Surface) -> tuple[np.ndarray, np.ndarray]:
    """The working mesh's eigenvalues and eigenfunctions (the surface keeps them)."""
    return surface.eigenpairs(min(EIGENPAIRS, len(surface.shape.vertices) - 1), 0)


def spin_functions(surface: Surface, p: Params) -> np.ndarray:
    """The spin image at every working vertex of a mesh, as a function on the mesh.

    The unary's spin images (:func:`intrinsym.unary.unary.spin_images_at`, radius
    ``p.spin_radius``) at the vertices nearest ``SPIN_POINTS`` area-uniform points (seed ``p.seed + 3``);
    every vertex takes its nearest such vertex's image, which costs a fraction of an
    image per vertex and varies no faster than the images themselves.

    Returns
    -------
    (N_working, spin_bins^2) float64, each row summing to 1 (or all 0).
    """
    shape = surface.shape
    if shape.faces is None:
        raise ValueError("spin functions need a mesh, not a point cloud")
    points = area_uniform_points(shape.vertices, shape.faces, SPIN_POINTS, seed=p.seed + 3)[0]
    at = np.unique(cKDTree(shape.vertices).query(points)[1])
    images = spin_images_at(surface, at, p.spin_radius, p)
    nearest = cKDTree(shape.vertices[at]).query(shape.vertices)[1]
    return images.reshape(len(at), -1).astype(np.float64)[nearest]


def part_descriptors(part: Surface, whole: Surface, p: Params) -> tuple[np.ndarray, np.ndarray]:
    """The partial functional map's descriptor functions on a part and on its whole.

    Spin images (:func:`spin_functions`) are local and invariant to reflections: a cut
    or a hole changes them only within ``p.spin_radius``, where the whole's spectral
    signatures change everywhere: on the 125 SHREC'16 pairs, ``match`` keeps 0.668 of
    the vertices within 0.10 of the nearer answer with them, 0.546 with wave-kernel
    densities in their place (docs/results.md). Both are projected onto the
    ``SPIN_COMPONENTS`` leading principal components of the whole's images and shifted
    by the same offset to be non-negative on the whole.

    Returns
    -------
    (N_part_working, SPIN_COMPONENTS) and (N_whole_working, SPIN_COMPONENTS) float64
    """
    d_whole = spin_functions(whole, p)
    d_part = d_whole if part is whole else spin_functions(part, p)  # a shape matched to itself
    mean = d_whole.mean(axis=0)
    axes = np.linalg.svd(d_whole - mean, full_matrices=False)[2][:SPIN_COMPONENTS].T
    on_whole = (d_whole - mean) @ axes
    low = on_whole.min(axis=0)
    return (d_part - mean) @ axes - low, on_whole - low


def part_fmap_map(part: Surface, whole: Surface, descriptors: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The partial functional map of a part into its whole, on their input vertices.

    Parameters
    ----------
    part, whole : Surface
        Meshes (not point clouds), prepared in one unit (:func:`intrinsym.surface.prepare_pair`).
        The map is solved on their working meshes. ``match`` passes them prepared without
        refinement (``min_vertices`` 0), the meshes as given: the refinement serves BP's
        dense targets, not the spectra or the spin images, and costs time here (a
        6,700-vertex SHREC'16 part refined to 26,600 vertices: 8.3-9.9 s, as given 5.5-5.7 s).
    descriptors : (N_part_working, D) and (N_whole_working, D) float
        :func:`part_descriptors` of the two.

    Returns
    -------
    (N_part_input,) int64
        Input vertex of the whole of every input vertex of the part.
    """
    if part.shape.faces is None or whole.shape.faces is None:
        raise ValueError("a partial functional map needs two meshes, not point clouds")
    evals_w, evecs_w, mass_w = _spectrum(whole)
    pair = (evals_w, evecs_w, mass_w, whole.shape.vertices, whole.shape.faces)
    images = partial_functional_map(_spectrum(part), pair, descriptors).images
    return whole.working_inputs[images[part.vertex_map]]


def refine_part_map(vertex_map: np.ndarray, part: Surface, whole: Surface) -> np.ndarray:
    """A part's map into its whole refined by ZoomOut restricted to where the map lies.

    The extraction's map comes from BP's sample cells, so its images are as coarse as
    the target samples, and the partial functional map's ZoomOut reaches anywhere in its
    indicator; where the map is right, ZoomOut seeded with it
    (:func:`~intrinsym.globalmap.partial_fmap.restricted_zoomout`, images within
    ``REFINE_REACH`` of the map's own) gives the precision, as it does for ``detect``'s
    global map. Vertices of the part without an image take that of the nearest one with
    an image (in space: a piece of the part with none has no path to one) as the seed.

    Parameters
    ----------
    vertex_map : (N_part_input,) int
        Input vertex of the whole of every input vertex of the part, -1 for none.
    part, whole : Surface
        Meshes prepared in one unit (:func:`intrinsym.surface.prepare_pair`).

    Returns
    -------
    (N_part_input,) int64
        The refined map, an image for every vertex; ``vertex_map`` itself when it gives
        none.
    """
    if part.shape.faces is None or whole.shape.faces is None:
        raise ValueError("refining a part's map needs two meshes, not point clouds")
    image = np.asarray(vertex_map, dtype=np.int64)[part.working_inputs]
    mapped = image >= 0
    if not mapped.any():
        return np.asarray(vertex_map, dtype=np.int64)
    with_image = np.flatnonzero(mapped)
    nearest = with_image[cKDTree(part.shape.vertices[with_image]).query(part.shape.vertices)[1]]
    seed = whole.vertex_map[image[nearest]]
    keep = np.isfinite(dijkstra(whole.graph, indices=np.unique(seed), min_only=True, limit=REFINE_REACH))
    # as in partial_functional_map: OpenBLAS's threads slow these (N, 100) products down
    with threadpool_limits(1, user_api="blas"):
        refined = restricted_zoomout(seed, _eigenpairs(part), _eigenpairs(whole), keep)
    return whole.working_inputs[refined[part.vertex_map]]


def refined_if_less_distorted(
    refined_map: np.ndarray, part: Surface, whole: Surface, stats: PartMapStats
) -> tuple[bool, PartMapStats]:
    """Whether the refinement (:func:`refine_part_map`) of the map :func:`choose_part_map`
    kept changes fewer of the part's geodesic distances than that map.

    The test :func:`choose_part_map` makes, between the map and its refinement only:
    ZoomOut gives a right map the precision of the whole's vertices, but it can also carry
    a half-right map further off, and then tears more of the part's distances. The
    choice between the extraction's map and the partial functional map weighs them
    unrefined: refined, a wrong map settles on a small region and changes fewer
    distances than a right one.

    Parameters
    ----------
    refined_map : (N_part_input,) int
        The refinement of the kept map.
    part, whole : Surface
        As in :func:`choose_part_map`.
    stats : PartMapStats
        :func:`choose_part_map`'s.

    Returns
    -------
    refined : bool
        The refinement is kept.
    stats : PartMapStats
        ``stats`` with the refinement's share in ``distortion`` and ``refined`` set.
    """
    distortion, better = _weighed("refined", _changed(refined_map, part, whole), stats)
    return better, dataclasses.replace(stats, distortion=distortion, refined=better)


def trilaterated_if_less_distorted(
    maps: list[np.ndarray], part: Surface, whole: Surface, stats: PartMapStats
) -> tuple[np.ndarray | None, PartMapStats]:
    """The round of a part's map's trilateration that changes the fewest of the part's
    geodesic distances, if it changes fewer than the map kept so far.

    The test of :func:`choose_part_map` and :func:`refined_if_less_distorted`, over the
    rounds of :func:`intrinsym.globalmap.part_trilateration.trilaterated_maps`: a round
    can also carry a core of right images onto a wrong region, and then tears more of
    the part's distances than the map it started from.

    Parameters
    ----------
    maps : list of (N_part_input,) int
        The trilaterated maps (none: nothing to weigh).
    part, whole : Surface
        As in :func:`choose_part_map`.
    stats : PartMapStats
        :func:`refined_if_less_distorted`'s.

    Returns
    -------
    vertex_map : (N_part_input,) int64 or None
        The least distorted round's map; None when the map kept so far stays.
    stats : PartMapStats
        ``stats`` with that round's share in ``distortion`` and ``trilaterated`` set.
    """
    return _if_less_distorted("trilaterated", maps, part, whole, stats)


def least_distorted(maps: list[np.ndarray], part: Surface, whole: Surface) -> tuple[int, float]:
    """The map of a part into its whole that changes the fewest of the part's distances.

    Parameters
    ----------
    maps : list of (N_part_input,) int, at least one
        Input vertex of the whole of every input vertex of the part, -1 for none.
    part, whole : Surface
        As in :func:`choose_part_map`.

    Returns
    -------
    index : int
        Of the least distorted map (the first where none gives an image).
    share : float
        Its share of the part's vertex pairs within ``PART_MAP_RADIUS`` whose distance it
        changes by more than ``PART_MAP_CHANGE``; ``inf`` where no map gives an image.
    """
    shares = np.array([_changed(m, part, whole) for m in maps])
    shares[~np.isfinite(shares)] = np.inf
    best = int(np.argmin(shares))
    return best, float(shares[best])


def hypothesis_if_less_distorted(
    maps: list[np.ndarray], part: Surface, whole: Surface, stats: PartMapStats
) -> tuple[np.ndarray | None, PartMapStats]:
    """The least distorted of a part's hypothesis maps, if it changes fewer of the part's
    geodesic distances than the map kept so far.

    The test of :func:`choose_part_map`, over the maps located from consistent clusters
    of descriptor matches (:func:`intrinsym.globalmap.part_hypothesis.hypothesis_maps`),
    each trilaterated and polished as the kept map is: on the SHREC'16 pairs whose kept
    map is wrong from the start, a hypothesis's map keeps the part's distances where it
    is right and tears them where its cluster was a coincidence (docs/results.md).
    ``maps`` are the hypotheses' polished maps, ``stats`` those of the map kept so far;
    returned as by :func:`trilaterated_if_less_distorted`, under ``"hypothesis"``.
    """
    return _if_less_distorted("hypothesis", maps, part, whole, stats)


def blended_if_less_distorted(
    blend: np.ndarray | None, part: Surface, whole: Surface, stats: PartMapStats
) -> tuple[np.ndarray | None, PartMapStats]:
    """The blend of a part's candidate maps, if it changes fewer of the part's geodesic
    distances than the map kept so far.

    The test of :func:`choose_part_map`, for the candidates' blend
    (:func:`intrinsym.globalmap.part_blend.blended_map`), trilaterated and polished as a
    hypothesis is: a blend of right pieces keeps the part's distances better than each
    piece's map, one that joins a wrong piece tears them at its seams. ``blend`` None
    (too few vertices mapped to trilaterate) leaves ``stats`` as it is; returned as by
    :func:`trilaterated_if_less_distorted`, under ``"blended"``.
    """
    return _if_less_distorted("blended", [] if blend is None else [blend], part, whole, stats)


def _if_less_distorted(
    name: str, maps: list[np.ndarray], part: Surface, whole: Surface, stats: PartMapStats
) -> tuple[np.ndarray | None, PartMapStats]:
    """The least distorted of ``maps`` if it changes fewer of the part's distances than
    the map kept so far, and ``stats`` with its share under ``name`` and the flag ``name``
    set accordingly."""
    if not maps:
        return None, stats
    best, share = least_distorted(maps, part, whole)
    distortion, better = _weighed(name, share, stats)
    kept = np.asarray(maps[best], dtype=np.int64) if better else None
    changes: dict[str, Any] = {"distortion": distortion, name: better}
    return kept, dataclasses.replace(stats, **changes)


def with_polish(polished_map: np.ndarray, part: Surface, whole: Surface, stats: PartMapStats) -> PartMapStats:
    """``stats`` of a trilaterated map (:func:`trilaterated_if_less_distorted`) that was
    refined once more (:func:`refine_part_map`), with the share of the part's distances
    the polished map changes.

    The polish is kept without a test: ZoomOut restricted to ``REFINE_REACH`` of a map
    that keeps the part's distances moves its images by a few vertices, and the share
    of distances changed by more than ``PART_MAP_CHANGE`` does not see that precision
    (on the 123 SHREC'16 pairs whose trilaterated map is kept, within 0.05 goes 0.638 ->
    0.703 with the polish kept everywhere, -> 0.688 kept only where it changes fewer
    distances; docs/results.md). The share is measured for
    the confidence, which is calibrated on the final map's (:attr:`PartMapStats.kept`).

    Parameters
    ----------
    polished_map : (N_part_input,) int
        The refinement of the trilaterated map.
    part, whole : Surface
        As in :func:`choose_part_map`.
    stats : PartMapStats
        :func:`trilaterated_if_less_distorted`'s, the trilateration kept.

    Returns
    -------
    PartMapStats
        ``stats`` with the polished map's share in ``distortion`` and ``polished`` set.
    """
    if not stats.trilaterated:
        raise ValueError("only a trilaterated map is polished")
    distortion = _recorded("polished", _changed(polished_map, part, whole), stats)
    return dataclasses.replace(stats, distortion=distortion, polished=True)


def _recorded(name: str, share: float, stats: PartMapStats) -> dict[str, float | None]:
    """``stats.distortion`` with a candidate's ``share`` under ``name`` (None: no image)."""
    return {**stats.distortion, name: float(share) if np.isfinite(share) else None}


def _weighed(name: str, share: float, stats: PartMapStats) -> tuple[dict[str, float | None], bool]:
    """:func:`_recorded`, and whether the candidate changes fewer of the part's distances
    than the map kept so far."""
    kept = stats.distortion.get(stats.final)
    return _recorded(name, share, stats), bool(np.isfinite(share) and (kept is None or share < kept))


def _changed(input_map: np.ndarray, part: Surface, whole: Surface) -> float:
    """The share of the part's vertex pairs within ``PART_MAP_RADIUS`` whose distance a
    map of input vertices changes by more than ``PART_MAP_CHANGE`` (NaN: no image)."""
    working = working_map(input_map, part, whole)
    scores = graph_map_distortion(
        working, part.graph, whole.graph, PART_MAP_RADIUS, thresholds=_CHANGE_CLIP, balls=part.balls
    )
    return float(scores.above(PART_MAP_CHANGE))


def choose_part_map(
    extraction_map: np.ndarray, part: Surface, whole: Surface, fmap_map: np.ndarray | None = None
) -> tuple[np.ndarray | None, PartMapStats]:
    """Keep the extraction's map of a part into its whole, or replace it by the partial
    functional map's when that changes fewer of the part's geodesic distances.

    Parameters
    ----------
    extraction_map, fmap_map : (N_part_input,) int
        Input vertex of the whole of every input vertex of the part, -1 for none: the
        extraction's map, and the partial functional map's (:func:`part_fmap_map`; None:
        the extraction's is only measured).
    part, whole : Surface
        Prepared in one unit (point clouds too); the distortion is measured on their
        working meshes' graphs.

    Returns
    -------
    vertex_map : (N_part_input,) int64 or None
        The partial functional map's; None when the extraction's is kept.
    stats : PartMapStats
    """
    maps = {"extraction": extraction_map}
    if fmap_map is not None:
        maps["partial_fmap"] = fmap_map
    shares = {name: _changed(input_map, part, whole) for name, input_map in maps.items()}
    distortion = {name: (float(s) if np.isfinite(s) else None) for name, s in shares.items()}
    if fmap_map is None:
        return None, PartMapStats("extraction", distortion)
    fmap_share, kept = shares["partial_fmap"], shares["extraction"]  # NaN: the map gives no image
    if not (np.isfinite(fmap_share) and (not np.isfinite(kept) or fmap_share < kept)):
        return None, PartMapStats("extraction", distortion)
    return np.asarray(fmap_map, dtype=np.int64), PartMapStats("partial_fmap", distortion)
