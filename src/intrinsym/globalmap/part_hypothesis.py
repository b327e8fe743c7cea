"""A part's map into its whole from a geodesically consistent set of descriptor matches.

Where the extraction's map and the partial functional map are both wrong from the
start, refining and trilaterating them does not help: their anchor core keeps its
distances and is itself wrong (a leg on the other leg, a shifted torso), and it carries
the rest of the part along. A fresh hypothesis comes from the descriptors alone. Every
farthest-point anchor of the part is offered the :data:`HYPOTHESIS_CANDIDATES` samples of
the whole nearest it in descriptor space (the spin images of
:func:`intrinsym.globalmap.part_map.part_descriptors`: local, so a cut changes them only
near it, and blind to reflections, so the true and the mirror answer are both among
them), or the peaks of BP's marginal at the part's sample nearest the anchor
(``part_proposals``), and the largest set of these matches whose geodesic distances agree on the two
shapes is selected by the replicator dynamics of their payoff matrix: the
game-theoretic matching of Albarelli, Rodolà and Torsello (IJCV 2012) and Rodolà et al.
("A game-theoretic approach to deformable shape matching", CVPR 2012), where a stable
strategy of the game is a cluster of mutually consistent matches and at most one match
per anchor survives. The selected anchors and their images locate every vertex of the
part (:func:`intrinsym.globalmap.part_trilateration.best_images`); ``match`` then
trilaterates and polishes that map as it does its other maps and keeps it where it
changes fewer of the part's distances than the map kept so far.

Only pairs of anchors within :data:`~intrinsym.globalmap.part_trilateration.TRILATERATION_REACH`
of each other on the part are compared: a cut or a hole lengthens the part's longer
geodesics against the whole's. The dynamics then favour a patch of anchors mostly within
reach of one another (10-27 of the 64 on the SHREC'16 pairs), and the trilateration grows
it over the part.
"""

from __future__ import annotations

from typing import get_args

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..geodesics.geodesics import distances_from
from ..mesh.sampling import farthest_point_sampling
from ..params import Proposals
from ..surface import Surface, input_map
from .part_map import PART_MAP_CHANGE
from .part_trilateration import MIN_ANCHORS, TRILATERATION_ANCHORS, TRILATERATION_REACH, best_images

__all__ = [
    "HYPOTHESIS_CANDIDATES",
    "HYPOTHESIS_SAMPLES",
    "consistent_matches",
    "hypothesis_maps",
    "marginal_peaks",
    "match_payoffs",
    "replicator_dynamics",
]

#: Farthest-point samples of the whole (Euclidean, seed 0) that the anchors are matched to.
HYPOTHESIS_SAMPLES = 1000
#: Each anchor's candidate images: the whole's samples nearest it in descriptor space.
HYPOTHESIS_CANDIDATES = 16
#: A match whose geodesic distances differ by more than this many ``PART_MAP_CHANGE``
#: pays nothing (the Gaussian's tail left out of the sparse payoff matrix).
PAYOFF_CUTOFF = 3.0
#: The replicator dynamics stop after this many steps, or once the population moves by
#: less than ``REPLICATOR_TOLERANCE`` (L1) in a step.
REPLICATOR_STEPS = 3000
REPLICATOR_TOLERANCE = 1e-9
#: Every this many steps the matches below ``PRUNE_SHARE`` of the strongest are dropped.
PRUNE_EVERY = 20
PRUNE_SHARE = 1e-9
#: Matches with less than this share of the strongest one's population are out of the
#: cluster.
SUPPORT_SHARE = 1e-3


def match_payoffs(
    part_distances: np.ndarray,
    whole_distances: np.ndarray,
    anchor_of: np.ndarray,
    target_of: np.ndarray,
    reach: float,
    width: float,
) -> sp.csr_matrix:
    """The payoff of every pair of candidate matches: how well they keep their distance.

    Two matches (a, b) and (a', b') of anchors a, a' of the part to vertices b, b' of the
    whole pay each other exp(-(d(a, a') - d(b, b'))^2 / (2 width^2)) when a and a' lie
    within ``reach`` of each other on the part, nothing when they lie farther apart,
    share an anchor or a target, or when the distances differ by more than
    ``PAYOFF_CUTOFF`` widths.

    Parameters
    ----------
    part_distances : (A, A) float
        Geodesic distances between the anchors on the part (``inf`` beyond ``reach``).
    whole_distances : (C, C) float
        Geodesic distances between the matches' targets on the whole (``inf`` where not
        measured).
    anchor_of, target_of : (C,) int
        Each match's anchor (row of ``part_distances``) and target (any vertex id).
    reach, width : float
        Graph length units.

    Returns
    -------
    (C, C) scipy.sparse.csr_matrix, symmetric, zero diagonal
    """
    anchor_of = np.asarray(anchor_of)
    target_of = np.asarray(target_of)
    on_part = part_distances[np.ix_(anchor_of, anchor_of)]
    near = (on_part < reach) & (anchor_of[:, None] != anchor_of[None, :]) & (target_of[:, None] != target_of[None, :])
    rows, cols = np.nonzero(near)
    difference = np.abs(on_part[rows, cols] - whole_distances[rows, cols])  # inf where not measured
    pays = difference <= PAYOFF_CUTOFF * width
    values = np.exp(-0.5 * (difference[pays] / width) ** 2)
    return sp.csr_matrix((values, (rows[pays], cols[pays])), shape=near.shape)


def replicator_dynamics(payoff: sp.spmatrix | np.ndarray) -> np.ndarray:
    """The population the discrete replicator dynamics reach from the barycentre.

    x <- x * (P x) / (x' P x), the dynamics whose stable points are the local maxima of
    x' P x on the simplex: for a payoff of mutual consistency, clusters of matches that
    agree with one another (Albarelli et al. 2012). Every ``PRUNE_EVERY`` steps the
    matches below ``PRUNE_SHARE`` of the strongest are set to zero and left out of the
    products: they are not coming back (on SHREC'16 pairs the clusters shrink from about
    1,000 matches to 10-30 over 1,000-3,000 steps, which pruning makes cheap).
    Deterministic.

    Parameters
    ----------
    payoff : (C, C) non-negative, symmetric

    Returns
    -------
    (C,) float64
        On the simplex; all zero when no two matches pay each other.
    """
    n = payoff.shape[0]
    matrix = sp.csr_matrix(payoff)
    active = np.arange(n)
    x = np.full(n, 1.0 / max(n, 1))
    for step in range(1, REPLICATOR_STEPS + 1):
        gain = matrix @ x
        mean = float(x @ gain)
        if mean <= 0.0:
            return np.zeros(n)
        moved = x * gain / mean
        change = float(np.abs(moved - x).sum())
        x = moved
        if change < REPLICATOR_TOLERANCE:
            break
        if step % PRUNE_EVERY == 0:
            keep = x >= PRUNE_SHARE * x.max()
            if not keep.all():
                matrix, x, active = matrix[keep][:, keep], x[keep] / x[keep].sum(), active[keep]
    population = np.zeros(n)
    population[active] = x
    return population


def consistent_matches(population: np.ndarray, anchor_of: np.ndarray) -> np.ndarray:
    """The cluster of a population: per anchor, its strongest match among those holding
    at least ``SUPPORT_SHARE`` of the strongest match's population.

    Parameters
    ----------
    population : (C,) float
        :func:`replicator_dynamics`'.
    anchor_of : (C,) int
        Each match's anchor.

    Returns
    -------
    (K,) int64
        Indices of the chosen matches, by anchor.
    """
    strong = np.flatnonzero(_cluster(population))
    if not len(strong):
        return strong.astype(np.int64)
    order = strong[np.lexsort((-population[strong], anchor_of[strong]))]
    first = np.r_[True, anchor_of[order][1:] != anchor_of[order][:-1]]
    return order[first].astype(np.int64)


def _cluster(population: np.ndarray) -> np.ndarray:
    """(C,) bool: the matches holding at least ``SUPPORT_SHARE`` of the strongest one's
    population (none for an all-zero population)."""
    population = np.asarray(population)
    top = population.max(initial=0.0)
    return (population >= SUPPORT_SHARE * top) & (top > 0.0)


def marginal_peaks(
    marginals: np.ndarray,
    source: np.ndarray,
    target: np.ndarray,
    part: Surface,
    whole: Surface,
    anchors: np.ndarray,
    k: int,
) -> np.ndarray:
    """Each anchor's ``k`` strongest peaks of BP's marginal at the part's sample nearest it.

    A peak is the most probable label not within ``PART_MAP_CHANGE`` (Euclidean) of a
    stronger peak: a match's tolerance, so that the ``k`` are ``k`` places, not one mode's
    neighbouring labels.

    Parameters
    ----------
    marginals : (S, T) float
        BP's marginals of the part's samples over the whole's labels.
    source, target : (S,) and (T,) int
        The samples' working vertices of ``part`` and the labels' of ``whole``.
    part, whole : Surface
    anchors : (A,) int
        Working vertices of ``part``.
    k : int

    Returns
    -------
    (A, k) int64
        Working vertices of ``whole``; a row with fewer than ``k`` peaks repeats its last.
    """
    nearest = cKDTree(part.shape.vertices[source]).query(part.shape.vertices[anchors])[1]
    labels = cKDTree(whole.shape.vertices[target])
    peaks = {}
    for s in np.unique(nearest):
        chosen: list[int] = []
        suppressed = np.zeros(len(target), dtype=bool)
        for t in np.argsort(-marginals[s], kind="stable"):
            if suppressed[t]:
                continue
            chosen.append(int(t))
            if len(chosen) == k:
                break
            suppressed[labels.query_ball_point(labels.data[t], PART_MAP_CHANGE)] = True
        peaks[s] = chosen + chosen[-1:] * (k - len(chosen))
    return np.asarray(target)[np.array([peaks[s] for s in nearest])].astype(np.int64)


def hypothesis_maps(
    part: Surface,
    whole: Surface,
    descriptors: tuple[np.ndarray, np.ndarray],
    count: int,
    trivial: float = 0.0,
    marginals: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    proposals: Proposals = "descriptors",
) -> list[np.ndarray]:
    """Maps of a part into its whole located from consistent clusters of descriptor matches.

    Each of ``count`` rounds runs :func:`replicator_dynamics` on the matches the rounds
    before left (a cluster's matches, and its anchors' other matches in it, are taken
    out) and locates every vertex of the part from the cluster's anchors within
    ``TRILATERATION_REACH`` (:func:`~intrinsym.globalmap.part_trilateration.best_images`).

    Parameters
    ----------
    part, whole : Surface
        Meshes prepared in one unit (:func:`intrinsym.surface.prepare_pair`), as given
        (``match`` prepares them without refinement); distances on their edges and the
        chords across them (``rings=1``, as the trilateration measures).
    descriptors : (N_part_working, D) and (N_whole_working, D) float
        :func:`intrinsym.globalmap.part_map.part_descriptors`.
    count : int
        Hypotheses to draw (``Params.part_hypotheses``, 1 by default: on 50 SHREC'16
        pairs, the 36 worst and best of round 41 among them, one took the share within
        0.10 from 0.672 to 0.828, two to 0.835, three to 0.849, each 3.5-7 s more on the 2-core
        machine; over all 125 pairs, with the part's ``row`` widths, two / four / eight
        reach 0.894 / 0.904 / 0.907 against one's 0.896, worse by more than 0.01 on 10 / 7
        / 13 pairs: the distortion test that weighs them chooses a wrong one about as often
        as a right one; docs/limitations.md).
    marginals : ((S, T) float, (S,) int, (T,) int) or None
        BP's marginals with their samples' working vertices of ``part`` and labels' of
        ``whole`` (:func:`marginal_peaks`); needed unless ``proposals`` is "descriptors".
    proposals : {"descriptors", "marginals", "both"}
        Each anchor's candidate images (``Params.part_proposals``): the
        :data:`HYPOTHESIS_CANDIDATES` samples of the whole nearest it in descriptor space,
        as many peaks of the marginal at the part's sample nearest it, or both, each
        its own ``count`` rounds (the descriptors' maps first).
    trivial : float
        A shape matched to itself (``part`` and ``whole`` one surface): candidates within
        this distance of their anchor are left out, else the identity is the largest
        consistent cluster (graph length units, below ``TRILATERATION_REACH``; 0 for two
        shapes).

    Returns
    -------
    list of (N_part_input,) int64
        Input vertex of the whole of every input vertex of the part, -1 where fewer than
        :data:`~intrinsym.globalmap.part_trilateration.MIN_ANCHORS` of the cluster's
        anchors lie within reach; a cluster of fewer anchors gives no map, and that set's
        rounds stop there.
    """
    if part.shape.faces is None or whole.shape.faces is None:
        raise ValueError("a part's hypotheses need two meshes, not point clouds")
    if not 0.0 <= trivial < TRILATERATION_REACH:
        raise ValueError(f"trivial must lie in [0, {TRILATERATION_REACH}), got {trivial}")
    if proposals not in get_args(Proposals):
        raise ValueError(f"proposals must be one of {get_args(Proposals)}, got {proposals!r}")
    if proposals != "descriptors" and marginals is None:
        raise ValueError(f"proposals={proposals!r} needs the marginals")
    d_part, d_whole = descriptors
    vertices_p, vertices_w = part.shape.vertices, whole.shape.vertices
    anchors = farthest_point_sampling(vertices_p, min(TRILATERATION_ANCHORS, len(vertices_p)))
    k = min(HYPOTHESIS_CANDIDATES, HYPOTHESIS_SAMPLES, len(vertices_w))
    on_part = distances_from(part.chord_graph, anchors, limit=TRILATERATION_REACH)
    offered = []
    if proposals != "marginals":
        samples = farthest_point_sampling(vertices_w, min(HYPOTHESIS_SAMPLES, len(vertices_w)))
        gaps = np.linalg.norm(d_part[anchors][:, None, :] - d_whole[samples][None, :, :], axis=2)
        if trivial > 0.0:
            gaps[on_part[:, samples] < trivial] = np.inf
        offered.append(samples[np.argsort(gaps, axis=1, kind="stable")[:, :k]])
    if marginals is not None and proposals != "descriptors":
        offered.append(marginal_peaks(*marginals, part, whole, anchors, k))
    return [m for per_anchor in offered for m in _cluster_maps(part, whole, anchors, on_part, per_anchor, count)]


def _cluster_maps(
    part: Surface, whole: Surface, anchors: np.ndarray, on_part: np.ndarray, per_anchor: np.ndarray, count: int
) -> list[np.ndarray]:
    """:func:`hypothesis_maps`' rounds on one set of candidates: ``per_anchor``, (A, k)
    working vertices of ``whole`` offered to each anchor; ``on_part``, (A, N_part_working)
    the anchors' distances within reach."""
    anchor_of = np.repeat(np.arange(len(anchors)), per_anchor.shape[1])
    target_of = per_anchor.ravel()
    whole_graph = whole.chord_graph
    targets, row = np.unique(target_of, return_inverse=True)
    # a pair pays nothing beyond this distance on the whole
    horizon = TRILATERATION_REACH + PAYOFF_CUTOFF * PART_MAP_CHANGE
    on_whole = distances_from(whole_graph, targets, limit=horizon)
    payoff = match_payoffs(
        on_part[:, anchors],
        on_whole[:, targets][np.ix_(row, row)],
        anchor_of,
        target_of,
        TRILATERATION_REACH,
        PART_MAP_CHANGE,
    )
    alive = np.ones(len(anchor_of), dtype=bool)
    maps = []
    for _ in range(count):
        keep = sp.diags(alive.astype(np.float64))
        population = replicator_dynamics(keep @ payoff @ keep)
        chosen = consistent_matches(population, anchor_of)
        if len(chosen) < MIN_ANCHORS:
            break
        alive[chosen] = False
        alive[_cluster(population) & np.isin(anchor_of, anchor_of[chosen])] = False
        # the trilateration's horizon: a vertex's image lies within reach of each
        # anchor's image it is located from, up to the change allowed
        images = distances_from(whole_graph, target_of[chosen], limit=2.0 * TRILATERATION_REACH)
        start = np.full(len(part.shape.vertices), -1, dtype=np.int64)
        located = best_images(on_part[anchor_of[chosen]], images, TRILATERATION_REACH, start)
        maps.append(input_map(located, part, whole))
    return maps
