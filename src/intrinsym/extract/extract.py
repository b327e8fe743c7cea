"""Symmetries from marginals: peak tracking and region growing (paper Sec. 5.1), then more.

For one source sample s, :func:`query` thresholds its max-normalised marginal at ``t``,
takes the distinct peaks as seeds, and grows each seed over the source graph: a
neighbour n of a mapped sample m joins, mapped to target t', when t' is a peak of n
(normalised marginal >= t) and ``|d_T(f(m), t') - d_S(m, n)| < d_error``. Every grown
seed is a symmetric part pair (source region -> target region, with the point map).

Beyond the paper, :func:`extract` grows from every source sample and every peak, merges
parts that describe the same map, separates the identity (self-matching only), ranks
the symmetries and picks the dominant global one (:mod:`intrinsym.globalmap.vertex_maps` extends
a symmetry to every input vertex).

Only the geodesics BP already needed are used: the source-graph edge lengths and the
sparse, distance-sorted target-target distances (:class:`~intrinsym.geodesics.geodesics.SparseDistances`,
radius R). A target pair farther apart than R counts as incompatible, so ``d_error``
acts at most up to ``R - d_S(m, n)``. All lengths are in units of sqrt(surface area).

The source graph and the geodesics come as :class:`~intrinsym.extract.support.SourceGraph` and
:class:`~intrinsym.extract.support.Support`; the records (:class:`ExtractParams`, :class:`Symmetry`,
:class:`Extraction`) live in :mod:`intrinsym.extract.symmetry`, the Numba kernels in
:mod:`intrinsym.extract._kernels`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from ..geodesics.geodesics import SparseDistances
from . import _kernels as kernels
from .support import SourceGraph, Support
from .symmetry import Extraction, ExtractParams, Symmetry

__all__ = [
    "ExtractParams",
    "Extraction",
    "Symmetry",
    "complete",
    "consistency",
    "extract",
    "extract_from_support",
    "grow",
    "is_identity",
    "mapped_symmetry",
    "nearest_targets",
    "normalise_rows",
    "peaks",
    "query",
    "query_from_support",
    "refine",
]

#: Two maps describe the same map (:func:`_merge`) when they agree on at least this share of
#: their shared samples and the edges between them.
MERGE_AGREEMENT = 0.8


def normalise_rows(marginals: np.ndarray) -> np.ndarray:
    """(S, T) float32 marginals divided by their row maxima (rows of zeros stay zero)."""
    m = np.asarray(marginals, dtype=np.float32)
    top = m.max(axis=1, keepdims=True)
    return np.divide(m, top, out=np.zeros_like(m), where=top > 0)


def nearest_targets(source_points: np.ndarray, target_points: np.ndarray) -> np.ndarray:
    """(S,) int64: the target sample nearest each source sample (self-matching).

    Euclidean nearest is exact enough here: the two lie about a target spacing apart.
    """
    return cKDTree(target_points).query(source_points)[1].astype(np.int64)


def peaks(row: np.ndarray, targets: SparseDistances, threshold: float, radius: float) -> np.ndarray:
    """Distinct peaks of a marginal row, strongest first.

    Parameters
    ----------
    row : (T,) array
        A marginal (any positive scale; normalised to its maximum here).
    targets : SparseDistances
    threshold : float
        Fraction of the row maximum a peak must reach (paper: t in [0.5, 0.75]).
    radius : float
        Peaks are farther apart than this (capped at ``targets.radius``).

    Returns
    -------
    (k,) int64 target indices.
    """
    r = np.asarray(row, dtype=np.float32)
    r = r / r.max() if r.max() > 0 else r
    cand = np.flatnonzero(r >= threshold)
    cand = cand[np.argsort(-r[cand], kind="stable")]  # here, not in the kernel: Numba's sort compiles slowly
    return kernels.peaks(cand, len(r), targets.indptr, targets.indices, targets.dist, radius)


def grow(
    norm: np.ndarray,
    graph: SourceGraph,
    targets: SparseDistances,
    seed_source: int,
    seed_target: int,
    params: ExtractParams = ExtractParams(),
    self_target: np.ndarray | None = None,
) -> np.ndarray:
    """Region growing of the paper's Sec. 5.1 from one correspondence.

    Parameters
    ----------
    norm : (S, T) float32
        Max-normalised marginals (:func:`normalise_rows`).
    graph : SourceGraph
    targets : SparseDistances
    seed_source, seed_target : int
        The seed pair (a source sample and one of its peaks).
    params : ExtractParams
        Uses the peak threshold t, d_error and identity_radius.
    self_target : (S,) int64, optional
        The target sample at each source sample's own position (self-matching). The
        map then stays on its seed's side of the identity (:func:`is_identity`): on a
        mirror plane identity and mirror coincide, and without this rule the growing
        crosses over to the identity, which the marginals support everywhere.

    Returns
    -------
    (S,) int64
        Image of every source sample under the grown map, -1 outside the region.
    """
    image = np.full(norm.shape[0], -1, dtype=np.int64)
    image[seed_source] = seed_target
    side = (
        -1
        if self_target is None
        else int(is_identity(seed_source, seed_target, targets, self_target, params.identity_radius))
    )
    own = np.full(len(image), -1, dtype=np.int64) if self_target is None else np.asarray(self_target, dtype=np.int64)
    kernels.grow(
        norm,
        graph.ptr,
        graph.neighbour,
        graph.length,
        targets.indptr,
        targets.indices,
        targets.dist,
        np.float32(params.threshold),
        params.d_error,
        1,
        own,
        params.identity_radius,
        side,
        image,
    )
    return image


def complete(
    norm: np.ndarray, graph: SourceGraph, targets: SparseDistances, image: np.ndarray, params: ExtractParams
) -> np.ndarray:
    """Extend a map to the samples its growing could not reach.

    Below the peak threshold and across the identity band (where a mirror maps points
    near themselves), geometry alone decides: an unmapped sample takes the target that
    keeps the geodesic lengths to at least two of its mapped neighbours within
    ``d_error`` (the most such neighbours, then the largest marginal).

    Returns
    -------
    (S,) int64, a completed copy of ``image``.
    """
    out = np.array(image, dtype=np.int64)
    unused = np.full(len(out), -1, dtype=np.int64)
    kernels.grow(
        norm,
        graph.ptr,
        graph.neighbour,
        graph.length,
        targets.indptr,
        targets.indices,
        targets.dist,
        np.float32(0.0),
        params.d_error,
        2,
        unused,
        params.identity_radius,
        -1,
        out,
    )
    return out


def refine(
    graph: SourceGraph,
    targets: SparseDistances,
    image: np.ndarray,
    params: ExtractParams,
    min_neighbours: int = 3,
    passes: int = 3,
) -> np.ndarray:
    """Re-place the samples of a map by the geodesic lengths to their mapped neighbours.

    Region growing accepts any image within ``d_error`` of one neighbour's ring, and the
    removed trivial match leaves samples on a mirror plane no peak at their own (true)
    image, so they settle off the plane; trilateration from the neighbours' images
    finds them (:func:`intrinsym.extract._kernels.refine`). Only samples with at least
    ``min_neighbours`` mapped neighbours move.

    Returns
    -------
    (S,) int64, a refined copy of ``image``.
    """
    out = np.array(image, dtype=np.int64)
    kernels.refine(
        out,
        graph.ptr,
        graph.neighbour,
        graph.length,
        targets.indptr,
        targets.indices,
        targets.dist,
        params.d_error,
        min_neighbours,
        passes,
    )
    return out


def is_identity(
    source: int, target: int, targets: SparseDistances, self_target: np.ndarray | None, radius: float
) -> bool:
    """Whether the correspondence source -> target is trivial: the target lies within
    ``radius`` of the source sample itself (always False without ``self_target``)."""
    if self_target is None:
        return False
    return kernels.find(targets.indptr, targets.indices, targets.dist, self_target[source], target, radius) <= radius


def consistency(image: np.ndarray, graph: SourceGraph, targets: SparseDistances, tolerance: float) -> float:
    """Share of the source edges inside a map whose geodesic length the map keeps.

    Parameters
    ----------
    image : (S,) int64
        Target sample of each source sample, -1 where unmapped.
    graph : SourceGraph
    targets : SparseDistances
        Target-target geodesics; a pair beyond their radius counts as not kept.
    tolerance : float
        An edge (u, v) of length l is kept when |d(image[u], image[v]) - l| < tolerance
        (length units of ``graph`` and ``targets``).

    Returns
    -------
    float in [0, 1]; 1 when no edge has both ends mapped.
    """
    image = np.asarray(image, dtype=np.int64)
    t = targets
    good, bad = kernels.edge_agreement(
        image, image, True, graph.ptr, graph.neighbour, graph.length, t.indptr, t.indices, t.dist, tolerance, 0.0
    )
    return good / (good + bad) if good + bad else 1.0


def _make(
    image: np.ndarray, norm: np.ndarray, graph: SourceGraph, targets: SparseDistances, p: ExtractParams, kind: str
) -> Symmetry:
    """A Symmetry with its score and consistency from a map (S,) int64."""
    src = np.flatnonzero(image >= 0)
    kept = consistency(image, graph, targets, p.d_error)
    score = float(norm[src, image[src]].sum()) / norm.shape[0] * kept
    return Symmetry(src, image[src], score, kept, kind)


def mapped_symmetry(
    vertex_map: np.ndarray, source_vertex: np.ndarray, edges: np.ndarray, support: Support, params: ExtractParams
) -> Symmetry:
    """A dense self-map on the samples: the symmetry record of a map not grown from the
    marginals (``detect``'s partial symmetry map, kind "self map").

    Each source sample whose vertex the map sends somewhere pairs with the target sample
    whose Voronoi cell holds the image vertex. The score is the share of the source
    samples so mapped times the consistency: the marginals do not support such a map (it
    is drawn where they found no global symmetry), so they do not weigh it.

    Parameters
    ----------
    vertex_map : (N_input,) int
        Input vertex of every input vertex, -1 for none.
    source_vertex : (S,) int64
        Input vertex of every source sample.
    edges : (E, 2) int64
        The source graph.
    support : Support
        Of the same run (self-matching: the target samples lie on the same shape).
    params : ExtractParams
        ``d_error`` for the consistency.
    """
    images = np.asarray(vertex_map, dtype=np.int64)[source_vertex]
    cells = support.vertex_target[np.maximum(images, 0)]
    image = np.where((images >= 0) & (cells >= 0), cells, -1)
    graph = SourceGraph.from_edges(edges, support.edge_length, len(image))
    kept = consistency(image, graph, support.targets, params.d_error)
    source = np.flatnonzero(image >= 0)
    return Symmetry(source, image[source], len(source) / max(len(image), 1) * kept, kept, "self map")


def query(
    marginals: np.ndarray,
    graph: SourceGraph,
    targets: SparseDistances,
    source: int,
    params: ExtractParams = ExtractParams(),
    self_target: np.ndarray | None = None,
    unary: np.ndarray | None = None,
    passes: Sequence[tuple[np.ndarray, np.ndarray]] = (),
) -> list[Symmetry]:
    """What is symmetric to one source sample: every part pair grown from its peaks.

    Parameters
    ----------
    marginals : (S, T) array
    graph : SourceGraph
    targets : SparseDistances
    source : int
        The chosen source sample.
    params : ExtractParams
    self_target : (S,) int64, optional
        The target sample at each source sample's own position (self-matching); enables
        the "identity" kind.
    unary : (S, T) array, optional
        With ``params.unary_seeds``, also grow from the peaks of the unary that no part
        grown from the marginals covers, on the unary (see :func:`extract`).
    passes : sequence of ((S, T), (S, T)) array pairs
        Marginals and unary of every later BP pass (see :func:`extract`).

    Returns
    -------
    list of Symmetry
        One per peak, best score (on the marginals) first; each contains ``source``.
    """
    fields = _fields(marginals, unary, passes, params, targets, self_target)
    norm = _score_field(fields, len(passes) + 1)
    found = []
    covered = np.zeros(norm.shape, dtype=np.bool_)
    for field in fields:
        for t in peaks(field[source], targets, params.threshold, params.peak_radius):
            if covered[source, t]:
                continue
            image = grow(field, graph, targets, source, int(t), params, self_target)
            kernels.mark_covered(covered, image, targets.indptr, targets.indices, targets.dist, params.peak_radius)
            kind = "identity" if is_identity(source, t, targets, self_target, params.identity_radius) else "partial"
            found.append(_make(image, norm, graph, targets, params, kind))
    return sorted(found, key=lambda s: -s.score)


def _fields(
    marginals: np.ndarray,
    unary: np.ndarray | None,
    passes: Sequence[tuple[np.ndarray, np.ndarray]],
    p: ExtractParams,
    targets: SparseDistances,
    self_target: np.ndarray | None,
) -> list[np.ndarray]:
    """The row-max-normalised fields to seed and grow from: the marginals of every BP
    pass, then, when ``unary`` is given and ``p.unary_seeds``, the unary of every pass.

    With ``p.no_partner``, a row whose marginals (the largest over the passes) peak on
    the identity is zero in the unary fields: that is BP's answer "no partner", and a
    part grown on the unary must not overrule it. Without it, a peak there is a
    fixed point of the symmetry BP found (a star's hub, a mirror plane).
    """
    fields = [normalise_rows(m) for m in (marginals, *(m for m, _ in passes))]
    if unary is not None and p.unary_seeds:
        home = np.zeros(len(marginals), dtype=bool)
        if self_target is not None and p.no_partner:
            best = _score_field(fields, len(fields)).argmax(axis=1)
            home = np.array(
                [is_identity(s, t, targets, self_target, p.identity_radius) for s, t in enumerate(best)], dtype=bool
            )
        fields += [np.where(home[:, None], np.float32(0), normalise_rows(u)) for u in (unary, *(u for _, u in passes))]
    return fields


def _score_field(fields: list[np.ndarray], n_passes: int) -> np.ndarray:
    """What symmetries are scored on: the max-normalised marginals, the largest over
    the passes (each pass's mode scores on its own pass)."""
    return fields[0] if n_passes == 1 else np.maximum.reduce(fields[:n_passes])


def _merge(
    images: list[np.ndarray],
    graph: SourceGraph,
    targets: SparseDistances,
    p: ExtractParams,
    extra: list[np.ndarray] | None = None,
) -> list[np.ndarray]:
    """Greedy union of maps that describe the same map, in the given order.

    A map joins an earlier group when they agree (on shared samples and across the
    edges between them) at least ``MERGE_AGREEMENT`` of the time; the group keeps its own images where
    both map a sample. Two different symmetries agree only near their common fixed
    points; a lower bar lets noisy parts of other maps into the group.
    The ``extra`` maps come last, and one that agrees with a group of ``images`` is
    dropped rather than merged (gaps are better left to :func:`complete`).
    """
    t = targets
    groups: list[np.ndarray] = []
    n_main = 0
    for i, image in enumerate(images + (extra or [])):
        if i == len(images):
            n_main = len(groups)
        for j, group in enumerate(groups):
            good, bad = kernels.edge_agreement(
                group,
                image,
                False,
                graph.ptr,
                graph.neighbour,
                graph.length,
                t.indptr,
                t.indices,
                t.dist,
                p.d_error,
                p.peak_radius,
                MERGE_AGREEMENT,
            )
            if good and good >= MERGE_AGREEMENT * (good + bad):
                if i < len(images) or j >= n_main:
                    np.copyto(group, image, where=group < 0)
                break
        else:
            groups.append(image.copy())
    return groups


def extract(
    marginals: np.ndarray,
    graph: SourceGraph,
    targets: SparseDistances,
    params: ExtractParams = ExtractParams(),
    self_target: np.ndarray | None = None,
    unary: np.ndarray | None = None,
    passes: Sequence[tuple[np.ndarray, np.ndarray]] = (),
) -> Extraction:
    """Enumerate all symmetries: grow from every source sample and peak, merge, rank.

    Seeds are taken strongest first; a seed (s, t) is skipped when an earlier part
    already maps s within ``peak_radius`` of t. With ``unary`` (and
    ``params.unary_seeds``), the peaks of the unary seed further parts, grown on the
    unary, after all those of the marginals: loopy BP can settle a marginal with several
    symmetric modes on one of them. The marginals of later BP ``passes`` (each run with
    the earlier passes' peaks removed from the unary,
    :func:`intrinsym.mrf.model.suppress_peaks`) seed and grow parts after those of the first
    pass, and the unaries of the passes after the marginals: a pass's unary no longer
    holds the modes found before it. Every part is scored on the marginals (the largest
    over the passes). Parts smaller than ``min_fraction`` of |Ps| are dropped, the others
    merged into maps (identity and non-identity parts separately, so that the two never
    fuse where they coincide, e.g. on a mirror plane; the unary's parts only where they
    add a map), and the best-ranked non-identity map covering at least
    ``global_fraction`` of the source samples, whose normalised marginal averages at
    least ``threshold`` over its pairs, is the global one.

    Parameters
    ----------
    marginals : (S, T) array
    graph : SourceGraph
    targets : SparseDistances
    params : ExtractParams
    self_target : (S,) int64, optional
        See :func:`query`.
    unary : (S, T) array, optional
        The unary potentials, for the extra seeds.
    passes : sequence of ((S, T), (S, T)) array pairs
        Marginals and unary of every later BP pass, in order.

    Returns
    -------
    Extraction
    """
    p = params
    fields = _fields(marginals, unary, passes, p, targets, self_target)
    n_main = len(passes) + 1
    norm = _score_field(fields, n_main)
    n_s = norm.shape[0]
    seeds = [
        (k, -float(field[s, t]), s, int(t))
        for k, field in enumerate(fields)
        for s in range(n_s)
        for t in peaks(field[s], targets, p.threshold, p.peak_radius)[: p.seeds_per_sample]
    ]
    seeds.sort()
    covered = np.zeros(norm.shape, dtype=np.bool_)
    parts: dict[str, list[tuple[int, np.ndarray]]] = {"identity": [], "partial": []}
    for k, _, s, t in seeds:
        if covered[s, t]:
            continue
        image = grow(fields[k], graph, targets, s, t, p, self_target)
        kernels.mark_covered(covered, image, targets.indptr, targets.indices, targets.dist, p.peak_radius)
        kind = "identity" if is_identity(s, t, targets, self_target, p.identity_radius) else "partial"
        parts[kind].append((k, image))
    smallest = max(1.0, p.min_fraction * n_s)

    def largest_first(kind: str, unary_parts: bool) -> list[np.ndarray]:
        found = [im for k, im in parts[kind] if (k >= n_main) == unary_parts and (im >= 0).sum() >= smallest]
        return sorted(found, key=lambda im: -int((im >= 0).sum()))

    symmetries = [
        _make(image, norm, graph, targets, p, kind)
        for kind in parts
        if kind == "partial" or p.keep_identity
        for image in _merge(largest_first(kind, False), graph, targets, p, largest_first(kind, True))
    ]
    symmetries = sorted(symmetries, key=lambda s: -s.score)[: p.max_count * n_main]
    # a global map is made of marginal peaks: one grown across rows without a peak
    # there (on the unary, say, where the marginals hold the identity) is not
    wide = [
        i
        for i, sym in enumerate(symmetries)
        if sym.kind == "partial"
        and len(sym.source) >= p.global_fraction * n_s
        and norm[sym.source, sym.target].mean() >= p.threshold
    ]
    global_index = wide[0] if wide else -1
    if global_index >= 0:
        full = refine(graph, targets, complete(norm, graph, targets, symmetries[global_index].image(n_s), p), p)
        symmetries[global_index] = _make(full, norm, graph, targets, p, "global")
    return Extraction(symmetries, global_index, p)


def _self_target(support: Support, source_points: np.ndarray, target_points: np.ndarray) -> np.ndarray | None:
    return nearest_targets(source_points, target_points) if support.self_match else None


def extract_from_support(
    marginals: np.ndarray,
    edges: np.ndarray,
    support: Support,
    source_points: np.ndarray,
    target_points: np.ndarray,
    params: ExtractParams = ExtractParams(),
    *,
    unary: np.ndarray | None = None,
    passes: Sequence[tuple[np.ndarray, np.ndarray]] = (),
) -> Extraction:
    """:func:`extract` on a pipeline's arrays.

    Parameters
    ----------
    marginals : (S, T) array
    edges : (E, 2) int64
    support : Support
    source_points, target_points : (S, 3), (T, 3) float64
        Sample positions (any common frame; used only to find each source sample's own
        target when self-matching).
    params : ExtractParams
    unary : (S, T) array, optional
        Also seed from the unary's peaks when ``params.unary_seeds``.
    passes : sequence of ((S, T), (S, T)) array pairs
        Marginals and unary of every later BP pass.
    """
    graph = SourceGraph.from_edges(edges, support.edge_length, len(marginals))
    self_target = _self_target(support, source_points, target_points)
    return extract(marginals, graph, support.targets, params, self_target, unary, passes)


def query_from_support(
    marginals: np.ndarray,
    edges: np.ndarray,
    support: Support,
    source_points: np.ndarray,
    target_points: np.ndarray,
    source: int,
    params: ExtractParams = ExtractParams(),
    *,
    unary: np.ndarray | None = None,
    passes: Sequence[tuple[np.ndarray, np.ndarray]] = (),
) -> list[Symmetry]:
    """:func:`query` of one source sample on a pipeline's arrays (parameters as
    :func:`extract_from_support`; ``source`` is the chosen source sample)."""
    graph = SourceGraph.from_edges(edges, support.edge_length, len(marginals))
    self_target = _self_target(support, source_points, target_points)
    return query(marginals, graph, support.targets, source, params, self_target, unary, passes)
