"""The dense global symmetry map, chosen by the marginals among candidate maps.

A self-matching run's global map can come from three places: the extraction's global
symmetry extended to every vertex (:func:`intrinsym.vertex_maps.fitted_vertex_map`,
resolved to the sample spacing), that symmetry refined by seeded ZoomOut in the
Laplace-Beltrami eigenfunctions (:func:`intrinsym.spectral.seeded_symmetry`, vertex
precision, but it can drift on strongly posed shapes), and the spectral baseline's
candidates (sign search + ZoomOut, :func:`intrinsym.spectral.symmetry_candidates`),
which need no marginals at all. The marginals judge: every candidate is scored by the
marginal mass it keeps (:func:`intrinsym.confidence.kept_mass`, within
``Params.mass_radius`` of each source sample's image). ZoomOut's map stays unless
it keeps ``MAP_MARGIN`` less mass than the extraction's: where both are right they keep
nearly the same mass within 0.10 (the extraction's sends every sample to a marginal
peak, so it can win by a hair, and within 0.05 by more at small sample counts) and
ZoomOut's is the more precise; where ZoomOut drifts on a strongly posed shape, it loses
mass within 0.10. The spectral candidates are only
tried when the chosen map keeps less than ``Params.fallback_mass``, and replace it only
when they keep ``MAP_MARGIN`` more.

The kept mass of the winner is recorded as the global map's mass (``run.json``'s
``global_map``). Only a run whose extraction found a global symmetry gets a global map:
the spectral candidates replace a weak map, they never invent a global symmetry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from . import spectral
from .confidence import kept_mass
from .extract import Symmetry
from .params import MAP_MARGIN, Params
from .support import Support
from .surface import Surface
from .vertex_maps import fitted_vertex_map

__all__ = ["GlobalMap", "choose_global_map"]


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
        Kept mass of every candidate tried ("spectral" is the best spectral candidate).
    """

    vertex_map: np.ndarray
    mass: float
    source: str
    masses: dict[str, float]


def _input_images(surface: Surface, image: np.ndarray) -> np.ndarray:
    """Working-vertex images -> nearest input vertices."""
    return surface.nearest_input_vertex(surface.shape.vertices[image])


def zoomout_map(
    surface: Surface, ps: np.ndarray, pt: np.ndarray, symmetry: Symmetry, evecs: np.ndarray, p: Params
) -> np.ndarray:
    """The symmetry's sample pairs refined by seeded ZoomOut, as the image of every input
    vertex (:func:`intrinsym.spectral.seeded_symmetry` on the working shape, the first
    ``p.zoomout_seed`` eigenfunctions fitted to the pairs, up to ``p.zoomout_final``).

    Returns
    -------
    (N_in,) int64
    """
    image = spectral.seeded_symmetry(
        surface.shape.vertices,
        evecs,
        ps[symmetry.source],
        pt[symmetry.target],
        p.zoomout_seed,
        p.zoomout_final,
        points=surface.vertex_map,
        candidates=np.unique(surface.vertex_map),
    )
    return _input_images(surface, image)


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
    p: Params,
) -> GlobalMap:
    """Score the candidate global maps by the marginal mass they keep; choose one.

    ZoomOut's map unless it keeps ``MAP_MARGIN`` less mass than the extraction's; below
    ``p.fallback_mass``, the best spectral candidate when it keeps ``MAP_MARGIN`` more.

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
    p : Params

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
        maps["zoomout"] = zoomout_map(surface, ps, pt, symmetry, spectrum[1], p)
    masses = {name: mass_of(m) for name, m in maps.items()}
    if p.zoomout and spectrum is not None and masses[choose(masses, p.fallback_mass)] < p.fallback_mass:
        found = best_spectral(surface, source_vertex, spectrum, mass_of, p)
        if found is not None:
            maps["spectral"], masses["spectral"] = found
    best = choose(masses, p.fallback_mass)
    return GlobalMap(np.asarray(maps[best], dtype=np.int64), masses[best], best, masses)


def best_spectral(
    surface: Surface,
    source_vertex: np.ndarray,
    spectrum: tuple[np.ndarray, np.ndarray],
    mass_of: Callable[[np.ndarray], float],
    p: Params,
) -> tuple[np.ndarray, float] | None:
    """The spectral candidate that keeps the most marginal mass, as an input-vertex map."""
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
    image = candidates[spectral.nearest_images(phi[surface.vertex_map], phi[candidates], maps[best])]
    return _input_images(surface, image), masses[best]
