"""Shape A matched to shape B (the paper's ambiguous two-shape case): :func:`match`,
and a part's match to its whole inverted into the whole's map onto the part
(:func:`invert_part_match`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from .._threads import one_blas_thread
from ..errors import ParameterError
from ..globalmap.part_chain import part_vertex_map
from ..globalmap.part_map import choose_part_map
from ..globalmap.vertex_maps import inverse_vertex_map
from ..mesh.shape import Shape, surface_area, vertex_areas
from ..mrf import model
from ..params import PARTIAL_AREA, Params
from ..problem import sampled
from ..progress import ProgressCallback
from ..result.modes import two_modes
from ..result.result import Result
from ..result.runinfo import PassStats
from ..surface import ShapeLike, Surface, as_shape, common_unit, in_unit, unrefined
from .inputs import check_machine, resolve_params, sample_pair, working_surface
from .stages import Clock, run_bp, solve


@one_blas_thread
def match(
    a: ShapeLike | Surface,
    b: ShapeLike | Surface,
    params: Params | None = None,
    *,
    n_source: int | None = None,
    n_target: int | None = None,
    seed: int | None = None,
    preset: str = "default",
    progress: ProgressCallback | None = None,
    target_symmetry: np.ndarray | Result | None = None,
) -> Result:
    """Marginals of the two-shape MRF: source samples on A, target labels on B.

    When the smaller shape has less than ``PARTIAL_AREA`` of the larger's area it is taken
    for a part of it: both are measured in one unit, sqrt(area) of the larger, so that
    the part keeps its size, the unary is ``params.partial_unary`` calibrated as
    ``params.partial_calibration`` says, and ``params.part_targets`` of ``n_target`` are
    sampled (:func:`part_params`; the result's ``params`` say which ran; a part's
    Laplace-Beltrami spectrum, and so its WKS, is not the whole's). Otherwise each is
    normalised to unit area, so near-isometric frames of one object match whatever their
    units (``params.match_scale`` decides).
    Parameters as in :func:`detect`; the trivial match does not apply. Either shape may
    be a :class:`~intrinsym.surface.Surface` from :func:`prepare`, not prepared again:
    a whole matched to many parts is prepared once, and its eigenpairs and chord graph
    serve every part's map (the result is the one of the shape itself).

    When the source A is the part (meshes, ``params.part_fmap``), its vertex map is the
    extraction's or a partial functional map's
    (:func:`~intrinsym.globalmap.part_map.choose_part_map`), whichever changes fewer of
    A's geodesic distances, refined by ZoomOut where that keeps more of them
    (:func:`~intrinsym.globalmap.part_map.refine_part_map`), then trilaterated from
    the anchors on which it keeps A's distances where that keeps more of them still
    (:func:`~intrinsym.globalmap.part_trilateration.trilaterated_maps`) and refined by
    ZoomOut once more (:func:`~intrinsym.globalmap.part_map.with_polish`), and replaced
    by the map located from a consistent cluster of spin-image matches
    (:func:`~intrinsym.globalmap.part_hypothesis.hypothesis_maps`), trilaterated and
    polished, where that keeps more of them than the map kept so far, and last by the
    blend of those maps vertex by vertex, each vertex where the candidate least distorted
    around it sends it (:func:`~intrinsym.globalmap.part_blend.blended_map`), trilaterated
    and polished, where that keeps more of them still (``run.json``: ``part_map``; the
    stage ``part map``, 9-22 s on the SHREC'16 shapes on a 2-core machine). The share
    of A's short distances the kept map keeps is the score of its confidence
    (:meth:`~intrinsym.result.result.Result.symmetry_confidence`).

    When the target B is the part (A the whole), every source sample still takes a label,
    so A's vertices cut away on B would get an image too. The result's vertex map
    (``global_map``, :meth:`~intrinsym.result.result.Result.symmetry_map`) is then the
    inverse of B's own match to A, that of ``match(b, a)``
    (:func:`~intrinsym.globalmap.vertex_maps.inverse_vertex_map`): -1 ("no match") on
    the vertices of A that B's image does not cover (B's extraction's map, not the partial
    functional map: see :func:`invert_part_match`). The marginals, the extraction and the
    modes stay those of A to B, whose labels on B lie as densely as B's own match's on A
    (:func:`part_target_params`: ``part_targets`` of ``n_target`` times B's share of A's
    area); the second
    solve costs about as much as the first (``run.json``: ``target_part``, the stage
    ``reverse match``).

    ``target_symmetry`` is B's own symmetry map, (N_b,) int (-1 where none) or a
    ``detect`` result of B: the result keeps it, and its second answer
    (:func:`~intrinsym.result.modes.two_modes`) is that symmetry applied after its map.
    A ``detect`` of B takes about as long as a match; run it once and give it to every
    match onto B.

    Every match ends with BP given each of its two modes (``mode_marginals``, the stage
    ``mode marginals``: two more BP runs, see :func:`_with_mode_marginals`);
    :meth:`~intrinsym.result.result.Result.mixed_marginals` mixes them by the modes'
    confidences.

    Raises
    ------
    ParameterError
        ``target_symmetry`` not a map of B's vertices.
    """
    p = resolve_params(params, preset, n_source=n_source, n_target=n_target, seed=seed)
    check_machine(p)
    clock = Clock(progress)
    sa, sb = as_shape(a), as_shape(b)
    symmetry = None if target_symmetry is None else checked_symmetry(target_symmetry, len(sb.vertices))
    clock.lap("load")
    first = working_surface(a if isinstance(a, Surface) else sa, p)
    second = working_surface(b if isinstance(b, Surface) else sb, p)
    unit = common_unit(first, second, p.match_scale)
    surf_a, surf_b = in_unit(first, unit), in_unit(second, unit)
    area_a, area_b = surface_area(surf_a.shape), surface_area(surf_b.shape)
    part = min(area_a, area_b) < PARTIAL_AREA
    if part:
        p = part_params(p)
    clock.lap("prepare")
    target_part = part and area_b < area_a
    p_ab = part_target_params(p, area_b / area_a) if target_part else p
    ps, pt = sample_pair(surf_a, surf_b, p_ab)
    clock.lap("sampling")
    problem = sampled(surf_a, surf_b, ps, pt, p_ab, False, area_b if target_part else 1.0)
    result = solve(problem, p_ab, clock, _match_header(sa, sb, preset, part))
    result = dataclasses.replace(result, target_symmetry=symmetry)
    if not part:
        return _with_mode_marginals(result, clock)
    if not target_part:
        result = _with_part_map(result, surf_a, surf_b, unit, p)
        clock.lap("part map")
        return _with_mode_marginals(result, clock)
    # The target is the part: every source sample takes a label, so the source vertices
    # cut away on the target would get one too. The part's own match to the whole (what
    # match(b, a) computes) covers those that have a counterpart; the rest get -1.
    back_header = _match_header(sb, sa, preset, part)
    back = solve(sampled(surf_b, surf_a, *sample_pair(surf_b, surf_a, p), p, False), p, Clock(None), back_header)
    image = invert_part_match(back, sb, sa)
    _, stats = choose_part_map(back.extraction_map(), surf_b, surf_a)
    clock.lap("reverse match")
    info = dataclasses.replace(result.info, target_part=True, part_map=stats)
    return _with_mode_marginals(dataclasses.replace(result, global_map=image, info=info), clock)


def part_params(p: Params) -> Params:
    """The parameters of a match of a part and its whole: the unary ``partial_unary``
    calibrated as ``partial_calibration`` says, and ``part_targets`` of ``n_target``
    (``target_spacing``, when given, fixes the density instead; never fewer than
    ``calibration_k`` targets)."""
    n_target = p.n_target
    if p.target_spacing is None and n_target is not None:
        # Params already holds calibration_k and 2 at most n_target
        n_target = max(2, p.calibration_k, round(n_target * p.part_targets))
    return dataclasses.replace(p, unary=p.partial_unary, calibration=p.partial_calibration, n_target=n_target)


def part_target_params(p: Params, share: float) -> Params:
    """The parameters of a match whose target is a part with ``share`` of the source's
    area (``p`` those of :func:`part_params`): ``n_target`` scaled by that share, so that
    the part's labels lie as densely as the part's own match's on the whole
    (``target_spacing``, when given, already fixes the density).

    The pairwise term compares a source edge with the target pairs within the edge's
    length plus its truncation, and the source samples lie as far apart as on a whole:
    with all ``n_target`` labels on a part, each target had several times the
    neighbours, a BP iteration cost 2-30 times as much, and BP on cuts_dog_shape_1 took
    108 s against 12 s (side by side; docs/results.md).
    """
    if p.target_spacing is not None or p.n_target is None:
        return p
    return dataclasses.replace(p, n_target=max(1, round(p.n_target * share)))


def checked_symmetry(symmetry: np.ndarray | Result, n_vertices: int) -> np.ndarray:
    """A shape's own symmetry map as (N,) int64 (a ``detect`` result's
    :meth:`~intrinsym.result.result.Result.symmetry_map`), -1 where it has none.

    Raises
    ------
    ParameterError
        Not one integer per vertex in [-1, N).
    """
    vmap = symmetry.symmetry_map() if isinstance(symmetry, Result) else np.asarray(symmetry)
    if vmap.ndim != 1 or len(vmap) != n_vertices or not np.issubdtype(vmap.dtype, np.integer):
        raise ParameterError(
            f"target_symmetry: need one integer per target vertex ({n_vertices}), got {vmap.dtype} {vmap.shape}"
        )
    if len(vmap) and (vmap.min() < -1 or vmap.max() >= n_vertices):
        raise ParameterError(f"target_symmetry: entries must lie in [-1, {n_vertices})")
    return vmap.astype(np.int64)


def _with_part_map(result: Result, part: Surface, whole: Surface, unit: float | None, p: Params) -> Result:
    """A part's match to its whole with the vertex map :func:`part_vertex_map` keeps
    (``global_map``, ``info.part_map``); with ``p.part_fmap`` off or a point cloud, the
    extraction's map as it is, measured. The partial functional map and the
    refinement are solved on the two meshes as given, in their common ``unit``
    (:func:`~intrinsym.surface.unrefined`)."""
    if not (p.part_fmap and part.shape.faces is not None and whole.shape.faces is not None):
        _, stats = choose_part_map(result.symmetry_map(), part, whole)
        return dataclasses.replace(result, info=dataclasses.replace(result.info, part_map=stats))
    given = (unrefined(part, unit), unrefined(whole, unit))
    marginals = (result.marginals, result.source_point_vertex, result.target_point_vertex)
    image, stats = part_vertex_map(result.symmetry_map(), part, whole, given, p, marginals)
    info = dataclasses.replace(result.info, part_map=stats)
    return dataclasses.replace(result, global_map=result.global_map if image is None else image, info=info)


def _with_mode_marginals(result: Result, clock: Clock) -> Result:
    """A match's result with its marginals given each of its two modes
    (``mode_marginals``, ``info.bp.modes``; the stage ``mode marginals``).

    Loopy BP settles on about one mode, and on a part matched to its whole not always on
    a right one where the vertex map is; BP run again on the unary conditioned on each
    mode's sample images (:func:`~intrinsym.mrf.model.condition_on_images`, a Gaussian of
    ``mode_width`` target spacings) gives each mode's marginals, and
    :meth:`~intrinsym.result.result.Result.mixed_marginals` mixes them by the modes'
    confidences.
    """
    p = result.params
    two = two_modes(result)
    mrf = result.mrf()
    width = p.mode_width * result.info.resolved.target_spacing
    floor = result.info.resolved.unary_floor
    marginals, stats = [], []
    for images in two.images:
        if not (images >= 0).any():
            marginals.append(np.asarray(result.marginals, dtype=np.float32))
            continue
        unary = model.condition_on_images(mrf.unary, images, mrf.targets, width, floor)
        run = run_bp(dataclasses.replace(mrf, unary=unary), p, clock.progress)
        marginals.append(run.marginals.astype(np.float32))
        stats.append(PassStats(run.iterations, run.converged, run.max_change))
    clock.lap("mode marginals")
    bp_stats = dataclasses.replace(result.info.bp, modes=tuple(stats))
    info = dataclasses.replace(result.info, bp=bp_stats, seconds=dict(clock.seconds))
    return dataclasses.replace(result, mode_marginals=np.stack(marginals), info=info)


def _match_header(a: Shape, b: Shape, preset: str, part: bool) -> dict:
    """:class:`RunInfo`'s mode, inputs and preset of a match of ``a`` to ``b``."""
    return {"mode": "match", "input": str(a.path), "target_input": str(b.path), "preset": preset, "part": part}


#: The counterpart of a part on its whole lies within this many of the part's sample
#: spacings of the part's images (:func:`invert_part_match`): a map that collapses the
#: part onto a small region leaves the rest of the whole unmatched. Fewer leave more of
#: the part's counterpart unmatched, more cover more of what was cut away: on the 125
#: SHREC'16 shapes 1.5 leaves 0.911 of the cut-away vertices unmatched (every class
#: >= 0.884) and matches 0.640 of the kept ones, 2 0.893 / 0.665, 3 0.873 / 0.690
#: (docs/results.md's reach table).
COVER_SPACINGS = 1.5


def invert_part_match(back: Result, part: ShapeLike, whole: ShapeLike, spacings: float = COVER_SPACINGS) -> np.ndarray:
    """The whole's vertices mapped onto the part, from the part's match to the whole:
    what ``match(whole, part)`` returns as its vertex map.

    Parameters
    ----------
    back : Result
        Of ``match(part, whole)`` (the part's samples, the whole's labels).
    part, whole : path, Shape, (vertices, faces) tuple, (N, 3) array or trimesh object
        Its two inputs.
    spacings : float
        The counterpart's reach from the part's images, in the part's sample spacings
        (the median source-graph edge).

    Returns
    -------
    (N_whole,) int64
        Part vertex of every vertex of the whole, -1 ("no match") where the part has no
        counterpart: ``back``'s extraction's vertex map
        (:meth:`~intrinsym.result.result.Result.extraction_map`) inverted
        (:func:`~intrinsym.globalmap.vertex_maps.inverse_vertex_map`, the counterpart as
        large as the part).
    """
    if back.support is None:
        raise ValueError("the result has no support (geodesics) to measure its sample spacing")
    sp, sw = as_shape(part), as_shape(whole)
    spacing = float(np.median(back.support.edge_length)) * back.info.resolved.scale  # input units
    # The extraction's map even where the part's match kept the partial functional map:
    # inverted, that one left 0.768 of the cut-away vertices unmatched on the 125 SHREC'16
    # pairs, against 0.888 (and matched 0.618 of the kept ones, against 0.639, both at 4,000 labels)
    return inverse_vertex_map(
        back.extraction_map(),
        sw.vertices,
        vertex_areas(sw),
        surface_area(sp),
        spacings * spacing,
        back.source_point_vertex,
    )
