"""The working surface the stages run on: cleaned, normalised to unit area, sampled.

:func:`prepare` turns any :class:`~intrinsym.mesh.shape.Shape` into a :class:`Surface`
(centred, unit sqrt(area), midpoint-subdivided when too coarse, with its geodesic graph
and normals); :func:`prepare_pair` prepares two for matching in a common unit;
:func:`sample` picks Poisson-disc samples of it.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .errors import InputError, ParameterError
from .geodesics import geodesics
from .geodesics._dijkstra import ball_pairs, csr_arrays
from .mesh import io, sampling
from .mesh.shape import Shape, clean, from_arrays, surface_area, vertex_normals
from .params import PARTIAL_AREA, MatchScale
from .spectral import laplacian

#: What :func:`as_shape` reads: a path, a Shape, a (vertices, faces) tuple, an (N, 3)
#: array (a point cloud), or an object with ``vertices`` (and ``faces``), such as a
#: trimesh.Trimesh or PointCloud. Results index its vertices in the order it gives them.
ShapeLike = str | os.PathLike | Shape | tuple | np.ndarray | Any


@dataclass(frozen=True)
class Surface:
    """A cleaned shape, normalised to unit sqrt(area), with what the stages need.

    Attributes
    ----------
    shape : Shape
        Normalised (centred, unit area), cleaned, possibly subdivided working shape.
    input_shape : Shape
        The shape it was prepared from (:func:`as_shape` returns it): what ``detect``'s
        self map and a part's map in ``match`` prepare again without subdivision
        (:func:`unrefined`).
    vertex_map : (N_in,) int64
        Working vertex representing each input vertex.
    center : (3,) float64
    scale : float
        Input length per normalised length (sqrt of the input surface area).
    graph : scipy.sparse.csr_matrix
        Geodesic graph of the working shape.
    normals : (N, 3) float64
    min_vertices : int
        The working size it was prepared for: a mesh with fewer vertices is subdivided
        until it has this many (``WORK_PER_SAMPLE`` max(n_source, n_target) of the
        parameters it was prepared with, :func:`intrinsym.prepare`).
    subdivided : bool
        Whether the cleaned mesh was subdivided to reach it.
    """

    shape: Shape
    input_shape: Shape
    vertex_map: np.ndarray
    center: np.ndarray
    scale: float
    graph: Any
    normals: np.ndarray
    min_vertices: int = 0
    subdivided: bool = False
    _spectra: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = dataclasses.field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    _balls: dict[tuple[bytes, float], tuple[np.ndarray, np.ndarray, np.ndarray]] = dataclasses.field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    _unrefined: dict[float | None, Surface] = dataclasses.field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def eigenpairs(self, k: int, coarse: int) -> tuple[np.ndarray, np.ndarray]:
        """The working shape's ``k`` smallest Laplace-Beltrami eigenpairs
        (:func:`intrinsym.spectral.laplacian.eigenpairs`, ``coarse`` as there), solved once
        per ``(k, coarse)``: the detects of one prepared surface share them.

        Returns
        -------
        evals : (k,) float64, read-only
        evecs : (N, k) float64, read-only
        """
        key = (k, coarse)
        if key not in self._spectra:
            pairs = laplacian.eigenpairs(self.shape.vertices, self.shape.faces, k, coarse)
            for a in pairs:
                a.setflags(write=False)
            self._spectra[key] = pairs
        return self._spectra[key]

    def balls(self, sources: np.ndarray, limit: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``graph``'s geodesic distances from ``sources`` to every vertex within ``limit``
        (:func:`~intrinsym.geodesics._dijkstra.ball_pairs`), kept for the last sources and
        limit asked: a part's candidate maps are weighed a dozen times from the same
        vertices, and these balls were a third of the weighing's time.

        Returns
        -------
        rows, cols, dists : (nnz,) int64, int64, float64, read-only
            As :func:`~intrinsym.geodesics._dijkstra.ball_pairs` returns them.
        """
        sources = np.asarray(sources, dtype=np.int64)
        key = (sources.tobytes(), float(limit))
        if key not in self._balls:
            self._balls.clear()
            triples = ball_pairs(csr_arrays(self.graph), sources, limit)
            for a in triples:
                a.setflags(write=False)
            self._balls[key] = triples
        return self._balls[key]

    def to_input(self, points: np.ndarray) -> np.ndarray:
        """Normalised coordinates -> the input file's coordinates."""
        return points * self.scale + self.center

    @cached_property
    def chord_graph(self) -> Any:
        """The working mesh's edges and the shortcut chords across them
        (:func:`~intrinsym.geodesics.geodesics.surface_graph` with ``rings=1``), built once:
        a part's trilaterations and hypotheses measure their distances on it (``graph``'s
        longer chords cut across a coarse mesh's thin limbs, differently on two meshes).
        A mesh's only; a point cloud has ``graph`` alone."""
        if self.shape.faces is None:
            raise ValueError("a point cloud has no mesh edges to chord")
        return geodesics.surface_graph(self.shape.vertices, self.shape.faces, rings=1)

    @cached_property
    def input_vertices(self) -> np.ndarray:
        """Vertices of the input shape as read, (N_in, 3) float64, for output coordinates."""
        return np.asarray(self.input_shape.vertices, dtype=np.float64)

    @cached_property
    def working_inputs(self) -> np.ndarray:
        """The input vertex nearest every working vertex, (N_working,) int64, found once
        (a part's match maps between input vertices a dozen times)."""
        return self.nearest_input_vertex(self.shape.vertices)

    @cached_property
    def _input_tree(self) -> cKDTree:
        # built once: a detect asks for nearest input vertices nine times
        return cKDTree(self.input_vertices)

    def nearest_input_vertex(self, points: np.ndarray) -> np.ndarray:
        """Index of the input vertex nearest each normalised point, (n,) int64."""
        _, idx = self._input_tree.query(self.to_input(points))
        return idx.astype(np.int64)


def prepare(shape: Shape, min_vertices: int = 0) -> Surface:
    """Clean, normalise to unit surface area and (for meshes) subdivide a shape.

    Parameters
    ----------
    shape : Shape
    min_vertices : int
        Meshes with fewer vertices are midpoint-subdivided until they have this many, so
        that the dense target sampling has a surface to choose from.
    """
    cleaned, vertex_map = clean(shape)
    area = surface_area(cleaned)
    if not np.isfinite(area) or area <= 0:
        raise InputError(f"{shape.path or 'input'}: the surface has zero area")
    center = cleaned.vertices.mean(axis=0)
    scale = float(np.sqrt(area))
    vertices = (cleaned.vertices - center) / scale
    faces = cleaned.faces
    subdivided = False
    if faces is not None and len(vertices) < min_vertices:
        vertices, faces = sampling.subdivide_to(vertices, faces, min_vertices)
        subdivided = True
    work = Shape(vertices, faces, shape.path)
    return Surface(
        shape=work,
        input_shape=shape,
        vertex_map=vertex_map,
        center=center,
        scale=scale,
        graph=geodesics.surface_graph(vertices, faces),
        normals=vertex_normals(work),
        min_vertices=min_vertices,
        subdivided=subdivided,
    )


def working_map(vertex_map: np.ndarray, source: Surface, target: Surface) -> np.ndarray:
    """A map between input vertices, (N_source_input,) int (-1: none), as working vertex
    of ``target`` of every working vertex of ``source`` (each takes its nearest input
    vertex's image), (N_source_working,) int64; :func:`input_map` goes back."""
    image = np.asarray(vertex_map, dtype=np.int64)[source.working_inputs]
    return np.where(image >= 0, target.vertex_map[np.maximum(image, 0)], -1)


def input_map(working: np.ndarray, source: Surface, target: Surface) -> np.ndarray:
    """A map between working vertices, (N_source_working,) int (-1: none), as input
    vertex of ``target`` of every input vertex of ``source``, (N_source_input,) int64."""
    return np.where(working >= 0, target.working_inputs[np.maximum(working, 0)], -1)[source.vertex_map]


def serves(surface: Surface, min_vertices: int) -> bool:
    """Whether ``surface`` is what :func:`prepare` gives for ``min_vertices``: it was
    prepared for that size, or it needed no subdivision and has at least that many
    vertices (or is a point cloud, never subdivided)."""
    if min_vertices == surface.min_vertices:
        return True
    enough = surface.shape.faces is None or len(surface.shape.vertices) >= min_vertices
    return not surface.subdivided and enough


def rescaled(surface: Surface, factor: float) -> Surface:
    """``surface`` with its working lengths multiplied by ``factor`` (its unit divided by
    it); ``surface`` itself, with the eigenpairs and balls it keeps, when ``factor`` is 1."""
    if factor == 1.0:
        return surface
    work = Shape(surface.shape.vertices * factor, surface.shape.faces, surface.shape.path)
    return dataclasses.replace(surface, shape=work, scale=surface.scale / factor, graph=surface.graph * factor)


def common_unit(a: Surface, b: Surface, scale: MatchScale) -> float | None:
    """The input length both of two prepared surfaces are measured in for matching, or
    None when each keeps its own (unit area).

    Parameters
    ----------
    a, b : Surface
        As :func:`prepare` returns them (each in its own unit, sqrt of its area).
    scale : {"auto", "larger", "each"}
        "larger": sqrt(area) of the larger one, so that a part keeps its size relative to
        the whole (each prepared alone would be blown up to unit area, and every geodesic
        distance the pairwise term compares with the other shape's would be off by
        sqrt(area ratio)); "each": None; "auto": "larger" when the smaller has less than
        ``PARTIAL_AREA`` of the larger's area, else "each".
    """
    if scale == "auto":
        ratio = (min(a.scale, b.scale) / max(a.scale, b.scale)) ** 2
        scale = "larger" if ratio < PARTIAL_AREA else "each"
    return None if scale == "each" else max(a.scale, b.scale)


def in_unit(surface: Surface, unit: float | None) -> Surface:
    """A surface from :func:`prepare` measured in ``unit`` (input length; None: as it is)."""
    return surface if unit is None else rescaled(surface, surface.scale / unit)


def unrefined(surface: Surface, unit: float | None = None) -> Surface:
    """``surface`` as :func:`prepare` gives it without subdivision, in ``unit`` (input
    length, the one ``surface`` is in; None: unit area): the surface itself, with what it
    keeps, when it was not subdivided, else its input shape prepared again, once per
    unit (the matches of many parts onto one refined whole share it and its eigenpairs).
    The meshes as given, on which a self map and a part's map are solved (a refined
    mesh's chords and spectra are not the input's)."""
    if serves(surface, 0):
        return surface
    if unit not in surface._unrefined:
        surface._unrefined[unit] = in_unit(prepare(surface.input_shape, 0), unit)
    return surface._unrefined[unit]


def prepare_pair(a: Shape, b: Shape, min_vertices: int, scale: MatchScale) -> tuple[Surface, Surface]:
    """:func:`prepare` two shapes for matching, in their :func:`common_unit`.

    Parameters
    ----------
    a, b : Shape
    min_vertices : int
        As in :func:`prepare`.
    scale : {"auto", "larger", "each"}
        As in :func:`common_unit`.
    """
    first, second = prepare(a, min_vertices), prepare(b, min_vertices)
    unit = common_unit(first, second, scale)
    return in_unit(first, unit), in_unit(second, unit)


def as_shape(obj: ShapeLike) -> Shape:
    """Read a :data:`ShapeLike` into a :class:`Shape`.

    The vertices keep the input's order: a file's (:func:`intrinsym.mesh.io.load`), the
    rows of an array, a trimesh object's ``vertices``. An array is read as a point
    cloud; one that is not (N, 3), holds NaN or infinity, or has fewer than 4 rows is
    an :class:`~intrinsym.errors.InputError`. A :class:`Surface` gives the shape it was
    prepared from.
    """
    if isinstance(obj, Shape):
        return obj
    if isinstance(obj, Surface):
        return obj.input_shape
    if isinstance(obj, (str, os.PathLike)):
        return io.load(obj)
    if isinstance(obj, tuple):
        return from_arrays(*obj)
    if isinstance(obj, np.ndarray):
        return from_arrays(obj, None)
    if hasattr(obj, "vertices"):  # a trimesh.Trimesh or PointCloud
        faces = getattr(obj, "faces", None)
        return from_arrays(np.asarray(obj.vertices), None if faces is None else np.asarray(faces))
    raise TypeError(f"cannot read a shape from {type(obj).__name__}")


def sample(surface: Surface, n: int | None, spacing: float | None, seed: int) -> np.ndarray:
    """Poisson-disc sample of working vertices, by count ``n`` or by ``spacing``.

    Returns
    -------
    (n,) int64, sorted working-vertex indices.
    """
    verts = surface.shape.vertices
    if spacing is not None:
        chosen = sampling.farthest_point_sampling(verts, spacing=spacing, seed=seed)
    elif n is None or n > len(verts):
        raise ParameterError(
            f"{surface.shape.path or 'shape'}: asked for {n} samples but the surface has {len(verts)} points"
        )
    else:
        chosen = sampling.farthest_point_sampling(verts, n=n, seed=seed)
    # Index order, not selection order: near-ties in the farthest-point order flip with
    # rounding (e.g. after a change of units), the chosen set does not.
    return np.sort(chosen)
