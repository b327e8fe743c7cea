"""Symmetries from marginals: peak tracking and region growing (paper Sec. 5.1), then more.

For one source sample s, :func:`query` thresholds its max-normalised marginal at ``t``,
takes the distinct peaks as seeds, and grows each seed over the source graph: a
neighbour n of a mapped sample m joins, mapped to target t', when t' is a peak of n
(normalised marginal >= t) and ``|d_T(f(m), t') - d_S(m, n)| < d_error``. Every grown
seed is a symmetric part pair (source region -> target region, with the point map).

Beyond the paper, :func:`extract` grows from every source sample and every peak, merges
parts that describe the same map, separates the identity (self-matching only), ranks
the symmetries and picks the dominant global one; :func:`vertex_map` extends a symmetry
to every input vertex through the geodesic Voronoi cells of the source samples.

Only the geodesics BP already needed are used: the source-graph edge lengths and the
sparse, distance-sorted target-target distances (:class:`~intrinsym.geodesics.SparseDistances`,
radius R). A target pair farther apart than R counts as incompatible, so ``d_error``
acts at most up to ``R - d_S(m, n)``. All lengths are in units of sqrt(surface area).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba as nb
import numpy as np

from scipy.spatial import cKDTree

from .geodesics import SparseDistances


@dataclass(frozen=True)
class ExtractParams:
    """Parameters of the extraction. Lengths in units of sqrt(surface area).

    Attributes
    ----------
    threshold : float
        Peak threshold t on the max-normalised marginal (paper: t in [0.5, 0.75]).
    d_error : float
        Geodesic error bound of the region growing (paper: d_error in [0.001, 0.15]).
        The default is about two target spacings at the default |Pt| = 4000.
    peak_radius : float
        Distinct peaks of one marginal are at least this far apart (non-maximum
        suppression); also the tolerance within which two maps agree on a point.
    identity_radius : float
        A correspondence is trivial when its target lies within this distance of the
        source point itself (self-matching only); a map seeded at a trivial
        correspondence is the identity, any other map never takes trivial ones.
    global_fraction : float
        The dominant non-identity symmetry is "global" when it covers at least this
        fraction of the source samples (and its pairs average ``threshold`` on the
        normalised marginals).
    seeds_per_sample : int
        :func:`extract` seeds region growings from at most this many (the strongest)
        peaks of each source sample.
    min_fraction : float
        Smallest symmetry that :func:`extract` reports, as a fraction of |Ps| (at least
        one sample).
    max_count : int
        At most this many symmetries per BP pass are reported (the best ranked).
    keep_identity : bool
        Report identity symmetries too.
    unary_seeds : bool
        When :func:`extract` or :func:`query` is given the unary, also seed parts from
        its peaks (beyond the paper; see :func:`extract`).
    no_partner : bool
        The trivial match was kept in the model at a weight (``trivial_weight`` > 0):
        a row whose marginals peak on the identity then says "no symmetric partner",
        and the unary's parts do not grow into it (see :func:`extract`).
    vertex_fit : float
        :func:`fitted_vertex_map` maps the input vertices of a sample's Voronoi cell
        through the linear map fitted to the sample's mapped neighbours when every
        neighbour's relative residual is at most this (beyond the paper; 0: each vertex
        takes its sample's image, :func:`vertex_map`). Off by default: 0.5 lifts the
        generated figure's segmentation to 0.91-1.00 per part and lowers the TOSCA
        global maps' mean error, but costs 1-3 points within 0.10 on cat1 and michael1.
    """

    threshold: float = 0.5
    d_error: float = 0.03
    peak_radius: float = 0.05
    identity_radius: float = 0.05
    global_fraction: float = 0.5
    seeds_per_sample: int = 6
    min_fraction: float = 0.05
    max_count: int = 32
    keep_identity: bool = False
    unary_seeds: bool = True
    no_partner: bool = False
    vertex_fit: float = 0.0

    def __post_init__(self) -> None:
        checks = [
            (not 0 < self.threshold <= 1, "threshold must lie in (0, 1]"),
            (self.d_error <= 0, "d_error must be positive"),
            (self.peak_radius < 0, "peak_radius must be non-negative"),
            (self.identity_radius < 0, "identity_radius must be non-negative"),
            (not 0 < self.global_fraction <= 1, "global_fraction must lie in (0, 1]"),
            (not 0 <= self.min_fraction <= 1, "min_fraction must lie in [0, 1]"),
            (self.max_count < 1, "max_count must be at least 1"),
            (self.seeds_per_sample < 1, "seeds_per_sample must be at least 1"),
            (self.vertex_fit < 0, "vertex_fit must be non-negative"),
        ]
        for bad, message in checks:
            if bad:
                raise ValueError(message)


@dataclass(frozen=True)
class Symmetry:
    """A symmetric part pair: source samples and their images.

    Attributes
    ----------
    source : (k,) int64
        Source sample indices, ascending.
    target : (k,) int64
        Target sample index of the image of each ``source`` entry.
    score : float
        In [0, 1]: the sum over the pairs of the max-normalised marginal, divided by
        |Ps|, times ``consistency``; 1 = the whole shape, each point at its marginal's
        maximum, every edge geodesically consistent.
    consistency : float
        Fraction of source edges inside the part whose images keep their length within
        ``d_error`` (1.0 for a part without internal edges).
    kind : {"identity", "partial", "global"}
    """

    source: np.ndarray
    target: np.ndarray
    score: float
    consistency: float
    kind: str

    def image(self, n_source: int) -> np.ndarray:
        """(n_source,) int64: target sample of every source sample, -1 outside the part."""
        out = np.full(n_source, -1, dtype=np.int64)
        out[self.source] = self.target
        return out


@dataclass(frozen=True)
class Extraction:
    """All symmetries of a result, ranked, and the dominant global one.

    Attributes
    ----------
    symmetries : list of Symmetry
        Ranked by score, best first (identity included only when asked).
    global_index : int
        Index into ``symmetries`` of the global symmetry, -1 when there is none.
    params : ExtractParams
    """

    symmetries: list[Symmetry]
    global_index: int
    params: ExtractParams


@dataclass(frozen=True)
class SourceGraph:
    """CSR adjacency of the undirected source graph with geodesic edge lengths.

    Attributes
    ----------
    ptr : (S+1,) int64
    neighbour : (2E,) int64
    length : (2E,) float64
    """

    ptr: np.ndarray
    neighbour: np.ndarray
    length: np.ndarray

    @classmethod
    def from_edges(cls, edges: np.ndarray, edge_length: np.ndarray, n_source: int) -> SourceGraph:
        """Build from (E, 2) edges into the source samples and their (E,) lengths."""
        e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        a = np.concatenate([e[:, 0], e[:, 1]])
        b = np.concatenate([e[:, 1], e[:, 0]])
        w = np.concatenate([edge_length, edge_length]).astype(np.float64)
        order = np.lexsort((b, a))
        ptr = np.zeros(n_source + 1, dtype=np.int64)
        np.cumsum(np.bincount(a, minlength=n_source), out=ptr[1:])
        return cls(ptr, b[order], w[order])


@dataclass(frozen=True)
class Support:
    """What extraction needs beside the marginals, all computed before or for BP.

    Attributes
    ----------
    edge_length : (E,) float64
        Geodesic length of every source-graph edge.
    targets : SparseDistances
        Target-target geodesics up to ``targets.radius``, rows sorted by distance.
    vertex_source : (N_a,) int64
        Source sample whose geodesic Voronoi cell holds each input vertex of the source
        shape (-1 where none).
    vertex_target : (N_b,) int64
        The same for the target samples on the target shape.
    self_match : bool
        Source and target are one shape (enables the identity kind).
    source_vertices, target_vertices : (N_a, 3), (N_b, 3) float64, optional
        The input vertices of both shapes, in the frame of the sample positions (for
        :func:`fitted_vertex_map`).
    """

    edge_length: np.ndarray
    targets: SparseDistances
    vertex_source: np.ndarray
    vertex_target: np.ndarray
    self_match: bool
    source_vertices: np.ndarray | None = None
    target_vertices: np.ndarray | None = None

    KEYS = ("edge_length", "vertex_source", "vertex_target", "target_distance_indptr",
            "target_distance_index", "target_distance", "target_distance_radius", "self_match")
    #: Keys stored when present (results written before they existed lack them).
    OPTIONAL_KEYS = ("source_vertices", "target_vertices")

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Arrays to store (under :attr:`KEYS` and :attr:`OPTIONAL_KEYS`) beside a
        result's own arrays; when self-matching, the one shape's vertices are stored once."""
        t = self.targets
        stored = self.OPTIONAL_KEYS[:1] if self.self_match else self.OPTIONAL_KEYS
        optional = {k: np.asarray(getattr(self, k), dtype=np.float64) for k in stored
                    if getattr(self, k) is not None}
        return optional | {
            "edge_length": np.asarray(self.edge_length, dtype=np.float64),
            "vertex_source": np.asarray(self.vertex_source, dtype=np.int64),
            "vertex_target": np.asarray(self.vertex_target, dtype=np.int64),
            "target_distance_indptr": t.indptr.astype(np.int64),
            "target_distance_index": t.indices.astype(np.int32),
            "target_distance": t.dist.astype(np.float64),
            "target_distance_radius": np.float64(t.radius),
            "self_match": np.bool_(self.self_match),
        }

    @classmethod
    def from_arrays(cls, z: dict) -> Support:
        """Inverse of :meth:`to_arrays` (optional keys may be missing)."""
        targets = SparseDistances(z["target_distance_indptr"].astype(np.int64),
                                  z["target_distance_index"].astype(np.int64),
                                  z["target_distance"].astype(np.float64), float(z["target_distance_radius"]))
        self_match = bool(z["self_match"])
        source_vertices = z.get("source_vertices")
        target_vertices = source_vertices if self_match else z.get("target_vertices")
        return cls(z["edge_length"], targets, z["vertex_source"], z["vertex_target"], self_match,
                   source_vertices, target_vertices)


# --------------------------------------------------------------------------- kernels


@nb.njit(cache=True)
def _find(t_ptr, t_idx, t_dist, a, b, limit):
    """d_T(a, b) when b lies in row a within ``limit``, else inf."""
    lo = t_ptr[a]
    hi = lo + np.searchsorted(t_dist[lo : t_ptr[a + 1]], limit, "right")
    for k in range(lo, hi):
        if t_idx[k] == b:
            return t_dist[k]
    return np.inf


@nb.njit(cache=True)
def _peaks(row, t_ptr, t_idx, t_dist, threshold, radius):
    """Distinct peaks of one max-normalised marginal row, strongest first.

    Greedy non-maximum suppression: the strongest remaining target >= threshold is a
    peak and suppresses every target within ``radius`` of it.
    """
    cand = np.flatnonzero(row >= threshold)
    cand = cand[np.argsort(-row[cand], kind="mergesort")]
    gone = np.zeros(len(row), dtype=np.bool_)
    out = np.empty(len(cand), dtype=np.int64)
    k = 0
    for t in cand:
        if gone[t]:
            continue
        out[k] = t
        k += 1
        lo = t_ptr[t]
        hi = lo + np.searchsorted(t_dist[lo : t_ptr[t + 1]], radius, "right")
        for j in range(lo, hi):
            gone[t_idx[j]] = True
    return out[:k]


@nb.njit(cache=True)
def _fit(image, n, candidate, g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, cap):
    """How candidate fits as the image of n, over the mapped neighbours k of n.

    Returns the number of them with |d_T(f(k), candidate) - d_S(k, n)| < d_error, the
    number with that residual < cap, and the sum of min(residual, cap)^2 (cap >= d_error).
    """
    count = 0
    within_cap = 0
    total = 0.0
    for e in range(g_ptr[n], g_ptr[n + 1]):
        k = g_nbr[e]
        if image[k] >= 0:
            r = abs(_find(t_ptr, t_idx, t_dist, image[k], candidate, g_len[e] + cap) - g_len[e])
            count += r < d_error
            within_cap += r < cap
            total += min(r, cap) ** 2
    return count, within_cap, total


@nb.njit(cache=True)
def _grow(norm, g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, threshold, d_error, min_support,
          self_target, identity_radius, side, image):
    """Region growing of Sec. 5.1 (breadth first) from the samples already in ``image``.

    ``image`` (S,) holds the map so far (-1 = unmapped) and is extended in place. A
    neighbour n of a mapped m may take any target t' >= threshold with
    |d_T(f(m), t') - d_S(m, n)| < d_error (a contiguous slice of the sorted row of f(m)).
    Among those it takes the one that agrees with most of its mapped neighbours, then
    the largest marginal, if at least ``min_support`` of them agree and no more than
    half of them contradict it by more than 2 d_error (beyond the paper: where two
    maps meet, e.g. rotations of a star at its centre, a candidate can keep the
    parent's length and no other; the looser bar lets near-isometric bends through).
    ``side`` 1 (0) allows only targets within (outside) ``identity_radius`` of n
    itself, the target ``self_target[n]``; -1 allows all. Returns the map's size.
    """
    cand = np.empty(norm.shape[1], dtype=np.int64)
    queue = np.flatnonzero(image >= 0)
    tail = len(queue)
    queue = np.concatenate((queue, np.empty(len(image) - tail, dtype=np.int64)))
    head = 0
    while head < tail:
        m = queue[head]
        head += 1
        row_lo, row_hi = t_ptr[image[m]], t_ptr[image[m] + 1]
        ring = t_dist[row_lo:row_hi]
        for e in range(g_ptr[m], g_ptr[m + 1]):
            n = g_nbr[e]
            if image[n] >= 0:
                continue
            lo = row_lo + np.searchsorted(ring, g_len[e] - d_error, "right")
            hi = row_lo + np.searchsorted(ring, g_len[e] + d_error, "left")
            n_cand = 0
            for k in range(lo, hi):
                if norm[n, t_idx[k]] < threshold:
                    continue
                if side >= 0:
                    near = _find(t_ptr, t_idx, t_dist, self_target[n], t_idx[k], identity_radius) <= identity_radius
                    if near != (side == 1):
                        continue
                cand[n_cand] = t_idx[k]
                n_cand += 1
            best, best_support, best_value = -1, -1, threshold
            mapped = 0
            for f in range(g_ptr[n], g_ptr[n + 1]):
                mapped += image[g_nbr[f]] >= 0
            for c in range(n_cand):
                value = norm[n, cand[c]]
                support, loose, _ = _fit(image, n, cand[c], g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error,
                                         2 * d_error)
                if support < min_support or 2 * loose < mapped:
                    continue
                if support > best_support or (support == best_support and value >= best_value):
                    best, best_support, best_value = cand[c], support, value
            if best >= 0:
                image[n] = best
                queue[tail] = n
                tail += 1
    return tail


@nb.njit(cache=True)
def _refine(image, g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, min_neighbours, passes):
    """Move the inconsistent samples of a map to the target that best keeps their edge lengths.

    A sample n is inconsistent when the distortion of its image (:func:`_fit`,
    residuals capped at 3 d_error) exceeds d_error^2 per mapped neighbour; samples that agree with
    their neighbours stay (moving them too cost 0.7 points of the global map within
    0.10 on TOSCA wolf1). Candidates for n are the targets at d_S(k, n) +- d_error from
    the image of each mapped neighbour k; n moves to the one of least distortion when
    that is less than half of its current image's. Repeated ``passes`` times or until
    nothing moves. Returns the number of moves.
    """
    cap = 3.0 * d_error
    moves = 0
    for _ in range(passes):
        moved = 0
        for n in range(len(image)):
            if image[n] < 0:
                continue
            mapped = 0
            for e in range(g_ptr[n], g_ptr[n + 1]):
                mapped += image[g_nbr[e]] >= 0
            if mapped < min_neighbours:
                continue
            best = image[n]
            best_cost = _fit(image, n, best, g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, cap)[2]
            current = best_cost
            if current <= mapped * d_error**2:
                continue
            for e in range(g_ptr[n], g_ptr[n + 1]):
                k = g_nbr[e]
                if image[k] < 0:
                    continue
                row_lo = t_ptr[image[k]]
                ring = t_dist[row_lo : t_ptr[image[k] + 1]]
                lo = row_lo + np.searchsorted(ring, g_len[e] - d_error, "right")
                hi = row_lo + np.searchsorted(ring, g_len[e] + d_error, "left")
                for j in range(lo, hi):
                    cost = _fit(image, n, t_idx[j], g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, cap)[2]
                    if cost < best_cost:
                        best, best_cost = t_idx[j], cost
            if best != image[n] and best_cost < 0.5 * current:
                image[n] = best
                moved += 1
        moves += moved
        if moved == 0:
            break
    return moves


@nb.njit(cache=True)
def _edge_agreement(a, b, internal, g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, same_tol):
    """(agreeing, disagreeing) counts between maps a and b, both (S,) with -1 = unmapped.

    A sample mapped by both agrees when its two images lie within ``same_tol``; an edge
    (u, v) with u mapped only by a and v only by b agrees when the images keep the edge
    length within ``d_error``. With ``internal`` (and a = b) it counts the edges inside
    one map instead: its consistency.
    """
    good, bad = 0, 0
    for u in range(len(a)):
        if a[u] < 0:
            continue
        if b[u] >= 0 and not internal:
            if _find(t_ptr, t_idx, t_dist, a[u], b[u], same_tol) <= same_tol:
                good += 1
            else:
                bad += 1
            continue
        for e in range(g_ptr[u], g_ptr[u + 1]):
            v = g_nbr[e]
            if b[v] < 0 or (not internal and a[v] >= 0) or (internal and v < u):
                continue
            d = _find(t_ptr, t_idx, t_dist, a[u], b[v], g_len[e] + d_error)
            if abs(d - g_len[e]) < d_error:
                good += 1
            else:
                bad += 1
    return good, bad


@nb.njit(cache=True)
def _dilate(mask, centres, t_ptr, t_idx, t_dist, radius):
    """mask[t] = True for every target t within ``radius`` of a centre (-1 skipped)."""
    for c in centres:
        if c < 0:
            continue
        lo = t_ptr[c]
        hi = lo + np.searchsorted(t_dist[lo : t_ptr[c + 1]], radius, "right")
        for k in range(lo, hi):
            mask[t_idx[k]] = True


@nb.njit(cache=True)
def _mark_covered(covered, image, t_ptr, t_idx, t_dist, radius):
    """covered[s, t] = True for every t within ``radius`` of image[s]."""
    for s in range(len(image)):
        _dilate(covered[s], image[s : s + 1], t_ptr, t_idx, t_dist, radius)


# --------------------------------------------------------------------------- public


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
    return _peaks(r, targets.indptr, targets.indices, targets.dist, threshold, radius)


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
    side = -1 if self_target is None else int(is_identity(seed_source, seed_target, targets, self_target,
                                                           params.identity_radius))
    own = np.full(len(image), -1, dtype=np.int64) if self_target is None else np.asarray(self_target, dtype=np.int64)
    _grow(norm, graph.ptr, graph.neighbour, graph.length, targets.indptr, targets.indices, targets.dist,
          np.float32(params.threshold), params.d_error, 1, own, params.identity_radius, side, image)
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
    _grow(norm, graph.ptr, graph.neighbour, graph.length, targets.indptr, targets.indices, targets.dist,
          np.float32(0.0), params.d_error, 2, unused, params.identity_radius, -1, out)
    return out


def refine(graph: SourceGraph, targets: SparseDistances, image: np.ndarray, params: ExtractParams,
           min_neighbours: int = 3, passes: int = 3) -> np.ndarray:
    """Re-place the samples of a map by the geodesic lengths to their mapped neighbours.

    Region growing accepts any image within ``d_error`` of one neighbour's ring, and the
    removed trivial match leaves samples on a mirror plane no peak at their own (true)
    image, so they settle off the plane; trilateration from the neighbours' images
    finds them (see :func:`_refine`). Only samples with at least ``min_neighbours``
    mapped neighbours move.

    Returns
    -------
    (S,) int64, a refined copy of ``image``.
    """
    out = np.array(image, dtype=np.int64)
    _refine(out, graph.ptr, graph.neighbour, graph.length, targets.indptr, targets.indices, targets.dist,
            params.d_error, min_neighbours, passes)
    return out


def is_identity(
    source: int, target: int, targets: SparseDistances, self_target: np.ndarray | None, radius: float
) -> bool:
    """Whether the correspondence source -> target is trivial: the target lies within
    ``radius`` of the source sample itself (always False without ``self_target``)."""
    if self_target is None:
        return False
    return _find(targets.indptr, targets.indices, targets.dist, self_target[source], target, radius) <= radius


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
    good, bad = _edge_agreement(image, image, True, graph.ptr, graph.neighbour, graph.length,
                                t.indptr, t.indices, t.dist, tolerance, 0.0)
    return good / (good + bad) if good + bad else 1.0


def _make(image: np.ndarray, norm: np.ndarray, graph: SourceGraph, targets: SparseDistances,
          p: ExtractParams, kind: str) -> Symmetry:
    """A Symmetry with its score and consistency from a map (S,) int64."""
    src = np.flatnonzero(image >= 0)
    kept = consistency(image, graph, targets, p.d_error)
    score = float(norm[src, image[src]].sum()) / norm.shape[0] * kept
    return Symmetry(src, image[src], score, kept, kind)


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
            _mark_covered(covered, image, targets.indptr, targets.indices, targets.dist, params.peak_radius)
            kind = "identity" if is_identity(source, t, targets, self_target, params.identity_radius) else "partial"
            found.append(_make(image, norm, graph, targets, params, kind))
    return sorted(found, key=lambda s: -s.score)


def _fields(marginals: np.ndarray, unary: np.ndarray | None, passes: Sequence[tuple[np.ndarray, np.ndarray]],
            p: ExtractParams, targets: SparseDistances, self_target: np.ndarray | None) -> list[np.ndarray]:
    """The row-max-normalised fields to seed and grow from: the marginals of every BP
    pass, then, when ``unary`` is given and ``p.unary_seeds``, the unary of every pass.

    With ``p.no_partner``, a row whose marginals (the largest over the passes) peak on
    the identity is zero in the unary fields: that is BP's answer "no partner", and a
    part grown on the unary must not overrule it (on the generated partial shape the
    unary otherwise carried the limb swap across the body, in parts of 190-220 of 250
    samples whose maps kept 0.66-0.73 of their edges). Without it, a peak there is a
    fixed point of the symmetry BP found (a star's hub, a mirror plane).
    """
    fields = [normalise_rows(m) for m in (marginals, *(m for m, _ in passes))]
    if unary is not None and p.unary_seeds:
        home = np.zeros(len(marginals), dtype=bool)
        if self_target is not None and p.no_partner:
            best = _score_field(fields, len(fields)).argmax(axis=1)
            home = np.array([is_identity(s, t, targets, self_target, p.identity_radius) for s, t in enumerate(best)],
                            dtype=bool)
        fields += [np.where(home[:, None], np.float32(0), normalise_rows(u)) for u in (unary, *(u for _, u in passes))]
    return fields


def _score_field(fields: list[np.ndarray], n_passes: int) -> np.ndarray:
    """What symmetries are scored on: the max-normalised marginals, the largest over
    the passes (each pass's mode scores on its own pass)."""
    return fields[0] if n_passes == 1 else np.maximum.reduce(fields[:n_passes])


def _merge(
    images: list[np.ndarray], graph: SourceGraph, targets: SparseDistances, p: ExtractParams,
    extra: list[np.ndarray] | None = None,
) -> list[np.ndarray]:
    """Greedy union of maps that describe the same map, in the given order.

    A map joins an earlier group when they agree (on shared samples and across the
    edges between them) at least 80% of the time; the group keeps its own images where
    both map a sample. Two different symmetries agree only near their common fixed
    points; a lower bar lets noisy parts of other maps into the group (on TOSCA cat0 a
    simple majority lowered the global map's share within 0.10 from 0.86 to 0.78).
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
            good, bad = _edge_agreement(group, image, False, graph.ptr, graph.neighbour, graph.length,
                                        t.indptr, t.indices, t.dist, p.d_error, p.peak_radius)
            if good and good >= 0.8 * (good + bad):
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
    symmetric modes on one of them (on a five-armed star, 60 / 600 samples, the
    extraction from the marginals alone found 5 of the 20 arm pairs, with the unary's
    peaks 17). The marginals of later BP ``passes`` (each run with the earlier passes'
    peaks removed from the unary, :func:`intrinsym.model.suppress_peaks`) seed and grow
    parts after those of the first pass, and the unaries of the passes after the
    marginals: a pass's unary no longer holds the modes found before it (on the
    generated lantern, three passes found 16 of its 16 arm pairs this way, 12 with the
    first unary's seeds only). Every part is scored on the marginals (the largest over
    the passes). Parts smaller than
    ``min_fraction`` of |Ps| are dropped, the others merged into maps (identity and
    non-identity parts separately, so that the two never fuse where they coincide, e.g.
    on a mirror plane; the unary's parts only where they add a map), and the
    best-ranked non-identity map covering at least ``global_fraction`` of the source
    samples, whose normalised marginal averages at least ``threshold`` over its pairs,
    is the global one.

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
    seeds = [(k, -float(field[s, t]), s, int(t)) for k, field in enumerate(fields) for s in range(n_s)
             for t in peaks(field[s], targets, p.threshold, p.peak_radius)[: p.seeds_per_sample]]
    seeds.sort()
    covered = np.zeros(norm.shape, dtype=np.bool_)
    parts: dict[str, list[tuple[int, np.ndarray]]] = {"identity": [], "partial": []}
    for k, _, s, t in seeds:
        if covered[s, t]:
            continue
        image = grow(fields[k], graph, targets, s, t, p, self_target)
        _mark_covered(covered, image, targets.indptr, targets.indices, targets.dist, p.peak_radius)
        parts["identity" if is_identity(s, t, targets, self_target, p.identity_radius) else "partial"].append((k, image))
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
    wide = [i for i, sym in enumerate(symmetries) if sym.kind == "partial" and len(sym.source) >= p.global_fraction * n_s
            and norm[sym.source, sym.target].mean() >= p.threshold]
    global_index = wide[0] if wide else -1
    if global_index >= 0:
        full = refine(graph, targets, complete(norm, graph, targets, symmetries[global_index].image(n_s), p), p)
        symmetries[global_index] = _make(full, norm, graph, targets, p, "global")
    return Extraction(symmetries, global_index, p)


def vertex_map(symmetry: Symmetry, vertex_source: np.ndarray, target_vertex: np.ndarray, n_source: int) -> np.ndarray:
    """Extend a symmetry to every input vertex.

    Each input vertex takes the image of the source sample whose geodesic Voronoi cell
    holds it.

    Parameters
    ----------
    symmetry : Symmetry
    vertex_source : (N,) int64
        Source sample owning every input vertex (-1 where none).
    target_vertex : (T,) int64
        Input vertex (of the target shape) of every target sample.
    n_source : int

    Returns
    -------
    (N,) int64
        Target input vertex of every input vertex, -1 where the symmetry says nothing.
    """
    image = np.append(symmetry.image(n_source), -1)
    sample = image[np.where(vertex_source >= 0, vertex_source, n_source)]
    return np.where(sample >= 0, np.asarray(target_vertex)[np.maximum(sample, 0)], -1).astype(np.int64)


def agreement(symmetry: Symmetry, vertex_image: np.ndarray, source_vertex: np.ndarray, support: Support) -> float:
    """How far a vertex map keeps a symmetry's sample pairs.

    Parameters
    ----------
    symmetry : Symmetry
    vertex_image : (N_a,) int64
        Target input vertex of every source input vertex (-1 where none).
    source_vertex : (S,) int64
        Input vertex of every source sample.
    support : Support

    Returns
    -------
    float
        Fraction of the pairs s -> t of ``symmetry`` whose source vertex the map sends
        into the Voronoi cell of a target sample within ``support.targets.radius`` of t
        (geodesic); 1.0 for an empty symmetry.
    """
    if not len(symmetry.source):
        return 1.0
    t = support.targets
    image = np.asarray(vertex_image)[np.asarray(source_vertex)[symmetry.source]]
    owner = np.where(image >= 0, np.asarray(support.vertex_target)[np.maximum(image, 0)], -1)
    kept = [b >= 0 and _find(t.indptr, t.indices, t.dist, a, b, t.radius) <= t.radius
            for a, b in zip(symmetry.target, owner)]
    return float(np.mean(kept))


def _members(owner: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices grouped by owner: ``order[bounds[i]:bounds[i + 1]]`` are those with
    ``owner == i`` (entries -1 belong to none)."""
    order = np.argsort(owner, kind="stable")
    return order, np.searchsorted(owner[order], np.arange(n + 1))


def fitted_vertex_map(
    symmetry: Symmetry,
    support: Support,
    edges: np.ndarray,
    source_points: np.ndarray,
    target_points: np.ndarray,
    target_vertex: np.ndarray,
    params: ExtractParams = ExtractParams(),
) -> np.ndarray:
    """Extend a symmetry to every input vertex through local linear fits (beyond the paper).

    :func:`vertex_map` gives every vertex of a sample's Voronoi cell the sample's image,
    so parts are resolved only to the sample spacing (on the generated figure the exact
    map at the samples scores 0.78-0.90 per part that way). Here a mapped sample s with
    at least two mapped neighbours n fits the linear map L (least squares, minimum norm)
    with L (p_n - p_s) = q_f(n) - q_f(s); when every neighbour's residual is at most
    ``params.vertex_fit`` times its edge, each vertex x of the cell goes to the target
    vertex nearest q_f(s) + L (x - p_s) among those in the cells of the targets within
    ``support.targets.radius`` of f(s). The other vertices keep :func:`vertex_map`.

    Parameters
    ----------
    symmetry : Symmetry
    support : Support
        Needs ``source_vertices`` and ``target_vertices``; without them (or with
        ``params.vertex_fit`` 0) this is :func:`vertex_map`.
    edges : (E, 2) int64
    source_points, target_points : (S, 3), (T, 3) float64
        Sample positions in the frame of the support's vertices.
    target_vertex : (T,) int64
    params : ExtractParams

    Returns
    -------
    (N_a,) int64
        Target input vertex of every source input vertex, -1 where the symmetry says
        nothing.
    """
    n_s = len(source_points)
    out = vertex_map(symmetry, support.vertex_source, target_vertex, n_s)
    if params.vertex_fit <= 0 or support.source_vertices is None or support.target_vertices is None:
        return out
    graph = SourceGraph.from_edges(edges, support.edge_length, n_s)
    image = symmetry.image(n_s)
    cell_order, cell_bounds = _members(np.asarray(support.vertex_source), n_s)
    target_order, target_bounds = _members(np.asarray(support.vertex_target), len(target_points))
    t = support.targets
    for s in np.flatnonzero(image >= 0):
        cell = cell_order[cell_bounds[s] : cell_bounds[s + 1]]
        nbr = graph.neighbour[graph.ptr[s] : graph.ptr[s + 1]]
        nbr = nbr[image[nbr] >= 0]
        if len(nbr) < 2 or not len(cell):
            continue
        d = source_points[nbr] - source_points[s]
        e = target_points[image[nbr]] - target_points[image[s]]
        lin = np.linalg.lstsq(d, e, rcond=None)[0]
        if np.max(np.linalg.norm(d @ lin - e, axis=1) / np.linalg.norm(d, axis=1)) > params.vertex_fit:
            continue
        nearby = t.indices[t.indptr[image[s]] : t.indptr[image[s] + 1]]
        candidates = np.sort(np.concatenate([target_order[target_bounds[j] : target_bounds[j + 1]] for j in nearby]))
        y = target_points[image[s]] + (support.source_vertices[cell] - source_points[s]) @ lin
        out[cell] = candidates[cKDTree(support.target_vertices[candidates]).query(y)[1]]
    return out


def from_result(
    marginals: np.ndarray,
    edges: np.ndarray,
    support: Support,
    source_points: np.ndarray,
    target_points: np.ndarray,
    params: ExtractParams = ExtractParams(),
    source: int | None = None,
    unary: np.ndarray | None = None,
    passes: Sequence[tuple[np.ndarray, np.ndarray]] = (),
) -> Extraction | list[Symmetry]:
    """:func:`extract` (or :func:`query` of one source sample) on a pipeline's arrays.

    Parameters
    ----------
    marginals : (S, T) array
    edges : (E, 2) int64
    support : Support
    source_points, target_points : (S, 3), (T, 3) float64
        Sample positions (any common frame; used only to find each source sample's own
        target when self-matching).
    params : ExtractParams
    source : int, optional
        Query this source sample instead of enumerating everything.
    unary : (S, T) array, optional
        Also seed from the unary's peaks (:func:`extract`) when ``params.unary_seeds``.
    passes : sequence of ((S, T), (S, T)) array pairs
        Marginals and unary of every later BP pass (:func:`extract`).
    """
    graph = SourceGraph.from_edges(edges, support.edge_length, len(marginals))
    self_target = nearest_targets(source_points, target_points) if support.self_match else None
    if source is not None:
        return query(marginals, graph, support.targets, source, params, self_target, unary, passes)
    return extract(marginals, graph, support.targets, params, self_target, unary, passes)


def records(
    symmetries: list[Symmetry],
    source_vertex: np.ndarray,
    target_vertex: np.ndarray,
    support: Support,
) -> list[dict]:
    """JSON-ready symmetries in input-vertex indices (the ``symmetries.json`` entries).

    ``source_vertices`` are the input vertices in the Voronoi cells of the part's source
    samples. ``target_vertices`` are those in the cells of the target samples within
    half the median source edge of an image sample (the image of a source cell is about
    that wide). ``pairs`` are [source vertex, target vertex] of every sample pair.
    """
    t = support.targets
    dilate = 0.5 * float(np.median(support.edge_length)) if len(support.edge_length) else 0.0
    out = []
    for sym in symmetries:
        in_source = np.zeros(len(source_vertex) + 1, dtype=bool)
        in_source[sym.source] = True
        near = np.zeros(len(target_vertex) + 1, dtype=bool)
        _dilate(near[:-1], sym.target, t.indptr, t.indices, t.dist, dilate)
        out.append({
            "kind": sym.kind,
            "score": round(float(sym.score), 6),
            "consistency": round(float(sym.consistency), 6),
            "source_vertices": np.flatnonzero(in_source[support.vertex_source]).tolist(),
            "target_vertices": np.flatnonzero(near[support.vertex_target]).tolist(),
            "pairs": np.column_stack([source_vertex[sym.source], target_vertex[sym.target]]).tolist(),
        })
    return out
