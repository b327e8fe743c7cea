"""The stages shared by :func:`~intrinsym.pipeline.detect` and
:func:`~intrinsym.pipeline.match`, from the samples onwards: the pairwise and unary
terms (:func:`pairwise_model`, :func:`unary_model`), BP (:func:`solve_bp`), the identity
decision of ``trivial_weight="auto"`` (:func:`decide_identity`), the extraction
(:func:`extraction_support`, :func:`extract_symmetries`) and the global map, run in
order by :func:`solve`.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass

import numpy as np

from .. import resources
from ..extract.extract import consistency, extract_from_support
from ..extract.reflection import RETURN_RADIUS, reflection
from ..extract.support import SourceGraph, Support
from ..extract.symmetry import Extraction
from ..geodesics import geodesics
from ..globalmap.globalmap import GlobalMap, choose_global_map, local_map_distortion, supported_map
from ..mrf import bp, model
from ..params import NO_PARTNER_WEIGHT, OFFSET_TARGETS, Params
from ..problem import Problem
from ..progress import BPIteration, ProgressCallback, StageDone
from ..result.result import Result
from ..result.runinfo import BPStats, GlobalMapStats, IdentityDecision, PassStats, Resolved, RunInfo, Sizes, versions
from ..unary import unary

log = logging.getLogger("intrinsym")


class Clock:
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


def model_bytes(n_s: int, n_t: int, n_edges: int, itemsize: int, passes: int = 1) -> int:
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


def run_bp(mrf: model.MRF, p: Params, progress: ProgressCallback | None) -> bp.BPResult:
    """BP on ``mrf`` with the schedule, iterations, tolerance, damping, seed, dtype and
    backend of ``p``, each iteration reported to ``progress``."""

    def on_iteration(it: int, change: float) -> None:
        log.debug("bp iteration %d: max message change %.3g", it, change)
        if progress is not None:
            progress(BPIteration(it, change, p.iterations))

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
    is :func:`solve`'s."""
    trivial = self_match and p.remove_trivial and p.trivial_radius > 0
    if weight is None:
        weight = 0.0 if p.trivial_weight == "auto" else float(p.trivial_weight)

    weakened = (
        model.suppress_trivial(phi, near, p.trivial_radius, floor, weight) if trivial and near is not None else phi
    )
    mrf = dataclasses.replace(mrf, unary=weakened.astype(np.float32))
    runs = [run_bp(mrf, p, progress)]
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
        runs.append(run_bp(mrf, p, progress))
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
    problem: Problem, support: Support, spectra: tuple | None, clock: Clock, outcome: BPOutcome, p: Params
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


def solve(problem: Problem, p: Params, clock: Clock, header: dict) -> Result:
    """Stages shared by detect and match, from the samples onwards; ``header`` holds
    :class:`RunInfo`'s mode, inputs and preset."""
    src, tgt, ps, pt, edges = problem.src, problem.tgt, problem.ps, problem.pt, problem.edges
    self_match = problem.self_match
    n_passes = p.passes if p.passes is not None else 1 if self_match else 2
    resources.check_memory(
        model_bytes(len(ps), len(pt), len(edges), np.dtype(p.dtype).itemsize, n_passes), "the model", src.shape.path
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
