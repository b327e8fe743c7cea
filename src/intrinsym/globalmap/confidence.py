"""How far the marginals support a map: the marginal mass it keeps, and a reliability check.

A source sample's marginals are the model's distribution over where it maps. The share of
that distribution within ``radius`` of the sample's image under a map (:func:`mass_within`)
says how far the model supports that image; its mean over the samples is the marginal
mass the map keeps (:func:`kept_mass`): near 1 when the marginals agree with the map
everywhere, low for a patchwork or for a map the marginals do not support. It judges
between candidate global maps (:mod:`intrinsym.globalmap.globalmap`), and every vertex takes the
value of the source sample whose Voronoi cell holds it (:func:`vertex_confidence`,
:func:`map_mass`: ``symmetry_mass.npy``).

The mass is not a calibrated probability: BP's marginals are sharper than the map's
errors on posed shapes. :func:`score` weighs it by how far two global maps agree on each
image, and :func:`calibrated` maps that through a non-decreasing table fitted on posed
shapes (one per bin of how far the map keeps the distances around the vertex) to the
probability that a vertex's image lies within 0.05 of the true one
(``symmetry_confidence.npy``); the map of a partial symmetry (no global map to weigh
it against, no local distortion that separates right from wrong: it changes the
distances across its parts' borders) takes the mass through its own table, fitted on
the SHREC'16 partial shapes. docs/results.md checks the tables on held-out classes with
:func:`calibration` (reliability table and expected calibration error).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..extract.support import Support
from ..geodesics.geodesics import SparseDistances

__all__ = [
    "CALIBRATION",
    "DISTORTION_BINS",
    "PARTIAL_CALIBRATION",
    "PART_CALIBRATION",
    "Bin",
    "calibrated",
    "calibration",
    "carried_confidence",
    "disagreement",
    "distortion_group",
    "kept_mass",
    "map_mass",
    "mass_within",
    "round_trip",
    "sample_images",
    "score",
    "trip_distance",
    "vertex_confidence",
]


#: Bin edges of the global map's local distortion (:func:`intrinsym.globalmap.distortion.local_distortion`,
#: sqrt(area) units) that pick a vertex's table in :data:`CALIBRATION`: where the map
#: keeps the distances around a vertex, its image is more often right at the same score.
DISTORTION_BINS = (0.01, 0.02)
#: The calibration of :func:`calibrated`, one table per bin of the local distortion
#: (below 0.01, 0.01-0.02, above 0.02): the share of vertices whose image lies within
#: 0.05 sqrt(area) of the true one, per 1/20-wide bin of :func:`score` (value at the
#: bin's centre), fitted (isotonic) over the TOSCA poses, KIDS and the mirror-posed scans
#: by ``benchmarks/calibration.py``; docs/results.md checks it one held-out class at a time.
CALIBRATION = (
    (
        0.943, 0.943, 0.943, 0.943, 0.943, 0.943, 0.943, 0.943, 0.943, 0.948,
        0.956, 0.978, 0.982, 0.988, 0.994, 0.996, 0.998, 0.999, 1.000, 1.000,
    ),
    (
        0.710, 0.796, 0.796, 0.796, 0.796, 0.796, 0.796, 0.799, 0.831, 0.864,
        0.906, 0.937, 0.937, 0.944, 0.955, 0.961, 0.967, 0.983, 0.983, 0.985,
    ),
    (
        0.130, 0.507, 0.531, 0.531, 0.531, 0.546, 0.638, 0.678, 0.747, 0.794,
        0.804, 0.804, 0.885, 0.935, 0.949, 0.949, 0.955, 1.000, 1.000, 1.000,
    ),
)  # fmt: skip


#: The calibration of a partial symmetry's map (self-matching): the share of its
#: vertices whose image lies within 0.05 sqrt(area) of the true partner (a vertex whose
#: partner is missing has none), per 1/20-wide bin of its score (value at the bin's
#: centre), fitted (isotonic) over the 70 SHREC'16 partial shapes whose dominant symmetry
#: is not global by ``benchmarks/calibration.py --feature partial_score`` (the maps
#: :func:`~intrinsym.globalmap.self_hypothesis.self_symmetry_map` keeps; held out by
#: class, pooled ECE 0.039). It varies little with the score: where the map is wholly
#: wrong its score is as high as where it is right, and 0.64 of such maps' images are right.
PARTIAL_CALIBRATION = (
    0.604, 0.642, 0.642, 0.692, 0.692, 0.692, 0.717, 0.717, 0.717, 0.717,
    0.717, 0.717, 0.717, 0.717, 0.717, 0.717, 0.717, 0.717, 0.717, 0.717,
)  # fmt: skip


#: The calibration of a part's map onto its whole (``match`` of a shape with less than
#: ``PARTIAL_AREA`` of the other's area): the share of its vertices whose image lies
#: within 0.05 sqrt(area) of the nearer of the true and the mirror point, per 1/20-wide
#: bin of the share of the part's short distances the map keeps
#: (:attr:`intrinsym.globalmap.part_map.PartMapStats.kept`; value at the bin's centre),
#: fitted (isotonic) over the 125 SHREC'16 partial shapes matched to their null shapes by
#: ``benchmarks/calibration.py --feature part_kept``. One value per map: a part's
#: marginals are nearly flat and do not rank its images, but a map that keeps the
#: part's distances is right on most of it, one that tears them on little.
PART_CALIBRATION = (
    0.076, 0.076, 0.076, 0.076, 0.076, 0.076, 0.076, 0.076, 0.076, 0.076,
    0.076, 0.076, 0.076, 0.076, 0.076, 0.201, 0.370, 0.597, 0.693, 0.886,
)  # fmt: skip


#: The confidence of a vertex is the probability that its image lies within this of the
#: true one (units of sqrt(area)).
WITHIN = 0.05
#: Two global maps (the chosen one and the extraction's) placing a vertex's image this far
#: apart (units of sqrt(area)) leave it no score: one of them is off by half of it at least.
DISAGREEMENT_RANGE = 0.10
#: :func:`round_trip` weighs a map only when at least this share of the vertices return
#: within ``DISAGREEMENT_RANGE`` under it (0.73-1.00 on the global maps of the 11 TOSCA
#: poses checked in docs/notes/2026-11-28-results-behind-the-defaults.md; a rotation of
#: order three returns only the vertices near its axis).
INVOLUTIVE_SHARE = 0.5


def disagreement(vertices: np.ndarray, first: np.ndarray, second: np.ndarray, scale: float) -> np.ndarray:
    """Straight-line distance between each vertex's images under two maps.

    Parameters
    ----------
    vertices : (M, 3) float array
        Positions of the image vertices.
    first, second : (N,) int arrays
        Image of every vertex under each map, -1 for none.
    scale : float
        Length unit of the result (sqrt(area) of the shape).

    Returns
    -------
    (N,) float64
        ``|vertices[first] - vertices[second]| / scale``; nan where either map has no image.
    """
    a, b = np.asarray(first, dtype=np.int64), np.asarray(second, dtype=np.int64)
    v = np.asarray(vertices, dtype=np.float64)
    d = np.linalg.norm(v[np.maximum(a, 0)] - v[np.maximum(b, 0)], axis=1) / scale
    return np.where((a >= 0) & (b >= 0), d, np.nan)


def round_trip(vertices: np.ndarray, image: np.ndarray, scale: float) -> np.ndarray:
    """Straight-line distance from each vertex to its image's image, where the map is a
    reflection.

    A reflection is its own inverse, so a vertex whose image's image lies ``r`` from it
    has an image (or an image's image) off by ``r / 2`` at least. A map that fewer than
    ``INVOLUTIVE_SHARE`` of the vertices return under within ``DISAGREEMENT_RANGE`` is
    taken for a rotation of higher order, and says nothing.

    Parameters and returns as :func:`trip_distance`'s, nan everywhere when the map is no
    reflection.
    """
    d = trip_distance(vertices, image, scale)
    if np.mean(d < DISAGREEMENT_RANGE) < INVOLUTIVE_SHARE:
        return np.full(len(d), np.nan)
    return d


def trip_distance(vertices: np.ndarray, image: np.ndarray, scale: float) -> np.ndarray:
    """Straight-line distance from each vertex to its image's image, any map.

    Parameters
    ----------
    vertices : (N, 3) float array
        Positions (self-matching: the map takes the vertices to themselves).
    image : (N,) int array
        Image of every vertex, -1 for none.
    scale : float
        Length unit of the result (sqrt(area) of the shape).

    Returns
    -------
    (N,) float64
        ``|vertices[image[image]] - vertices| / scale``; nan where either step has no image.
    """
    a = np.asarray(image, dtype=np.int64)
    twice = np.where(a >= 0, a[np.maximum(a, 0)], -1)
    return disagreement(vertices, twice, np.arange(len(a)), scale)


def score(mass: np.ndarray, apart: np.ndarray, trip: np.ndarray | None = None) -> np.ndarray:
    """Per-vertex score in [0, 1] that :func:`calibrated` turns into a probability: the
    marginal mass (:func:`map_mass`, how far the model supports the image) times
    ``1 - apart / DISAGREEMENT_RANGE`` clipped to [0, 1] (how far two maps agree on it;
    ``apart``: :func:`disagreement`, nan where the second map has no image: the mass
    alone), times ``1 - trip / DISAGREEMENT_RANGE`` clipped likewise (how far the map
    returns the vertex to itself; ``trip``: :func:`round_trip`, nan: no factor)."""
    factor = np.asarray(mass, dtype=np.float64).copy()
    for d in (apart, trip):
        if d is not None:
            d = np.nan_to_num(np.asarray(d, dtype=np.float64), nan=0.0)
            factor *= np.clip(1.0 - d / DISAGREEMENT_RANGE, 0.0, 1.0)
    return factor


def distortion_group(distortion: np.ndarray | None, n: int) -> np.ndarray:
    """(n,) int64: the table of :data:`CALIBRATION` each vertex takes, by its local
    distortion's bin (:data:`DISTORTION_BINS`); NaN (unknown) takes the last, None
    (a result without it) the first."""
    if distortion is None:
        return np.zeros(n, dtype=np.int64)
    d = np.asarray(distortion, dtype=np.float64)
    return np.where(np.isnan(d), len(DISTORTION_BINS), np.digitize(d, DISTORTION_BINS)).astype(np.int64)


def calibrated(
    mass: np.ndarray, distortion: np.ndarray | None = None, *, table: tuple[float, ...] | None = None
) -> np.ndarray:
    """Per-vertex confidence from :func:`score`: the probability that the vertex's image
    lies within 0.05 sqrt(area) of its true image.

    Parameters
    ----------
    mass : (N,) float array in [0, 1]
        :func:`score` of every vertex.
    distortion : (N,) float array, optional
        The global map's local distortion at every vertex
        (:func:`intrinsym.globalmap.distortion.local_distortion`, sqrt(area) units; NaN unknown);
        None: every vertex takes the first table.
    table : tuple of float, optional
        One table every vertex takes instead (``distortion`` is ignored): a partial
        symmetry's map, :data:`PARTIAL_CALIBRATION`; a part matched to its whole,
        :data:`PART_CALIBRATION`.

    Returns
    -------
    (N,) float32 in [0, 1]
        Linear interpolation of the vertex's table of :data:`CALIBRATION`
        (:func:`distortion_group`), or of ``table``, between the bin centres (constant
        beyond the first and last).
    """
    x = np.asarray(mass, dtype=np.float64)
    if table is not None:
        return _through(x, table).astype(np.float32)
    group = distortion_group(distortion, len(x))
    out = np.empty(len(x))
    for g, tab in enumerate(CALIBRATION):
        inside = group == g
        out[inside] = _through(x[inside], tab)
    return out.astype(np.float32)


def _through(x: np.ndarray, table: tuple[float, ...]) -> np.ndarray:
    """``x`` through a table of values at the centres of equal-width bins of [0, 1]."""
    return np.interp(x, (np.arange(len(table)) + 0.5) / len(table), table)


def carried_confidence(confidence: np.ndarray, vertex_source: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Per-vertex confidence where no source sample's cell reaches: that of the nearest
    vertex a cell holds.

    Such a vertex lies on a connected component without samples, whose image the rigid
    motion of the surface around it gives (:func:`intrinsym.globalmap.vertex_maps.carried_to_components`):
    it is as sure as the map of that surface. Its own score has no marginal mass behind
    it and would say it is almost surely wrong (gorilla1's teeth: 0.12, while 93.5 % of
    them land on their mirror tooth).

    Parameters
    ----------
    confidence : (N,) float array
        :func:`calibrated` of every vertex.
    vertex_source : (N,) int array
        Source sample whose cell holds every vertex (``Support.vertex_source``), -1 for none.
    positions : (N, 3) float array
        Vertex positions.

    Returns
    -------
    (N,) float32
        ``confidence`` itself where every vertex is in a cell, or none is.
    """
    out = np.array(confidence, dtype=np.float32)
    seen = np.asarray(vertex_source) >= 0
    if seen.all() or not seen.any():
        return out
    nearest = cKDTree(np.asarray(positions)[seen]).query(np.asarray(positions)[~seen])[1]
    out[~seen] = out[seen][nearest]
    return out


def mass_within(marginals: np.ndarray, image: np.ndarray, targets: SparseDistances, radius: float) -> np.ndarray:
    """Marginal mass of every source sample within ``radius`` of its image.

    Parameters
    ----------
    marginals : (S, T) float array
        Marginals (any positive scale per row; rows are normalised here).
    image : (S,) int array
        Target sample of each source sample's image, -1 for none.
    targets : SparseDistances
        Target-target geodesics; ``radius`` is clipped to theirs.
    radius : float
        Length units of ``targets`` (normalised: unit sqrt(area)).

    Returns
    -------
    (S,) float64 in [0, 1]
        0 where ``image`` is -1.
    """
    image = np.asarray(image, dtype=np.int64)
    m = np.asarray(marginals, dtype=np.float64)
    total = m.sum(axis=1)
    out = np.zeros(len(image))
    for s in np.flatnonzero((image >= 0) & (total > 0)):
        lo, hi = targets.indptr[image[s]], targets.indptr[image[s] + 1]
        near = targets.indices[lo:hi][targets.dist[lo:hi] <= radius]
        out[s] = m[s, near].sum() / total[s]
    return out


def kept_mass(marginals: np.ndarray, image: np.ndarray, targets: SparseDistances, radius: float) -> float:
    """Mean of :func:`mass_within` over the source samples (unmapped ones count 0)."""
    return float(mass_within(marginals, image, targets, radius).mean()) if len(image) else 0.0


def sample_images(vertex_image: np.ndarray, source_vertex: np.ndarray, vertex_target: np.ndarray) -> np.ndarray:
    """The target sample a dense map sends each source sample to.

    Parameters
    ----------
    vertex_image : (N,) int array
        Image input vertex of every input vertex, -1 for none.
    source_vertex : (S,) int array
        Input vertex of every source sample.
    vertex_target : (N,) int array
        Target sample whose Voronoi cell holds each input vertex (``Support.vertex_target``).

    Returns
    -------
    (S,) int64, -1 where the map has no image.
    """
    image = np.asarray(vertex_image, dtype=np.int64)[np.asarray(source_vertex, dtype=np.int64)]
    cell = np.asarray(vertex_target, dtype=np.int64)
    return np.where(image >= 0, cell[np.maximum(image, 0)], -1)


def vertex_confidence(sample_confidence: np.ndarray, vertex_source: np.ndarray) -> np.ndarray:
    """Per input vertex, the confidence of the source sample whose Voronoi cell holds it.

    Parameters
    ----------
    sample_confidence : (S,) float array
    vertex_source : (N,) int array
        Source sample of every input vertex (``Support.vertex_source``), -1 for none.

    Returns
    -------
    (N,) float32, 0 where a vertex has no sample.
    """
    owner = np.asarray(vertex_source, dtype=np.int64)
    conf = np.asarray(sample_confidence, dtype=np.float32)
    return np.where(owner >= 0, conf[np.maximum(owner, 0)], 0.0).astype(np.float32)


def map_mass(
    marginals: np.ndarray, vertex_image: np.ndarray, source_vertex: np.ndarray, support: Support, radius: float
) -> np.ndarray:
    """Per input vertex, the marginal mass a dense map keeps (``symmetry_mass.npy``).

    Parameters
    ----------
    marginals : (S, T) float array
    vertex_image : (N,) int array
        The map: image input vertex of every input vertex, -1 for none.
    source_vertex : (S,) int array
        Input vertex of every source sample.
    support : Support
        Its Voronoi cells (input vertex -> sample) and target geodesics.
    radius : float
        Normalised length (unit sqrt(area)).

    Returns
    -------
    (N,) float32 in [0, 1]
        The marginal mass of the vertex's source sample within ``radius`` of where the map
        sends that sample (:func:`mass_within`); 0 where the map has no image.
    """
    image = sample_images(vertex_image, source_vertex, support.vertex_target)
    conf = vertex_confidence(mass_within(marginals, image, support.targets, radius), support.vertex_source)
    return np.where(np.asarray(vertex_image) >= 0, conf, 0.0).astype(np.float32)


@dataclass(frozen=True)
class Bin:
    """One bin of a reliability table.

    Attributes
    ----------
    low, high : float
        Confidence range [low, high) (the last bin includes 1).
    share : float
        Fraction of the items in the bin.
    confidence : float
        Their mean confidence (nan for an empty bin).
    accuracy : float
        Fraction of them that are correct (nan for an empty bin).
    """

    low: float
    high: float
    share: float
    confidence: float
    accuracy: float


def calibration(confidence: np.ndarray, correct: np.ndarray, n_bins: int = 10) -> tuple[float, list[Bin]]:
    """Reliability table and expected calibration error of a confidence.

    Parameters
    ----------
    confidence : (N,) float array in [0, 1]
    correct : (N,) bool array
        Whether each item is right (for a map: its image within 0.05 of the true one).
    n_bins : int
        Equal-width bins over [0, 1].

    Returns
    -------
    ece : float
        Sum over the bins of share x |accuracy - confidence| (0: calibrated).
    bins : list of Bin
    """
    conf = np.asarray(confidence, dtype=np.float64)
    ok = np.asarray(correct, dtype=bool)
    which = np.minimum((conf * n_bins).astype(np.int64), n_bins - 1)
    bins, ece = [], 0.0
    for b in range(n_bins):
        inside = which == b
        share = float(inside.mean()) if len(conf) else 0.0
        mean_conf = float(conf[inside].mean()) if inside.any() else float("nan")
        accuracy = float(ok[inside].mean()) if inside.any() else float("nan")
        if inside.any():
            ece += share * abs(accuracy - mean_conf)
        bins.append(Bin(b / n_bins, (b + 1) / n_bins, share, mean_conf, accuracy))
    return ece, bins


def calibration_report(confidence: np.ndarray, errors: np.ndarray, n_bins: int = 10) -> dict:
    """How well a per-vertex confidence predicts which images are right, JSON-ready.

    Parameters
    ----------
    confidence : (N,) float array in [0, 1]
        The confidence of every scored vertex (``symmetry_confidence.npy``).
    errors : (N,) float array
        Geodesic distance from each vertex's image to its true one (sqrt(area) units; inf
        where the map gives none, which then counts as wrong).
    n_bins : int
        Equal-width confidence bins of :func:`calibration`.

    Returns
    -------
    dict
        ``expected_calibration_error``; ``confidence``, the mean confidence (the global
        confidence over these vertices); ``within``, the share of them whose image lies
        within :data:`WITHIN` of the true one; ``bins``, the reliability table (its empty
        bins' mean confidence and accuracy None).
    """
    conf = np.asarray(confidence, dtype=np.float64)
    right = np.asarray(errors, dtype=np.float64) <= WITHIN
    if len(conf) != len(right) or len(conf) == 0:
        raise ValueError(f"{len(conf)} confidences for {len(right)} errors: need as many, and some")
    ece, bins = calibration(conf, right, n_bins)

    def finite(x: float) -> float | None:
        return None if np.isnan(x) else float(x)

    return {
        "expected_calibration_error": float(ece),
        "confidence": float(conf.mean()),
        "within": float(right.mean()),
        "threshold": WITHIN,
        "bins": [
            {
                "low": b.low,
                "high": b.high,
                "share": b.share,
                "confidence": finite(b.confidence),
                "accuracy": finite(b.accuracy),
            }
            for b in bins
        ],
    }
