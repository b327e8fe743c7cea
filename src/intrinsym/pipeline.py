"""End-to-end detection: shape -> samples -> geodesics -> descriptors -> MRF -> BP ->
extraction -> global map.

:func:`detect` matches a shape to itself (partial intrinsic symmetries); :func:`match`
matches shape A to shape B (the paper's ambiguous two-shape case). Both return a
:class:`~intrinsym.result.result.Result`. The steps between (:func:`pairwise_model`,
:func:`unary_model`, :func:`solve_bp`, :func:`extraction_support`,
:func:`extract_symmetries`, :func:`intrinsym.globalmap.globalmap.choose_global_map`) can run
alone: they take the sampled problem (:class:`intrinsym.problem.Problem`, from
:func:`intrinsym.problem.sampled`) or arrays, and return arrays.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import resources
from .errors import ParameterError
from .extract.extract import consistency, extract_from_support, mapped_symmetry
from .extract.reflection import RETURN_RADIUS, reflection
from .extract.support import SourceGraph, Support
from .extract.symmetry import Extraction
from .geodesics import geodesics
from .globalmap.globalmap import GlobalMap, choose_global_map, local_map_distortion, supported_map
from .globalmap.part_chain import part_vertex_map
from .globalmap.part_map import choose_part_map
from .globalmap.self_hypothesis import TRIVIAL_SHARE, fixed_share, self_symmetry_map
from .globalmap.vertex_maps import inverse_vertex_map
from .mesh.shape import Shape, surface_area, vertex_areas
from .mrf import bp, model
from .params import NO_PARTNER_WEIGHT, OFFSET_TARGETS, PARTIAL_AREA, WORK_PER_SAMPLE, Params, make_params
from .problem import Problem, sampled
from .progress import BPIteration, ProgressCallback, StageDone
from .result.result import Result
from .result.runinfo import BPStats, GlobalMapStats, IdentityDecision, PassStats, Resolved, RunInfo, Sizes, versions
from .surface import ShapeLike, Surface, as_shape, prepare_pair, sample, serves
from .surface import prepare as prepare_surface
from .unary import unary

log = logging.getLogger("intrinsym")


class _Clock:
    """Seconds per named stage, reported to the log and the progress callback."""

    def __init__(self, progress: ProgressCallback | None) -> None:
        self.seconds: dict[str, float] = {}
        self.progress = progress
        self._t = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + now - self._t
        self._t = now
        log.info("%s: %.2f s", stage, self.seconds[stage])
        if self.progress is not None:
            self.progress(StageDone(stage, self.seconds[stage]))


def _model_bytes(n_s: int, n_t: int, n_edges: int, itemsize: int, passes: int = 1) -> int:
    """Rough peak of the arrays sized by |Ps| x |Pt| and |E| x |Pt|."""
    return (6 + 2 * (passes - 1)) * n_s * n_t * 4 + 2 * n_edges * n_t * itemsize


@dataclass(frozen=True)
class Pairwise:
    """The pairwise term (Eq. 6) in normalised units.

    Attributes
    ----------
    lam : float
        lambda of Eq. 6.
    delta : float
        Half-width of the ring where psi > rho^2 (:func:`intrinsym.mrf.model.truncation_width`).
    targets : SparseDistances
        Target-to-target geodesics out to the longest edge plus ``delta`` (what the exact
        message needs), or ``pass_radius`` when further passes need more.
    """

    lam: float
    delta: float
    targets: geodesics.SparseDistances


def pairwise_model(problem: Problem, p: Params, n_passes: int) -> Pairwise:
    """lambda from ``p.tolerance`` target spacings (or ``p.lam``) and the target rings."""
    if p.lam is not None:
        lam = p.lam * problem.src.scale**2
    else:
        lam = model.lambda_for_tolerance(p.tolerance * problem.t_spacing, p.rho)
    delta = model.truncation_width(lam, p.rho)
    ring = float(problem.edge_length.max() + delta)
    radius = max(ring, p.pass_radius) if n_passes > 1 else ring
    return Pairwise(lam, delta, geodesics.local_distances(problem.tgt.graph, problem.pt, radius))


def unary_model(problem: Problem, p: Params) -> tuple[np.ndarray, float, np.ndarray | None, tuple | None]:
    """The unary potentials before the trivial match is weakened.

    Returns
    -------
    unary : (S, T) float64
    floor : float
        Its smallest possible value.
    near : (S, T) float64 or None
        Self-matching: geodesic distances from the source samples to the targets, inf
        beyond what the calibration and the trivial match need (one Dijkstra per sample
        serves both).
    spectra : pair of (eigenvalues, eigenvectors) or None
        Of source and target (:func:`intrinsym.unary.unary.spectra`).
    """
    src, tgt, ps, pt, t_spacing = problem.src, problem.tgt, problem.ps, problem.pt, problem.t_spacing
    spectra = unary.spectra(src, tgt, p, problem.self_match)
    trivial = problem.self_match and p.remove_trivial and p.trivial_radius > 0
    reach = max(
        (OFFSET_TARGETS + 2) * t_spacing if unary.offset_calibrated(p) else 0.0, p.trivial_radius if trivial else 0.0
    )
    near = unary.near_targets(src, ps, pt, reach) if problem.self_match and reach > 0 else None
    phi, floor = unary.unary_potentials(src, tgt, ps, pt, p, spectra, t_spacing, near)
    return phi, floor, near, spectra


@dataclass(frozen=True)
class BPOutcome:
    """What :func:`solve_bp` gives back.

    Attributes
    ----------
    unary : (S, T) float32
        The first pass's unary (trivial match weakened as decided).
    marginals : (S, T) float32
        The first pass's marginals.
    passes : list of ((S, T), (S, T)) float32 pairs
        Marginals and unary of every further pass.
    runs : list of bp.BPResult
        One per pass.
    identity : IdentityDecision or None
    """

    unary: np.ndarray
    marginals: np.ndarray
    passes: list[tuple[np.ndarray, np.ndarray]]
    runs: list[bp.BPResult]
    identity: IdentityDecision | None


def solve_bp(
    mrf: model.MRF,
    phi: np.ndarray,
    floor: float,
    near: np.ndarray | None,
    p: Params,
    self_match: bool,
    n_passes: int,
    progress: ProgressCallback | None,
    weight: float | None = None,
) -> BPOutcome:
    """BP on the MRF (``mrf.unary`` is replaced by ``phi`` with the trivial match
    weakened to ``weight``, default ``p.trivial_weight``, 0 for "auto"), then the
    further passes. The identity decision of "auto" (BP again at ``NO_PARTNER_WEIGHT``)
    is :func:`_solve`'s."""
    trivial = self_match and p.remove_trivial and p.trivial_radius > 0
    if weight is None:
        weight = 0.0 if p.trivial_weight == "auto" else float(p.trivial_weight)

    def on_iteration(it: int, change: float) -> None:
        log.debug("bp iteration %d: max message change %.3g", it, change)
        if progress is not None:
            progress(BPIteration(it, change, p.iterations))

    def run(mrf: model.MRF) -> bp.BPResult:
        return bp.belief_propagation(
            mrf,
            p.schedule,
            p.iterations,
            p.bp_tol,
            p.damping,
            p.seed,
            np.dtype(p.dtype).type,
            on_iteration,
            backend=p.backend,
        )

    weakened = (
        model.suppress_trivial(phi, near, p.trivial_radius, floor, weight) if trivial and near is not None else phi
    )
    mrf = dataclasses.replace(mrf, unary=weakened.astype(np.float32))
    runs = [run(mrf)]
    first_unary = mrf.unary
    marginals = runs[0].marginals.astype(np.float32)
    passes: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(1, n_passes):
        # Result.passes derives these unaries again from the stored marginals
        mrf = dataclasses.replace(
            mrf,
            unary=model.suppress_peaks(
                mrf.unary, (passes[-1][0] if passes else marginals), mrf.targets, p.pass_radius, floor
            ),
        )
        runs.append(run(mrf))
        passes.append((runs[-1].marginals.astype(np.float32), mrf.unary))
    return BPOutcome(first_unary, marginals, passes, runs, IdentityDecision(weight) if trivial else None)


def extraction_support(problem: Problem, pair: Pairwise) -> Support:
    """The extraction's support: Voronoi cells of the samples and the target geodesics."""
    src, tgt = problem.src, problem.tgt
    return Support(
        edge_length=problem.edge_length,
        targets=pair.targets,
        vertex_source=geodesics.voronoi_cells(src.graph, problem.ps)[src.vertex_map],
        vertex_target=geodesics.voronoi_cells(tgt.graph, problem.pt)[tgt.vertex_map],
        self_match=problem.self_match,
        source_mesh_vertices=src.input_vertices,
        target_mesh_vertices=tgt.input_vertices,
    )


def extract_symmetries(problem: Problem, support: Support, outcome: BPOutcome, p: Params) -> Extraction:
    """The symmetries of all passes of a BP outcome."""
    no_partner = outcome.identity is not None and outcome.identity.weight > 0
    return extract_from_support(
        outcome.marginals,
        problem.edges,
        support,
        problem.source_points,
        problem.target_points,
        p.extraction(no_partner),
        unary=outcome.unary,
        passes=outcome.passes,
    )


def decide_identity(problem: Problem, pair: Pairwise, outcome: BPOutcome, p: Params) -> IdentityDecision:
    """The decision of ``trivial_weight="auto"`` on an identity-removed BP outcome: the
    weight the trivial match gets (0: a global symmetry, ``NO_PARTNER_WEIGHT``: partial).

    With the identity removed every row puts its mass somewhere, and on a shape without a
    global symmetry BP invents a self-map that keeps short distances only roughly; a true,
    posed symmetry's argmax keeps nearly all of them (within ``d_error`` or the target
    spacing ``t_spacing``). Where the unary is weak (strongly posed shapes) it keeps
    fewer, but a reflection's argmax still acts as one at most samples (its own inverse,
    the surface's orientation reversed: :func:`intrinsym.extract.reflection.reflection`), which
    an invented self-map does not: either test makes the symmetry global. Self-matching:
    both sample sets lie on ``problem.src``.
    """
    image = outcome.marginals.argmax(axis=1)
    graph = SourceGraph.from_edges(problem.edges, problem.edge_length, len(outcome.marginals))
    kept = consistency(image, graph, pair.targets, max(p.d_error, problem.t_spacing))
    normals, ps, pt = problem.src.normals, problem.ps, problem.pt
    acts = reflection(
        image, problem.edges, problem.source_points, problem.target_points, normals[ps], normals[pt], RETURN_RADIUS
    )
    partial = kept < p.isometry_threshold and acts < p.reflection_threshold
    return IdentityDecision(
        NO_PARTNER_WEIGHT if partial else 0.0,
        kept,
        p.isometry_threshold,
        outcome.runs[0].iterations if partial else None,
        acts,
        p.reflection_threshold,
    )


def _bp_stats(runs: list[bp.BPResult]) -> BPStats:
    res = runs[0]
    return BPStats(
        backend=res.backend,
        schedule=res.schedule,
        iterations=res.iterations,
        converged=res.converged,
        max_change=res.max_change,
        history=tuple(res.history),
        seconds_per_iteration=float(np.mean(res.seconds)),
        setup_seconds=res.setup_seconds,
        message_updates=int(sum(res.updates)),
        passes=tuple(PassStats(r.iterations, r.converged, r.max_change) for r in runs[1:]),
    )


def _global_map(
    problem: Problem, support: Support, spectra: tuple | None, clock: _Clock, outcome: BPOutcome, p: Params
) -> tuple[Extraction, GlobalMap | None, np.ndarray | None]:
    """The symmetries of a BP outcome, and (self-matching, when one is global) the global
    map :func:`choose_global_map` chooses with its local distortion."""
    extraction = extract_symmetries(problem, support, outcome, p)
    clock.lap("extract")
    if not problem.self_match or extraction.global_symmetry is None:
        return extraction, None, None
    src, tgt = problem.src, problem.tgt
    fit = (
        problem.edges,
        src.to_input(problem.source_points),
        tgt.to_input(problem.target_points),
        problem.target_vertex,
    )
    chosen = choose_global_map(
        src,
        problem.ps,
        problem.pt,
        problem.source_vertex,
        outcome.marginals,
        extraction.global_symmetry,
        support,
        None if spectra is None else spectra[0],
        fit,
        problem.t_spacing,
        p,
        device=outcome.runs[0].backend,  # the GPU that ran BP runs the dense searches
    )
    map_distortion = local_map_distortion(src, chosen.vertex_map)
    chosen = dataclasses.replace(chosen, vertex_map=supported_map(chosen.vertex_map, src.input_vertices, src.scale))
    clock.lap("global_map")
    return extraction, chosen, map_distortion


def _solve(problem: Problem, p: Params, clock: _Clock, header: dict) -> Result:
    """Stages shared by detect and match, from the samples onwards; ``header`` holds
    :class:`RunInfo`'s mode, inputs and preset."""
    src, tgt, ps, pt, edges = problem.src, problem.tgt, problem.ps, problem.pt, problem.edges
    self_match = problem.self_match
    n_passes = p.passes if p.passes is not None else 1 if self_match else 2
    resources.check_memory(
        _model_bytes(len(ps), len(pt), len(edges), np.dtype(p.dtype).itemsize, n_passes), "the model", src.shape.path
    )
    pair = pairwise_model(problem, p, n_passes)
    clock.lap("geodesics")
    phi, floor, near, spectra = unary_model(problem, p)
    clock.lap("descriptors")
    mrf = model.MRF(phi.astype(np.float32), edges, problem.edge_length, pair.targets, pair.lam, p.rho)
    clock.lap("unary")
    outcome = solve_bp(mrf, phi, floor, near, p, self_match, n_passes, clock.progress)
    unsure = False
    if outcome.identity is not None and p.trivial_weight == "auto":
        identity = decide_identity(problem, pair, outcome, p)
        if identity.weight > 0:
            outcome = solve_bp(mrf, phi, floor, near, p, self_match, n_passes, clock.progress, NO_PARTNER_WEIGHT)
        outcome = dataclasses.replace(outcome, identity=identity)
        unsure = identity.weight == 0 and identity.isometry is not None and identity.isometry < p.isometry_threshold
    clock.lap("bp")
    support = extraction_support(problem, pair)
    extraction, chosen, map_distortion = _global_map(problem, support, spectra, clock, outcome, p)
    if unsure and map_distortion is not None and p.unsure_radius > 1:
        # The global symmetry rests on the reflection test alone: a slide of the identity
        # just past the trivial radius can pass it too. BP again with a wider radius, and
        # keep the more isometric global map (the model's own premise).
        wider = dataclasses.replace(p, trivial_radius=p.trivial_radius * p.unsure_radius)
        near_wider = unary.near_targets(src, ps, pt, wider.trivial_radius)
        second = solve_bp(mrf, phi, floor, near_wider, wider, self_match, n_passes, clock.progress)
        decision = decide_identity(problem, pair, second, wider)
        clock.lap("bp")
        now = float(np.nanmean(map_distortion))
        then: float | None = None
        kept = False
        if decision.weight == 0:
            found = _global_map(problem, support, spectra, clock, second, wider)
            if found[2] is not None:
                then = float(np.nanmean(found[2]))
                kept = then < now
                if kept:
                    outcome, (extraction, chosen, map_distortion) = second, found
        record = dataclasses.replace(
            decision if kept else identity,
            wider_radius=wider.trivial_radius,
            distortion=now,
            wider_distortion=then,
            wider_kept=kept,
        )
        outcome = dataclasses.replace(outcome, identity=record)
    sizes = Sizes(
        source=len(ps),
        target=len(pt),
        edges=len(edges),
        directed_edges=2 * len(edges),
        max_degree=int(np.bincount(edges.ravel(), minlength=len(ps)).max()),
        target_distance_entries=len(pair.targets.dist),
        source_working_vertices=len(src.shape.vertices),
        target_working_vertices=len(tgt.shape.vertices),
    )
    resolved = Resolved(
        lambda_normalised=pair.lam,
        lambda_input_units=pair.lam / src.scale**2,
        delta=pair.delta,
        target_spacing=problem.t_spacing,
        target_radius=pair.targets.radius,
        unary_floor=floor,
        scale=src.scale,
    )
    info = RunInfo(
        **header,
        sizes=sizes,
        resolved=resolved,
        seconds=clock.seconds,
        bp=_bp_stats(outcome.runs),
        identity=outcome.identity,
        global_map=None
        if chosen is None
        else GlobalMapStats(chosen.source, chosen.mass, chosen.masses, chosen.refined, chosen.smoothed, chosen.carried),
        versions=versions(),
    )
    return Result(
        source_points=src.to_input(problem.source_points),
        target_points=tgt.to_input(problem.target_points),
        source_point_vertex=problem.source_vertex,
        target_point_vertex=problem.target_vertex,
        edges=edges.astype(np.int64),
        unary=outcome.unary,
        marginals=outcome.marginals,
        params=p,
        info=info,
        support=support,
        extraction=extraction,
        global_map=None if chosen is None else chosen.vertex_map,
        pass_marginals=np.stack([m for m, _ in outcome.passes]) if outcome.passes else None,
        map_distortion=map_distortion,
    )


def resolve_params(params: Params | None, preset: str, **common: Any) -> Params:
    """``params`` (or the preset's) with the common keywords that are not None applied."""
    if params is not None and preset != "default":
        raise ParameterError("give params or a preset, not both")
    base = params if params is not None else make_params(preset)
    return dataclasses.replace(base, **{k: v for k, v in common.items() if v is not None})


def check_machine(p: Params) -> None:
    """Raise :class:`ParameterError` when this machine cannot run ``p`` (a GPU backend
    without a GPU, or with a schedule it does not run)."""
    if p.backend == "gpu":
        try:
            bp.resolve_backend(p.backend, p.schedule)
        except ValueError as err:
            raise ParameterError(str(err)) from None


def _min_vertices(p: Params) -> int:
    return WORK_PER_SAMPLE * max(p.n_source or 0, p.n_target or 0)


def sample_pair(src: Surface, tgt: Surface, p: Params) -> tuple[np.ndarray, np.ndarray]:
    """Working vertices of the source samples (on ``src``, seed ``p.seed + 1``) and of the
    target samples (on ``tgt``, seed ``p.seed``): those of a run with parameters ``p``."""
    return sample(src, p.n_source, p.source_spacing, p.seed + 1), sample(tgt, p.n_target, p.target_spacing, p.seed)


def prepare(
    shape: ShapeLike,
    params: Params | None = None,
    *,
    n_source: int | None = None,
    n_target: int | None = None,
    preset: str = "default",
) -> Surface:
    """The working surface of a shape for :func:`detect`, to reuse across runs.

    Cleaned (duplicate vertices merged; degenerate and duplicate faces and unreferenced
    vertices dropped), centred, normalised to unit surface area, midpoint-subdivided
    while it has fewer than ``WORK_PER_SAMPLE max(n_source, n_target)`` vertices (a mesh; a point cloud
    is never subdivided), with its geodesic graph and normals: what :func:`detect` does
    before sampling. ``detect(prepare(shape, p), p)`` equals ``detect(shape, p)`` exactly,
    so a parameter sweep prepares once; the surface also keeps the Laplace-Beltrami
    eigenpairs its first detect solves (:meth:`intrinsym.Surface.eigenpairs`), for
    the detects after it with the same ``eigenpairs`` and ``eigen_coarse``.

    Parameters
    ----------
    shape : path, Shape, (vertices, faces) tuple, (N, 3) array or trimesh object
        As in :func:`detect`.
    params : Params, optional
        The parameters of the detects it is for (default: the preset's); only the sample
        counts matter: they set the working size.
    n_source, n_target : int, optional
        Override the fields of the same names.
    preset : {"default", "paper"}
        The parameters when ``params`` is not given.

    Returns
    -------
    Surface
        :func:`detect` takes it in place of the shape with any parameters whose sample
        counts ask for the same working size (any counts when no subdivision was needed);
        with others it raises :class:`~intrinsym.errors.ParameterError` rather than
        prepare again.
    """
    p = resolve_params(params, preset, n_source=n_source, n_target=n_target)
    return prepare_surface(as_shape(shape), _min_vertices(p))


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
    likeness rank at most ``SELF_LIKENESS``) and that are not the trivial match, else -1
    everywhere (``run.json``:
    ``self_map``; the stage ``self map``). A map kept ranks first among the symmetries
    (kind "self map", :func:`~intrinsym.extract.extract.mapped_symmetry`) and is the
    dominant one.
    """
    p = resolve_params(params, preset, n_source=n_source, n_target=n_target, seed=seed)
    check_machine(p)
    clock = _Clock(progress)
    if isinstance(shape, Surface):
        surf = shape
        if not serves(surf, _min_vertices(p)):
            raise ParameterError(
                f"the surface was prepared for a working size of {surf.min_vertices} vertices (it has "
                f"{len(surf.shape.vertices)}); n_source={p.n_source}, n_target={p.n_target} need "
                f"{_min_vertices(p)}: prepare it with these parameters, intrinsym.prepare(shape, params)"
            )
        clock.lap("load")
    else:
        s = as_shape(shape)
        clock.lap("load")
        surf = prepare_surface(s, _min_vertices(p))
    clock.lap("prepare")
    ps, pt = sample_pair(surf, surf, p)
    clock.lap("sampling")
    header = {"mode": "detect", "input": str(surf.shape.path), "preset": preset}
    result = _solve(sampled(surf, surf, ps, pt, p, True), p, clock, header)
    if not p.self_hypotheses or surf.shape.faces is None:
        return result
    # a Surface given keeps only its working mesh: the hypotheses are solved on that
    given = surf if isinstance(shape, Surface) or serves(surf, 0) else prepare_surface(s, 0)
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


def match(
    a: ShapeLike,
    b: ShapeLike,
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
    the part keeps its size, and the unary is ``params.partial_unary`` (the result's
    ``params.unary`` says which ran; a part's Laplace-Beltrami spectrum, and so its WKS,
    is not the whole's). Otherwise each is normalised to unit area, so near-isometric
    frames of one object match whatever their units (``params.match_scale`` decides).
    Parameters as in :func:`detect`; the trivial match does not apply.

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
    polished, where that keeps more of them than the map kept so far (``run.json``:
    ``part_map``; the stage ``part map``, 9-22 s on the SHREC'16 shapes on a 2-core
    machine). The share of A's short distances the
    kept map keeps is the score of its confidence
    (:meth:`~intrinsym.result.result.Result.symmetry_confidence`).

    When the target B is the part (A the whole), every source sample still takes a label,
    so A's vertices cut away on B would get an image too. The result's vertex map
    (``global_map``, :meth:`~intrinsym.result.result.Result.symmetry_map`) is then the
    inverse of B's own match to A, that of ``match(b, a)``
    (:func:`~intrinsym.globalmap.vertex_maps.inverse_vertex_map`): -1 ("no match") on
    the vertices of A that B's image does not cover (B's extraction's map, not the partial
    functional map: see :func:`invert_part_match`). The marginals, the extraction and the
    modes stay those of A to B, whose labels on B lie as densely as on a whole
    (:func:`part_target_params`: ``n_target`` times B's share of A's area); the second
    solve costs about as much as the first (``run.json``: ``target_part``, the stage
    ``reverse match``).

    ``target_symmetry`` is B's own symmetry map, (N_b,) int (-1 where none) or a
    ``detect`` result of B: the result keeps it, and its second answer
    (:func:`~intrinsym.result.modes.two_modes`) is that symmetry applied after its map.
    A ``detect`` of B takes about as long as a match; run it once and give it to every
    match onto B.

    Raises
    ------
    ParameterError
        ``target_symmetry`` not a map of B's vertices.
    """
    p = resolve_params(params, preset, n_source=n_source, n_target=n_target, seed=seed)
    check_machine(p)
    clock = _Clock(progress)
    sa, sb = as_shape(a), as_shape(b)
    symmetry = None if target_symmetry is None else checked_symmetry(target_symmetry, len(sb.vertices))
    clock.lap("load")
    surf_a, surf_b = prepare_pair(sa, sb, _min_vertices(p), p.match_scale)
    area_a, area_b = surface_area(surf_a.shape), surface_area(surf_b.shape)
    part = min(area_a, area_b) < PARTIAL_AREA
    if part:
        p = dataclasses.replace(p, unary=p.partial_unary)
    clock.lap("prepare")
    target_part = part and area_b < area_a
    p_ab = part_target_params(p, area_b / area_a) if target_part else p
    ps, pt = sample_pair(surf_a, surf_b, p_ab)
    clock.lap("sampling")
    problem = sampled(surf_a, surf_b, ps, pt, p_ab, False, area_b if target_part else 1.0)
    result = _solve(problem, p_ab, clock, _match_header(sa, sb, preset, part))
    result = dataclasses.replace(result, target_symmetry=symmetry)
    if not part:
        return result
    if not target_part:
        result = _with_part_map(result, surf_a, surf_b, (sa, sb), p)
        clock.lap("part map")
        return dataclasses.replace(result, info=dataclasses.replace(result.info, seconds=dict(clock.seconds)))
    # The target is the part: every source sample takes a label, so the source vertices
    # cut away on the target would get one too. The part's own match to the whole (what
    # match(b, a) computes) covers those that have a counterpart; the rest get -1.
    back_header = _match_header(sb, sa, preset, part)
    back = _solve(sampled(surf_b, surf_a, *sample_pair(surf_b, surf_a, p), p, False), p, _Clock(None), back_header)
    image = invert_part_match(back, sb, sa)
    _, stats = choose_part_map(back.extraction_map(), surf_b, surf_a)
    clock.lap("reverse match")
    info = dataclasses.replace(result.info, seconds=dict(clock.seconds), target_part=True, part_map=stats)
    return dataclasses.replace(result, global_map=image, info=info)


def part_target_params(p: Params, share: float) -> Params:
    """The parameters of a match whose target is a part with ``share`` of the source's
    area: ``n_target`` scaled by that share, so that the part's labels lie as densely as
    on a whole (``target_spacing``, when given, already fixes the density).

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


def _with_part_map(result: Result, part: Surface, whole: Surface, shapes: tuple[Shape, Shape], p: Params) -> Result:
    """A part's match to its whole with the vertex map :func:`part_vertex_map` keeps
    (``global_map``, ``info.part_map``); with ``p.part_fmap`` off or a point cloud, the
    extraction's map as it is, measured. The partial functional map and the
    refinement are solved on the two meshes as given (``shapes``, the part and the whole,
    prepared again without refinement when either was refined)."""
    if not (p.part_fmap and part.shape.faces is not None and whole.shape.faces is not None):
        _, stats = choose_part_map(result.symmetry_map(), part, whole)
        return dataclasses.replace(result, info=dataclasses.replace(result.info, part_map=stats))
    given = (part, whole) if serves(part, 0) and serves(whole, 0) else prepare_pair(*shapes, 0, p.match_scale)
    image, stats = part_vertex_map(result.symmetry_map(), part, whole, given, p)
    info = dataclasses.replace(result.info, part_map=stats)
    return dataclasses.replace(result, global_map=result.global_map if image is None else image, info=info)


def _match_header(a: Shape, b: Shape, preset: str, part: bool) -> dict:
    """:class:`RunInfo`'s mode, inputs and preset of a match of ``a`` to ``b``."""
    return {"mode": "match", "input": str(a.path), "target_input": str(b.path), "preset": preset, "part": part}


#: The counterpart of a part on its whole lies within this many of the part's sample
#: spacings of the part's images (:func:`invert_part_match`): a map that collapses the
#: part onto a small region leaves the rest of the whole unmatched. Fewer leave more of
#: the part's counterpart unmatched, more cover more of what was cut away: on the 125
#: SHREC'16 shapes 1.5 leaves 0.920 of the cut-away vertices unmatched (every class
#: >= 0.882), 2 0.897 (michael 0.861), 3 0.849 (docs/results.md's reach table).
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
    # pairs, against 0.920 (and matched 0.618 of the kept ones, against 0.348)
    return inverse_vertex_map(
        back.extraction_map(),
        sw.vertices,
        vertex_areas(sw),
        surface_area(sp),
        spacings * spacing,
        back.source_point_vertex,
    )


def extract_result(result: Result) -> Extraction:
    """Run the extraction again on a loaded result (its stored parameters)."""
    if result.support is None:
        raise ValueError("the result has no support (geodesics) to extract from")
    return extract_from_support(
        result.marginals,
        result.edges,
        result.support,
        result.source_points,
        result.target_points,
        result.extraction_params(),
        unary=result.unary,
        passes=result.passes,
    )
