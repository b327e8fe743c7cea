"""One shape matched to itself: :func:`detect` (partial intrinsic symmetries) and the
working surface it reuses, :func:`prepare`."""

from __future__ import annotations

import dataclasses

from .._threads import one_blas_thread
from ..extract.extract import mapped_symmetry
from ..globalmap.self_hypothesis import TRIVIAL_SHARE, fixed_share, self_symmetry_map
from ..params import Params
from ..problem import sampled
from ..progress import ProgressCallback
from ..result.result import Result
from ..surface import ShapeLike, Surface, as_shape, unrefined
from ..surface import prepare as prepare_surface
from .inputs import check_machine, min_vertices, resolve_params, sample_pair, working_surface
from .stages import Clock, solve


def prepare(
    shape: ShapeLike,
    params: Params | None = None,
    *,
    n_source: int | None = None,
    n_target: int | None = None,
    preset: str = "default",
) -> Surface:
    """The working surface of a shape for :func:`detect` and :func:`match`, to reuse
    across runs.

    Cleaned (duplicate vertices merged; degenerate and duplicate faces and unreferenced
    vertices dropped), centred, normalised to unit surface area, midpoint-subdivided
    while it has fewer than ``WORK_PER_SAMPLE max(n_source, n_target)`` vertices (a mesh; a point cloud
    is never subdivided), with its geodesic graph and normals: what :func:`detect` does
    before sampling. ``detect(prepare(shape, p), p)`` equals ``detect(shape, p)`` exactly,
    so a parameter sweep prepares once; the surface also keeps the Laplace-Beltrami
    eigenpairs its first detect solves (:meth:`intrinsym.Surface.eigenpairs`), for
    the detects after it with the same ``eigenpairs`` and ``eigen_coarse``. Likewise
    ``match(part, prepare(whole, p), p)`` equals ``match(part, whole, p)`` exactly, and
    the matches of many parts onto one prepared whole share the whole's working mesh,
    its eigenpairs and its chord graph (a part's map; about 2 s of a SHREC'16 pair).

    Parameters
    ----------
    shape : path, Shape, (vertices, faces) tuple, (N, 3) array or trimesh object
        As in :func:`detect`.
    params : Params, optional
        The parameters of the runs it is for (default: the preset's); only the sample
        counts matter: they set the working size.
    n_source, n_target : int, optional
        Override the fields of the same names.
    preset : {"default", "paper"}
        The parameters when ``params`` is not given.

    Returns
    -------
    Surface
        :func:`detect` and :func:`match` take it in place of the shape with any
        parameters whose sample counts ask for the same working size (any counts when
        no subdivision was needed); with others they raise
        :class:`~intrinsym.errors.ParameterError` rather than prepare again.
    """
    p = resolve_params(params, preset, n_source=n_source, n_target=n_target)
    return prepare_surface(as_shape(shape), min_vertices(p))


@one_blas_thread
def detect(
    shape: ShapeLike | Surface,
    params: Params | None = None,
    *,
    n_source: int | None = None,
    n_target: int | None = None,
    seed: int | None = None,
    preset: str = "default",
    progress: ProgressCallback | None = None,
) -> Result:
    """Marginals of the self-matching MRF: where may every source sample map on the shape?

    Parameters
    ----------
    shape : path, Shape, (vertices, faces) tuple, (N, 3) array or trimesh object
        A triangle mesh or a point cloud (faces None; an array is one). The result's
        vertex indices refer to its vertices in the order it gives them: a file's
        order (:func:`~intrinsym.mesh.io.load`), a trimesh object's ``vertices``, an
        array's rows. Or a :class:`~intrinsym.surface.Surface` from :func:`prepare`, not
        prepared again: it must have been prepared for these sample counts' working size
        (else :class:`~intrinsym.errors.ParameterError`).
    params : Params, optional
        Every parameter (default: the preset's).
    n_source, n_target, seed : int, optional
        Override the fields of the same names.
    preset : {"default", "paper"}
        The parameters when ``params`` is not given.
    progress : callable, optional
        Called with a :class:`~intrinsym.progress.StageDone` after each stage and a
        :class:`~intrinsym.progress.BPIteration` after each BP iteration.

    Returns
    -------
    Result

    Notes
    -----
    Where no global symmetry is found on a mesh (a shape with a side cut away or holes),
    or the global map found is the trivial match (more than ``TRIVIAL_SHARE`` of its
    vertices stay within ``trivial_radius`` of themselves,
    :func:`~intrinsym.globalmap.self_hypothesis.fixed_share`; its symmetry then becomes an
    identity one), the symmetry map (``global_map``) is the partial one
    :func:`~intrinsym.globalmap.self_hypothesis.self_symmetry_map` keeps: of the
    extraction's map and ``params.self_hypotheses`` maps located from consistent clusters
    of spin-image self-matches, each with -1 where it changes the distances to the
    anchors around a vertex by more than ``SELF_RESIDUAL`` ("no partner"), the one that
    maps the most vertices among those whose images look like their vertices (median
    likeness rank at most ``SELF_LIKENESS``) and that are not the trivial match, with -1
    where it does not return a vertex to itself as a global map does
    (:func:`~intrinsym.globalmap.globalmap.supported_map`), else -1 everywhere (``run.json``:
    ``self_map``; the stage ``self map``). A map kept ranks first among the symmetries
    (kind "self map", :func:`~intrinsym.extract.extract.mapped_symmetry`) and is the
    dominant one.
    """
    p = resolve_params(params, preset, n_source=n_source, n_target=n_target, seed=seed)
    check_machine(p)
    clock = Clock(progress)
    s = shape if isinstance(shape, Surface) else as_shape(shape)
    clock.lap("load")
    surf = working_surface(s, p)
    clock.lap("prepare")
    ps, pt = sample_pair(surf, surf, p)
    clock.lap("sampling")
    header = {"mode": "detect", "input": str(surf.shape.path), "preset": preset}
    result = solve(sampled(surf, surf, ps, pt, p, True), p, clock, header)
    if not p.self_hypotheses or surf.shape.faces is None:
        return result
    given = unrefined(surf)
    trivial = None
    if result.global_map is not None:
        trivial = fixed_share(result.global_map, given, p.trivial_radius)
        clock.lap("trivial check")
        if trivial <= TRIVIAL_SHARE:
            return result
        result = _trivial_global(result)
    image, stats = self_symmetry_map(result.symmetry_map(), given, p, p.self_hypotheses)
    stats = dataclasses.replace(stats, trivial_global=trivial)
    extraction = result.extraction
    if stats.source != "none" and extraction is not None and result.support is not None:
        # the map kept ranks first in symmetries.json, its row of symmetry_maps.npy the map itself
        kept = mapped_symmetry(image, result.source_point_vertex, result.edges, result.support, extraction.params)
        extraction = dataclasses.replace(extraction, symmetries=[kept, *extraction.symmetries])
    clock.lap("self map")
    info = dataclasses.replace(result.info, seconds=dict(clock.seconds), self_map=stats)
    return dataclasses.replace(result, global_map=image, info=info, extraction=extraction)


def _trivial_global(result: Result) -> Result:
    """``result`` without its global map, which was the trivial match: the global
    symmetry becomes an identity one (kind "identity", no longer global)."""
    assert result.extraction is not None and result.extraction.global_index >= 0
    extraction = result.extraction
    symmetries = list(extraction.symmetries)
    symmetries[extraction.global_index] = dataclasses.replace(symmetries[extraction.global_index], kind="identity")
    extraction = dataclasses.replace(extraction, symmetries=symmetries, global_index=-1)
    info = dataclasses.replace(result.info, global_map=None)
    return dataclasses.replace(result, extraction=extraction, global_map=None, map_distortion=None, info=info)
