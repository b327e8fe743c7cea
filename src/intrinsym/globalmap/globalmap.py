"""The dense global symmetry map, chosen by the marginals among candidate maps.

A self-matching run's global map can come from three places: the extraction's global
symmetry extended to every vertex (:func:`intrinsym.globalmap.vertex_maps.fitted_vertex_map`,
resolved to the sample spacing), that symmetry refined by seeded ZoomOut in the
Laplace-Beltrami eigenfunctions (:func:`zoomout_map`: vertex precision; fitted as the
symmetry is and as its own inverse, the marginals choosing between the two fits cell by
cell; it can still drift on strongly posed shapes), and the spectral baseline's
candidates (sign search + ZoomOut, :func:`intrinsym.spectral.spectral.symmetry_candidates`),
which need no marginals at all. The marginals judge: every candidate is scored by the
marginal mass it keeps (:func:`intrinsym.globalmap.confidence.kept_mass`, within
``Params.mass_radius`` of each source sample's image). ZoomOut's map stays unless
it keeps ``MAP_MARGIN`` less mass than the extraction's: where both are right they keep
nearly the same mass within 0.10 (the extraction's sends every sample to a marginal
peak, so it can win by a hair, and within 0.05 by more at small sample counts) and
ZoomOut's is the more precise; where ZoomOut drifts on a strongly posed shape, it loses
mass within 0.10. The spectral candidates are only
tried when the chosen map keeps less than ``Params.fallback_mass``, and replace it only
when they keep ``MAP_MARGIN`` more.

The winner is then refined by geodesic trilateration to the marginals' sample images
(:func:`refined_map`, :mod:`intrinsym.globalmap.refine`) and smoothed by one projection onto the
eigenfunctions (:func:`smoothed_map`, kept unless it keeps ``MAP_MARGIN`` less mass), and
its kept mass is recorded as the global map's mass (``run.json``'s ``global_map``). On a
shape of several connected components, those that hold fewer than ``CARRY_SAMPLES``
source samples (a tooth or an eye modelled apart) then take the rigid motion of the
surface around them (:func:`carried_map`). The map's local distortion
(:func:`local_map_distortion`) picks the confidence's calibration table. Only a run
whose extraction found a global symmetry gets a global map: the spectral candidates
replace a weak map, they never invent a global symmetry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import connected_components

from ..extract.support import Support
from ..extract.symmetry import Symmetry
from ..params import MAP_MARGIN, Params
from ..spectral import neighbours, spectral
from ..surface import Surface
from . import distortion
from .confidence import DISAGREEMENT_RANGE, INVOLUTIVE_SHARE, kept_mass, mass_within, trip_distance
from .refine import consistent_anchors, spectral_descent, trilaterate
from .vertex_maps import carried_to_components, fitted_vertex_map

__all__ = ["GlobalMap", "carried_map", "choose_global_map"]

#: :func:`supported_map` drops the image of a vertex whose round trip is at least this
#: long (sqrt(area) units): twice ``DISAGREEMENT_RANGE``, so that the image or the image's
#: image is off by 0.10 at least. On complete TOSCA poses a right image's round trip
#: reaches 0.136 (cat1's tail tip, on the mirror plane); at 0.10, 0.9 % of cat1's
#: vertices, 0.7 % right within 0.10, lost their image (docs/results.md).
SUPPORT_TRIP = 2 * DISAGREEMENT_RANGE


#: Radius (sqrt(area) units) of the marginal mass that chooses, per source sample's cell,
#: between seeded ZoomOut's plain and involutive fits (:func:`intrinsym.globalmap.globalmap.zoomout_map`).
CELL_RADIUS = 0.05
#: The involutive ZoomOut fit's image of a vertex is kept only within this distance (sqrt(area) units) of
#: the extraction's image; beyond it, the plain fit's (:func:`intrinsym.globalmap.globalmap.zoomout_map`).
GUIDE_TOLERANCE = 0.05
#: A vertex whose global-map image keeps its geodesic distances to the anchors of ``refine_anchors``
#: within this many target spacings (root mean square, and to the nearest anchor) keeps it
#: (:func:`intrinsym.globalmap.refine.trilaterate`; measured in docs/notes/2026-11-28-results-behind-the-defaults.md).
REFINE_TOLERANCE = 2.0
#: Samples farther than this (sqrt(area) units) from a vertex are not its anchors.
REFINE_REACH = 0.3
#: ``smooth_map`` fits its functional map only with at least this many mapped input
#: vertices per eigenfunction; a coarser input keeps its map
#: (:func:`intrinsym.globalmap.globalmap.smoothed_map`).
SMOOTH_POINTS = 4
#: A connected component with fewer source samples than this is carried by the rigid
#: motion of the surface around it rather than mapped by the model: two sample pairs do
#: not fix its orientation (:func:`intrinsym.globalmap.globalmap.carried_map`).
CARRY_SAMPLES = 3


@dataclass(frozen=True)
class GlobalMap:
    """The chosen global map and how it was chosen.

    Attributes
    ----------
    vertex_map : (N_in,) int64
        Image input vertex of every input vertex.
    mass : float
        Marginal mass the map keeps.
    source : str
        Which candidate won: "extraction", "zoomout" or "spectral".
    masses : dict of str to float
        Kept mass of every candidate tried ("spectral" is the best spectral candidate),
        before the refinement.
    refined : float
        Share of the input vertices whose image :func:`refined_map` moved.
    smoothed : float
        Share of the input vertices whose image :func:`smoothed_map` then moved (0 when
        it was refused or not run).
    carried : float
        Share of the input vertices on connected components with fewer than
        ``CARRY_SAMPLES`` source samples, whose image :func:`carried_map` gave.
    """

    vertex_map: np.ndarray
    mass: float
    source: str
    masses: dict[str, float]
    refined: float = 0.0
    smoothed: float = 0.0
    carried: float = 0.0


def _input_images(surface: Surface, image: np.ndarray) -> np.ndarray:
    """Working-vertex images -> nearest input vertices."""
    return surface.nearest_input_vertex(surface.shape.vertices[image])


def cell_mass(marginals: np.ndarray, support: Support) -> Callable[[np.ndarray], np.ndarray]:
    """The judge of :func:`zoomout_map` from BP's marginals: (S,) input-vertex images of
    the source samples -> (S,) marginal mass within ``CELL_RADIUS`` of each."""

    def sample_mass(image: np.ndarray) -> np.ndarray:
        return mass_within(marginals, support.vertex_target[image], support.targets, CELL_RADIUS)

    return sample_mass


def zoomout_map(
    surface: Surface,
    ps: np.ndarray,
    pt: np.ndarray,
    symmetry: Symmetry,
    evecs: np.ndarray,
    p: Params,
    source_vertex: np.ndarray,
    vertex_source: np.ndarray,
    sample_mass: Callable[[np.ndarray], np.ndarray],
    guide: np.ndarray,
    device: str = "cpu",
) -> np.ndarray:
    """The symmetry's sample pairs refined by seeded ZoomOut, as the image of every input
    vertex.

    Two fits of the first ``p.zoomout_seed`` eigenfunctions to the pairs (without the
    pairs the fit cannot explain, :func:`intrinsym.spectral.spectral.seed_map`), each refined
    up to ``p.zoomout_final`` (:func:`intrinsym.spectral.spectral.seeded_functional_maps` on the
    working shape): one as the symmetry is (plain), one as its own inverse (every pair
    also reversed, ``involution=True``), which holds for a reflection and keeps the fit
    from drifting on strongly posed shapes. The marginals judge them cell by cell: each
    source sample's Voronoi cell follows the fit that keeps more of the sample's
    marginal mass within ``CELL_RADIUS`` of its image, the involutive one on a tie (the
    plain fit wins everywhere on a rotation, which is not its own inverse). A vertex's
    involutive image farther than ``GUIDE_TOLERANCE`` from the extraction's image of it
    (``guide``) is replaced by the plain fit's: the involutive fit can flip a small,
    densely meshed part such as a head, around a sample it maps right.

    Parameters
    ----------
    surface : Surface
    ps, pt : (S,), (T,) int64
        Working vertices of the source and target samples.
    symmetry : Symmetry
    evecs : (N, K) float array
        Eigenfunctions of the working shape, constant first.
    p : Params
    source_vertex : (S,) int64
        Input vertex of every source sample.
    vertex_source : (N_in,) int64
        Source sample whose cell holds each input vertex, -1 for none.
    sample_mass : callable
        (S,) input-vertex images of the source samples -> (S,) marginal mass within
        ``CELL_RADIUS`` of each (:func:`cell_mass`).
    guide : (N_in,) int64
        The extraction's image of every input vertex, -1 for none
        (:func:`intrinsym.globalmap.vertex_maps.fitted_vertex_map`).
    device : {"cpu", "gpu"}
        Where ZoomOut's nearest-row searches and the point maps of every input vertex
        run (:func:`intrinsym.spectral.spectral.nearest_images`; the same maps on both).

    Returns
    -------
    (N_in,) int64
    """
    fits = spectral.seeded_functional_maps(
        surface.shape.vertices,
        evecs,
        ps[symmetry.source],
        pt[symmetry.target],
        p.zoomout_seed,
        p.zoomout_final,
        involutions=(True, False),
        device=device,
    )
    candidates = np.unique(surface.vertex_map)
    # every fit has the same size: one search structure serves all their point maps
    k = len(fits[0])
    rows = neighbours.search_rows(evecs[candidates, 1 : k + 1], device)

    def images_of(vertices: np.ndarray, C: np.ndarray) -> np.ndarray:
        """Input vertices -> input-vertex images under the functional map C."""
        points = surface.vertex_map[vertices]
        return _input_images(surface, candidates[spectral.nearest_images(evecs[points, 1 : k + 1], rows, C, device)])

    masses = [sample_mass(images_of(source_vertex, C)) for C in fits]
    plain_cell = masses[1] > masses[0]
    cell = np.asarray(vertex_source, dtype=np.int64)
    # vertices in no cell follow the fit most cells follow
    plain = np.where(cell >= 0, plain_cell[np.maximum(cell, 0)], 2 * plain_cell.sum() > len(plain_cell))
    image = np.empty(len(cell), dtype=np.int64)
    involutive = np.flatnonzero(~plain)
    image[involutive] = images_of(involutive, fits[0])
    # the involutive image strays from the extraction's: the plain fit's instead
    guide = np.asarray(guide, dtype=np.int64)
    positions = surface.shape.vertices[surface.vertex_map]
    stray = involutive[
        (guide[involutive] >= 0)
        & (np.linalg.norm(positions[image[involutive]] - positions[guide[involutive]], axis=1) > GUIDE_TOLERANCE)
    ]
    rest = np.concatenate([np.flatnonzero(plain), stray])
    image[rest] = images_of(rest, fits[1])
    return image


def choose(masses: dict[str, float], fallback_mass: float) -> str:
    """The rule: ZoomOut's map ("zoomout") unless it keeps ``MAP_MARGIN`` less mass than
    the extraction's ("extraction"); a "spectral" candidate, when scored, wins only if the
    chosen map keeps less than ``fallback_mass`` and the candidate ``MAP_MARGIN`` more."""
    best = "zoomout" if masses.get("zoomout", -1.0) >= masses["extraction"] - MAP_MARGIN else "extraction"
    if "spectral" in masses and masses[best] < fallback_mass and masses["spectral"] > masses[best] + MAP_MARGIN:
        best = "spectral"
    return best


def choose_global_map(
    surface: Surface,
    ps: np.ndarray,
    pt: np.ndarray,
    source_vertex: np.ndarray,
    marginals: np.ndarray,
    symmetry: Symmetry,
    support: Support,
    spectrum: tuple[np.ndarray, np.ndarray] | None,
    fit: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    spacing: float,
    p: Params,
    device: str = "cpu",
) -> GlobalMap:
    """Score the candidate global maps by the marginal mass they keep; choose one, refine it.

    ZoomOut's map unless it keeps ``MAP_MARGIN`` less mass than the extraction's; below
    ``p.fallback_mass``, the best spectral candidate when it keeps ``MAP_MARGIN`` more.
    The winner is refined by :func:`refined_map` unless ``p.refine_anchors`` is 0.

    Parameters
    ----------
    surface : Surface
        The working shape (self-matching).
    ps, pt : (S,), (T,) int64
        Working vertices of the source and target samples.
    source_vertex : (S,) int64
        Input vertex of every source sample.
    marginals : (S, T) float array
    symmetry : Symmetry
        The extraction's global symmetry.
    support : Support
    spectrum : ((K,), (N, K)) float arrays or None
        Eigenpairs of the working shape, constant first; None: only the extraction's map.
    fit : ((E, 2), (S, 3), (T, 3), (T,)) arrays
        Source-graph edges, source and target sample positions (input coordinates) and
        the input vertex of every target sample, for :func:`fitted_vertex_map`.
    spacing : float
        Target spacing (sqrt(area) units), the scale of the refinement's tolerance.
    p : Params
    device : {"cpu", "gpu"}
        Where the nearest-row searches of ZoomOut and of the point maps run (the same
        maps on both).

    Returns
    -------
    GlobalMap
    """
    t = support.targets
    r = p.mass_radius

    def mass_of(vertex_map: np.ndarray) -> float:
        image = np.asarray(vertex_map)[source_vertex]
        return kept_mass(marginals, np.where(image >= 0, support.vertex_target[np.maximum(image, 0)], -1), t, r)

    maps = {"extraction": fitted_vertex_map(symmetry, support, *fit, p.extraction(False))}
    if p.zoomout and spectrum is not None and len(symmetry.source) >= p.zoomout_seed:
        maps["zoomout"] = zoomout_map(
            surface,
            ps,
            pt,
            symmetry,
            spectrum[1],
            p,
            source_vertex,
            support.vertex_source,
            cell_mass(marginals, support),
            maps["extraction"],
            device,
        )
    masses = {name: mass_of(m) for name, m in maps.items()}
    if p.zoomout and spectrum is not None and masses[choose(masses, p.fallback_mass)] < p.fallback_mass:
        found = best_spectral(surface, source_vertex, spectrum, mass_of, p, device)
        if found is not None:
            maps["spectral"], masses["spectral"] = found
    best = choose(masses, p.fallback_mass)
    vertex_map = np.asarray(maps[best], dtype=np.int64)
    refined = vertex_map
    if p.refine_anchors > 0:
        refined = refined_map(surface, ps, pt, source_vertex, marginals, vertex_map, fit[0], spacing, p)
    final, mass = refined, mass_of(refined)
    if p.smooth_map and spectrum is not None:
        smoothed = smoothed_map(surface, refined, spectrum[1])
        # the marginals judge, as they judge the candidates
        smoothed_mass = mass_of(smoothed)
        if smoothed_mass >= mass - MAP_MARGIN:
            final, mass = smoothed, smoothed_mass
    carried, loose = carried_map(surface, ps, final)
    return GlobalMap(
        carried,
        mass,
        best,
        masses,
        float(np.mean(refined != vertex_map)),
        float(np.mean(final != refined)),
        float(np.mean(loose)),
    )


def carried_map(surface: Surface, ps: np.ndarray, vertex_map: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The global map carried onto the connected components of the working shape that
    hold fewer than ``CARRY_SAMPLES`` of the source samples ``ps``
    (:func:`intrinsym.globalmap.vertex_maps.carried_to_components`).

    Returns
    -------
    vertex_map : (N_in,) int64
    loose : (N_in,) bool
        The input vertices carried: none on a connected shape, or where no component
        holds that many samples (nothing to carry them by).
    """
    n_components, label = connected_components(surface.graph, directed=False)
    component = label[surface.vertex_map]
    held = np.bincount(label[ps], minlength=n_components)[component] >= CARRY_SAMPLES
    if n_components == 1 or held.all() or not held.any():
        return vertex_map, np.zeros(len(held), dtype=bool)
    positions = surface.shape.vertices[surface.vertex_map]
    return carried_to_components(positions, component, vertex_map, held), ~held


def smoothed_map(surface: Surface, vertex_map: np.ndarray, evecs: np.ndarray) -> np.ndarray:
    """The global map projected once onto the eigenfunctions of the working shape
    (:func:`intrinsym.globalmap.refine.spectral_descent`), as the image of every input vertex.

    Parameters
    ----------
    surface : Surface
    vertex_map : (N_in,) int64
        Image input vertex of every input vertex, -1 for none (kept).
    evecs : (N, K) float array
        Eigenfunctions of the working shape, constant first.

    Returns
    -------
    (N_in,) int64
        The map unchanged when fewer than ``SMOOTH_POINTS * K`` distinct vertices are mapped.
    """
    work = surface.vertex_map
    has = np.flatnonzero(vertex_map >= 0)
    if len(np.unique(work[has])) < SMOOTH_POINTS * evecs.shape[1]:
        # too few vertices for a least-squares fit that smooths rather than interpolates
        return vertex_map.copy()
    start = work[vertex_map[has]]
    image = spectral_descent(surface.graph, work[has], start, evecs)
    moved = image != start
    out = vertex_map.copy()
    out[has[moved]] = _input_images(surface, image[moved])
    return out


def supported_map(vertex_map: np.ndarray, vertices: np.ndarray, scale: float) -> np.ndarray:
    """The dominant symmetry's map with -1 where it has no support: a reflection that does
    not return a vertex to within ``SUPPORT_TRIP`` of itself.

    On an incomplete shape, the vertices whose partner is missing still get an image
    (ZoomOut and the refinement map every vertex; a partial symmetry's part can reach past
    its partner), on the partner side's remains; that image's own image is its true
    partner, far from the vertex. A vertex whose round trip is that long has its image or
    its image's image off by half of it, ``DISAGREEMENT_RANGE``, at least: the map is not
    the symmetry there. A map that returns fewer than ``INVOLUTIVE_SHARE`` of the vertices
    it maps is no reflection (a rotation of higher order) and keeps every image. A vertex
    whose image has none (a partial map's) keeps its own: its round trip is unknown.

    Parameters
    ----------
    vertex_map : (N,) int64
        Image input vertex of every input vertex, -1 for none.
    vertices : (N, 3) float
        Input vertex positions.
    scale : float
        sqrt(area) of the shape, in input units.
    """
    image = np.asarray(vertex_map, dtype=np.int64)
    trip = trip_distance(vertices, image, scale)
    mapped = image >= 0
    if not mapped.any() or np.mean(trip[mapped] < DISAGREEMENT_RANGE) < INVOLUTIVE_SHARE:
        return image
    return np.where(trip >= SUPPORT_TRIP, -1, image)


def local_map_distortion(surface: Surface, vertex_map: np.ndarray) -> np.ndarray:
    """(N_in,) float32: the local distortion of a self-map of the input vertices
    (:func:`intrinsym.globalmap.distortion.local_distortion`), measured on the working shape's
    graph (each input vertex at its working vertex); NaN where unknown."""
    work = surface.vertex_map
    vertex_map = np.asarray(vertex_map, dtype=np.int64)
    has = vertex_map >= 0
    image = np.full(len(surface.shape.vertices), -1, dtype=np.int64)
    image[work[has]] = work[vertex_map[has]]
    local = distortion.local_distortion_on_graph(surface.graph, surface.shape.vertices, image)
    return np.where(has, local[work], np.nan).astype(np.float32)


def refined_map(
    surface: Surface,
    ps: np.ndarray,
    pt: np.ndarray,
    source_vertex: np.ndarray,
    marginals: np.ndarray,
    vertex_map: np.ndarray,
    edges: np.ndarray,
    spacing: float,
    p: Params,
    tolerance: float = REFINE_TOLERANCE,
) -> np.ndarray:
    """The global map refined by geodesic trilateration (:func:`intrinsym.globalmap.refine.trilaterate`).

    Anchors: each source sample's marginal argmax target, where it lies within
    ``p.mass_radius`` of the map's image of the sample, or where the map turns the
    sample the wrong way round or (with ``p.remove_trivial``) moves it beyond
    ``p.trivial_radius`` of itself, and the argmax keeps the geodesic distances to those
    anchors better (:func:`intrinsym.globalmap.refine.consistent_anchors`: a part the map flipped
    or slid); each vertex is trilaterated against its ``p.refine_anchors`` nearest
    anchored samples within ``REFINE_REACH`` (those there are, where fewer), and keeps its
    image where that keeps the distances to within ``tolerance`` target spacings, in the
    root mean square and to the nearest anchor.

    Parameters
    ----------
    surface : Surface
    ps, pt : (S,), (T,) int64
        Working vertices of the source and target samples.
    source_vertex : (S,) int64
        Input vertex of every source sample.
    marginals : (S, T) float array
    vertex_map : (N_in,) int64
        Image input vertex of every input vertex.
    edges : (E, 2) int64
        Source-graph edges (rows of ``ps``).
    spacing : float
        Target spacing (sqrt(area) units).
    p : Params
    tolerance : float
        In target spacings (default ``REFINE_TOLERANCE``).

    Returns
    -------
    (N_in,) int64
    """
    work = surface.vertex_map
    start = work[vertex_map]
    anchors = np.asarray(pt, dtype=np.int64)[np.asarray(marginals).argmax(axis=1)]
    samples = np.asarray(ps, dtype=np.int64)
    keep = consistent_anchors(
        surface.graph,
        samples,
        anchors,
        start[source_vertex],
        p.mass_radius,
        p.refine_anchors,
        REFINE_REACH,
        (edges, surface.shape.vertices, surface.normals),
        p.trivial_radius if p.remove_trivial else np.inf,
    )
    image = trilaterate(
        surface.graph,
        work,
        start,
        samples[keep],
        anchors[keep],
        p.refine_anchors,
        tolerance * spacing,
        REFINE_REACH,
    )
    moved = image != start
    out = vertex_map.copy()
    out[moved] = _input_images(surface, image[moved])
    return out


def best_spectral(
    surface: Surface,
    source_vertex: np.ndarray,
    spectrum: tuple[np.ndarray, np.ndarray],
    mass_of: Callable[[np.ndarray], float],
    p: Params,
    device: str = "cpu",
) -> tuple[np.ndarray, float] | None:
    """The spectral candidate that keeps the most marginal mass, as an input-vertex map
    (its last point map's search on ``device``)."""
    evals, evecs = spectrum
    vertices = surface.shape.vertices
    try:
        maps, _ = spectral.symmetry_candidates(vertices, evals, evecs, n_final=p.zoomout_final)
    except ValueError:
        return None
    if not maps:
        return None
    k = len(maps[0])
    phi = np.asarray(evecs, dtype=np.float64)[:, 1 : k + 1]
    candidates = np.unique(surface.vertex_map)
    # score on the working vertices of the input vertices of the samples, then map all
    sample_points = surface.vertex_map[source_vertex]
    masses = []
    for C in maps:
        image = candidates[spectral.nearest_images(phi[sample_points], phi[candidates], C)]
        partial = np.full(len(surface.vertex_map), -1, dtype=np.int64)
        partial[source_vertex] = _input_images(surface, image)
        masses.append(mass_of(partial))
    best = int(np.argmax(masses))
    image = candidates[spectral.nearest_images(phi[surface.vertex_map], phi[candidates], maps[best], device)]
    return _input_images(surface, image), masses[best]
