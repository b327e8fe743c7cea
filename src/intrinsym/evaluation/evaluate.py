"""Scores of marginals against a ground-truth symmetry map.

All distances are geodesic, in units of sqrt(surface area). Only source samples whose
true image g lies farther than ``near`` from themselves are scored (a point on the
symmetry plane has nothing to find).

* mirror hit: the argmax of the marginal over targets farther than ``near`` from s lies
  within ``near`` of g;
* peak recall: the largest marginal within ``peak`` of g reaches half the row maximum;
* decoy recall: the same test around a random vertex farther than ``2 near`` from both
  s and g (chance level: a flat marginal passes peak and decoy recall alike);
* breadth: the mean fraction of targets whose marginal reaches half the row maximum.

Scores of a symmetry that is only partial (labelled parts with a true image, the rest
of the shape without one; :func:`partial_scores`):

* limb hit: the mirror hit over the source samples on the labelled parts;
* peak mass: a row's marginal mass within ``near`` of its argmax over targets farther
  than ``near`` from s. A point with a symmetric image concentrates its mass there; a
  point without one (off the parts) spreads it, unless the model invents a symmetry.

Scores of an extracted symmetry map (one image per input vertex):

* correspondence curve: the fraction of vertices whose predicted image lies within
  t of the true one, for t in [0, 0.25] (vertices without a prediction never do), and
  the mean error over the vertices with a prediction;
* segmentation score (the paper's Sec. 6: "the percentage of points that have been
  correctly classified. Incorrect points are either those outside the manual
  segmentation or the missing"): for a labelled part G whose true symmetric part is G',
  the region R the predicted map sends into G' scores |R & G| / |R | G|;
* calibration of the map's per-vertex confidence (the probability that the image lies
  within 0.05 of the true one): per equal-width confidence bin, the share of its
  vertices that do against their mean confidence, and the expected calibration error,
  the gap weighed by the bins' shares (:func:`intrinsym.globalmap.confidence.calibration_report`).
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from ..errors import InputError
from ..files import atomic_write, read_npy
from ..geodesics import geodesics
from ..globalmap.confidence import calibration_report
from ..globalmap.distortion import map_distortion
from ..mesh.shape import Shape, surface_area, vertex_areas


@dataclass(frozen=True)
class MarginalScores:
    """Averages over the scored source samples (see the module docstring)."""

    mirror_hit: float
    peak_recall: float
    decoy_recall: float
    breadth: float
    n_scored: int

    def as_dict(self) -> dict:
        return asdict(self)


def load_symmetry_map(
    path: str | os.PathLike, n_vertices: int | None = None, allow_missing: bool = False
) -> np.ndarray:
    """Read a symmetry map as a 0-based (N,) int64 array.

    Formats: TOSCA ``.sym`` (one 1-based index per line), KIDS ``sym.txt`` (1-based
    indices in ``%e`` notation, any whitespace) and ``.npy`` (0-based integers). With
    ``allow_missing``, -1 (0 in the 1-based formats) marks a vertex without an image,
    as in ``symmetry_map.npy``, and -2 (-1) one that is not scored
    (:data:`intrinsym.evaluation.partial_truth.NOT_SCORED`).

    Raises
    ------
    InputError
        On unreadable files, non-integers or indices out of range.
    """
    p = Path(path)
    try:
        if p.suffix.lower() == ".npy":
            raw = read_npy(p)
            values, base = np.asarray(raw).ravel(), 0
        else:
            values, base = np.array(p.read_text().split(), dtype=np.float64), 1
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: cannot read a symmetry map ({err})") from None
    if values.size == 0:
        raise InputError(f"{path}: empty symmetry map")
    if not np.all(np.isfinite(values)) or np.any(values != np.round(values)):
        raise InputError(f"{path}: symmetry map holds non-integer entries")
    sym = values.astype(np.int64) - base
    if n_vertices is not None and len(sym) != n_vertices:
        raise InputError(f"{path}: symmetry map has {len(sym)} entries, the mesh {n_vertices} vertices")
    if sym.min() < (-2 if allow_missing else 0) or sym.max() >= len(sym):
        raise InputError(f"{path}: symmetry map index out of range")
    return sym


def load_confidence(path: str | os.PathLike, n_vertices: int) -> np.ndarray:
    """Read a per-vertex confidence (``symmetry_confidence.npy``) as (N,) float64.

    Raises
    ------
    InputError
        On an unreadable file, another length than ``n_vertices``, or values outside [0, 1].
    """
    try:
        values = np.asarray(read_npy(path), dtype=np.float64).ravel()
    except (OSError, ValueError, TypeError) as err:
        raise InputError(f"{path}: cannot read a confidence ({err})") from None
    if len(values) != n_vertices:
        raise InputError(f"{path}: {len(values)} confidences, the mesh has {n_vertices} vertices")
    if not np.all((values >= 0) & (values <= 1)):
        raise InputError(f"{path}: confidences must lie in [0, 1]")
    return values


def extrinsic_mirror(vertices: np.ndarray, iterations: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Ground truth for a mesh posed (nearly) mirror-symmetrically: its best reflection.

    Each principal plane through the centroid reflects the vertices; ICP
    (:func:`trimesh.registration.icp`, rigid) then moves the reflected copy onto the
    original, and the plane whose copy lands closest (median distance) wins. Every
    vertex's image is the vertex nearest its reflection. Only as good as the pose is
    symmetric: check ``residual``.

    Parameters
    ----------
    vertices : (N, 3) float array
    iterations : int
        ICP iterations per plane.

    Returns
    -------
    sym : (N,) int64
        Vertex nearest the reflection of every vertex.
    residual : (N,) float64
        Distance from each reflected vertex to that vertex (input units).
    """
    x = np.asarray(vertices, dtype=np.float64)
    x = x - x.mean(axis=0)
    tree = cKDTree(x)
    import trimesh.registration  # here, not at the top: importing trimesh costs 0.2 s

    best: tuple[np.ndarray, np.ndarray] | None = None
    for normal in np.linalg.svd(x, full_matrices=False)[2]:
        reflected = x - 2.0 * np.outer(x @ normal, normal)
        _, moved, _ = trimesh.registration.icp(reflected, x, max_iterations=iterations, reflection=False, scale=False)
        residual, sym = tree.query(moved)
        if best is None or np.median(residual) < np.median(best[1]):
            best = (sym.astype(np.int64), residual)
    assert best is not None
    return best


@dataclass(frozen=True)
class PartialScores:
    """Scores of a partial symmetry (see the module docstring).

    Attributes
    ----------
    limb_hit : float
        Mirror hit over the source samples on the labelled parts.
    limb_mass, off_mass : (n_on,), (n_off,) float64
        Peak mass of each source sample on a labelled part, and of each one farther
        than ``near`` from every labelled part (the body around a part's base is
        locally symmetric too, so it is scored as neither).
    on, off : (S,) bool
        Which source samples those are.
    """

    limb_hit: float
    limb_mass: np.ndarray
    off_mass: np.ndarray
    on: np.ndarray
    off: np.ndarray


def partial_scores(
    vertices: np.ndarray,
    faces: np.ndarray,
    labels: np.ndarray,
    symmetry: np.ndarray,
    marginals: np.ndarray,
    source_vertex: np.ndarray,
    target_vertex: np.ndarray,
    near: float = 0.10,
) -> PartialScores:
    """Limb hit and peak masses of marginals on a shape whose symmetry is partial.

    Parameters
    ----------
    vertices, faces : (N, 3) float, (F, 3) int
        The shape (any units; distances are taken in units of sqrt(area)).
    labels : (N,) int
        Part label of every vertex, 0 off the symmetric parts.
    symmetry : (N,) int
        True image of every vertex on a labelled part (other entries are unused).
    marginals : (S, T) array
    source_vertex, target_vertex : (S,), (T,) int
        Vertex of each source and target sample.
    near : float
        Radius of a hit and of a peak, in units of sqrt(area).
    """
    shape = Shape(np.asarray(vertices, dtype=np.float64), np.asarray(faces))
    graph = geodesics.surface_graph(shape.vertices / np.sqrt(surface_area(shape)), shape.faces)
    labels, sv, tv = np.asarray(labels), np.asarray(source_vertex), np.asarray(target_vertex)
    d_s = geodesics.distances_from(graph, sv)[:, tv]
    d_limb = dijkstra(graph, indices=np.flatnonzero(labels > 0), min_only=True)
    on, off = labels[sv] > 0, (labels[sv] == 0) & (d_limb[sv] > near)
    marg = np.asarray(marginals, dtype=np.float64)
    marg = marg / marg.sum(axis=1, keepdims=True)
    best = np.where(d_s > near, marg, -1.0).argmax(axis=1)
    d_image = geodesics.distances_from(graph, np.asarray(symmetry)[sv[on]])[:, tv]
    hit = d_image[np.arange(on.sum()), best[on]] <= near
    mass = np.sum(marg * (geodesics.distances_from(graph, tv[best])[:, tv] <= near), axis=1)
    return PartialScores(float(hit.mean()) if len(hit) else np.nan, mass[on], mass[off], on, off)


def marginal_scores(
    marginals: np.ndarray,
    d_source: np.ndarray,
    d_mirror: np.ndarray,
    d_decoy: np.ndarray,
    source_mirror: np.ndarray,
    near: float = 0.10,
    peak: float = 0.05,
) -> MarginalScores:
    """The four marginal scores from precomputed geodesics.

    Parameters
    ----------
    marginals : (S, T) array
    d_source, d_mirror, d_decoy : (S, T) arrays
        Distance from s, from its true image g, and from its decoy vertex to every target.
    source_mirror : (S,) array
        d(s, g).
    near, peak : float
        Thresholds (0.10 and 0.05 of sqrt(area) in the project's definition).
    """
    marg = np.asarray(marginals, dtype=np.float64)
    scored = np.flatnonzero(np.asarray(source_mirror) > near)
    if len(scored) == 0:
        return MarginalScores(np.nan, np.nan, np.nan, np.nan, 0)
    hits, peaks, decoys, breadth = [], [], [], []
    for s in scored:
        row = marg[s]
        half = 0.5 * row.max()
        away = d_source[s] > near
        best = np.flatnonzero(away)[np.argmax(row[away])] if away.any() else np.argmax(row)
        hits.append(d_mirror[s, best] <= near)
        around = d_mirror[s] <= peak
        peaks.append(around.any() and row[around].max() >= half)
        around = d_decoy[s] <= peak
        decoys.append(around.any() and row[around].max() >= half)
        breadth.append(np.mean(row >= half))
    return MarginalScores(
        float(np.mean(hits)), float(np.mean(peaks)), float(np.mean(decoys)), float(np.mean(breadth)), len(scored)
    )


def score_marginals(
    marginals: np.ndarray,
    source_vertex: np.ndarray,
    target_vertex: np.ndarray,
    shape: Shape,
    sym: np.ndarray,
    seed: int = 0,
    near: float = 0.10,
    peak: float = 0.05,
    unit: tuple | None = None,
) -> MarginalScores:
    """Score marginals on the input mesh they were computed on.

    Parameters
    ----------
    marginals : (S, T) array
    source_vertex, target_vertex : (S,), (T,) int
        Input-mesh vertex of every source and target sample.
    shape : Shape
        The input mesh (as loaded; it is cleaned and normalised to unit area here).
    sym : (N_in,) int
        Ground-truth symmetric image of every input vertex; -1 (a partial symmetry) for
        none: source samples there are not scored.
    seed : int
        Seed of the decoy choice.
    near, peak : float
        Radii of a hit and of a peak (sqrt(area) units).
    unit : tuple, optional
        ``geodesics.unit_area_graph(shape)``, when the caller has it already.
    """
    cleaned, vmap, graph = unit if unit is not None else geodesics.unit_area_graph(shape)
    image = np.asarray(sym)[np.asarray(source_vertex)]
    has = image >= 0
    marginals = np.asarray(marginals)[has]
    src = vmap[np.asarray(source_vertex)[has]]
    tgt = vmap[np.asarray(target_vertex)]
    mir = vmap[image[has]]
    d_s = geodesics.distances_from(graph, src)
    d_g = geodesics.distances_from(graph, mir)
    rng = np.random.default_rng(seed)
    decoy = np.empty(len(src), dtype=np.int64)
    for i in range(len(src)):
        far = np.flatnonzero((d_s[i] > 2 * near) & (d_g[i] > 2 * near) & np.isfinite(d_s[i]))
        decoy[i] = rng.choice(far) if len(far) else src[i]
    d_d = geodesics.distances_from(graph, decoy)[:, tgt]
    source_mirror = d_s[np.arange(len(src)), mir]
    return marginal_scores(marginals, d_s[:, tgt], d_g[:, tgt], d_d, source_mirror, near, peak)


def save_scores(scores: MarginalScores | dict, path: str | os.PathLike) -> None:
    """Write the scores (or a report dict of them) as JSON (atomically)."""
    report = scores if isinstance(scores, dict) else scores.as_dict()
    atomic_write(path, lambda f: json.dump(report, f, indent=2))


@dataclass(frozen=True)
class MapScores:
    """How close a per-vertex symmetry map comes to the true one (geodesic, sqrt(area)).

    Attributes
    ----------
    thresholds : (K,) float64
        Error thresholds t.
    fraction : (K,) float64
        Fraction of the scored vertices (all that have a true image) whose predicted
        image lies within t of the true one.
    area_fraction : (K,) float64
        The same share of the scored surface area (each vertex weighed by
        :func:`intrinsym.mesh.shape.vertex_areas`): unlike ``fraction`` it does not depend on
        where the mesh is dense (a finely meshed hand holds a larger share of the
        vertices than of the area).
    mean_error : float
        Mean error over the vertices with a prediction (nan when there is none).
    coverage : float
        Fraction of the scored vertices with a prediction.
    n_vertices : int
        Scored vertices.
    errors : (n_vertices,) float64
        Each scored vertex's error (inf without a prediction), in the mesh's vertex order.
    segmentation : dict
        Part label -> segmentation score in [0, 1] (empty without labels).
    """

    thresholds: np.ndarray
    fraction: np.ndarray
    area_fraction: np.ndarray
    mean_error: float
    coverage: float
    n_vertices: int
    errors: np.ndarray
    segmentation: dict = field(default_factory=dict)

    def within(self, t: float, by_area: bool = False) -> float:
        """Fraction of vertices (``by_area``: of the area) within ``t`` (the curve at its
        nearest threshold <= t)."""
        curve = self.area_fraction if by_area else self.fraction
        return float(curve[np.searchsorted(self.thresholds, t + 1e-12) - 1])

    def as_dict(self) -> dict:
        return {
            "within_0.05": self.within(0.05),
            "within_0.10": self.within(0.10),
            "area_within_0.05": self.within(0.05, by_area=True),
            "area_within_0.10": self.within(0.10, by_area=True),
            "mean_error": self.mean_error,
            "coverage": self.coverage,
            "n_vertices": self.n_vertices,
            "curve": {"thresholds": self.thresholds.tolist(), "fraction": self.fraction.tolist()},
            "segmentation": {str(k): v for k, v in self.segmentation.items()},
        }


def load_labels(path: str | os.PathLike, n_vertices: int) -> np.ndarray:
    """Read per-vertex part labels as (N,) int64: ``.npy`` or one integer per line/token.

    Label 0 (or negative) marks vertices outside every part.

    Raises
    ------
    InputError
        On unreadable files, non-integers or a wrong length.
    """
    p = Path(path)
    try:
        values = (
            read_npy(p).ravel() if p.suffix.lower() == ".npy" else np.array(p.read_text().split(), dtype=np.float64)
        )
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: cannot read labels ({err})") from None
    if not np.all(np.isfinite(values)) or np.any(values != np.round(values)):
        raise InputError(f"{path}: labels hold non-integer entries")
    if len(values) != n_vertices:
        raise InputError(f"{path}: {len(values)} labels, the mesh has {n_vertices} vertices")
    return values.astype(np.int64)


def map_errors(predicted: np.ndarray, truth: np.ndarray, graph) -> np.ndarray:
    """Geodesic distance between predicted and true image of every vertex.

    One Dijkstra per distinct predicted vertex, stopped once the true images of all
    vertices mapped there are settled (:func:`geodesics.pair_distances`), so a dense
    map with small errors costs little more than a map extended from a few samples.

    Parameters
    ----------
    predicted : (N,) int
        Predicted image vertex, -1 for none.
    truth : (N,) int
        True image vertex.
    graph : (N, N) sparse
        Geodesic graph (:func:`geodesics.surface_graph`) of the shape, in sqrt(area) units.

    Returns
    -------
    (N,) float64
        Errors; inf where there is no prediction or the two are not connected.
    """
    pred = np.asarray(predicted, dtype=np.int64)
    true = np.asarray(truth, dtype=np.int64)
    err = np.full(len(pred), np.inf)
    has = np.flatnonzero(pred >= 0)
    err[has] = geodesics.pair_distances(graph, np.column_stack([pred[has], true[has]]))
    return err


def correspondence_curve(errors: np.ndarray, thresholds: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """(K,) fraction of the errors (N,) at most each threshold (K,); with ``weights``
    (N,), non-negative, the fraction of their sum."""
    e = np.asarray(errors, dtype=np.float64)
    w = np.ones(len(e)) if weights is None else np.asarray(weights, dtype=np.float64)
    order = np.argsort(e, kind="stable")
    cumulative = np.concatenate([[0.0], np.cumsum(w[order])])
    reached = cumulative[np.searchsorted(e[order], np.asarray(thresholds, dtype=np.float64), side="right")]
    return reached / cumulative[-1] if cumulative[-1] > 0 else np.zeros(len(reached))


def segmentation_scores(predicted: np.ndarray, truth: np.ndarray, labels: np.ndarray) -> dict[int, float]:
    """The paper's segmentation score of every labelled part under a predicted map.

    Parameters
    ----------
    predicted : (N,) int
        Predicted image of every vertex, -1 for none.
    truth : (N,) int
        True image of every vertex; the symmetric part of part k is the label most of
        its true images carry.
    labels : (N,) int
        Part label of every vertex; <= 0 outside all parts.

    Returns
    -------
    dict
        Label k -> |R & G| / |R | G| with G the part and R the vertices whose predicted
        image lies in G's symmetric part.
    """
    lab = np.asarray(labels)
    pred = np.asarray(predicted)
    image_label = np.where(pred >= 0, lab[np.maximum(pred, 0)], 0)
    out = {}
    for k in np.unique(lab[lab > 0]):
        part = lab == k
        partner = np.bincount(lab[np.asarray(truth)[part]].clip(0)).argmax()
        region = (image_label == partner) & (pred >= 0)
        out[int(k)] = float((region & part).sum() / (region | part).sum())
    return out


#: Error thresholds of the correspondence curve, in units of sqrt(area).
THRESHOLDS = np.linspace(0.0, 0.25, 51)


def score_map(
    predicted: np.ndarray,
    shape: Shape,
    sym: np.ndarray,
    thresholds: np.ndarray = THRESHOLDS,
    labels: np.ndarray | None = None,
    unit: tuple | None = None,
) -> MapScores:
    """Score a per-vertex symmetry map on the input mesh (normalised to unit area here).

    Parameters
    ----------
    predicted : (N,) int
        Predicted image of every input vertex, -1 for none.
    shape : Shape
        The input mesh as loaded.
    sym : (N,) int
        True image of every input vertex; -1 (a partial symmetry) for none: only the
        vertices with a true image are scored.
    thresholds : (K,) float
        In units of sqrt(surface area).
    labels : (N,) int, optional
        Part labels for :func:`segmentation_scores`.
    unit : tuple, optional
        ``geodesics.unit_area_graph(shape)``, when the caller has it already.
    """
    _, vmap, graph = unit if unit is not None else geodesics.unit_area_graph(shape)
    truth = np.asarray(sym, dtype=np.int64)
    scored = truth >= 0
    pred = np.asarray(predicted, dtype=np.int64)[scored]
    err = map_errors(np.where(pred >= 0, vmap[np.maximum(pred, 0)], -1), vmap[truth[scored]], graph)
    has = pred >= 0
    return MapScores(
        thresholds=np.asarray(thresholds, dtype=np.float64),
        fraction=correspondence_curve(err, thresholds),
        area_fraction=correspondence_curve(err, thresholds, vertex_areas(shape)[scored]),
        mean_error=float(np.mean(err[has])) if has.any() else float("nan"),
        coverage=float(np.mean(has)),
        n_vertices=len(pred),
        errors=err,
        segmentation={} if labels is None else segmentation_scores(predicted, truth, labels),
    )


def evaluation_report(
    marginals: np.ndarray,
    source_vertex: np.ndarray,
    target_vertex: np.ndarray,
    predicted: np.ndarray | None,
    shape: Shape,
    sym: np.ndarray,
    labels: np.ndarray | None = None,
    seed: int = 0,
    confidence: np.ndarray | None = None,
) -> tuple[dict, MapScores | None]:
    """What ``intrinsym evaluate`` reports (``scores.json``) of a result.

    Parameters
    ----------
    marginals : (S, T) float array
    source_vertex, target_vertex : (S,), (T,) int
        Input vertex of every source and target sample.
    predicted : (N,) int or None
        The symmetry map (image input vertex of every input vertex, -1 for none); None
        when the result has none.
    shape : Shape
    sym : (N,) int
        Ground truth, -1 where a vertex has no true image.
    labels : (N,) int, optional
        Part labels for the segmentation scores.
    seed : int
        Of the decoys and of the distortion's vertices.
    confidence : (N,) float, optional
        The map's per-vertex confidence (``symmetry_confidence.npy``), scored on the
        vertices with a true image.

    Returns
    -------
    report : dict
        :meth:`MarginalScores.as_dict`, the ground truth's :func:`map_distortion` under
        ``"truth_distortion"`` and, with a map, :meth:`MapScores.as_dict` with its
        distortion under ``"map"``; with a map and a confidence, its
        :func:`intrinsym.globalmap.confidence.calibration_report` under ``"confidence"``.
    map_scores : MapScores or None
    """
    unit = geodesics.unit_area_graph(shape)
    report = score_marginals(marginals, source_vertex, target_vertex, shape, sym, seed=seed, unit=unit).as_dict()
    report["truth_distortion"] = map_distortion(sym, shape, seed=seed, unit=unit).as_dict()
    if predicted is None:
        return report, None
    scores = score_map(predicted, shape, sym, labels=labels, unit=unit)
    report["map"] = {**scores.as_dict(), "distortion": map_distortion(predicted, shape, seed=seed, unit=unit).as_dict()}
    if confidence is not None:
        scored = np.asarray(sym) >= 0
        report["confidence"] = calibration_report(np.asarray(confidence)[scored], scores.errors)
    return report, scores


def plot_curve(scores: MapScores, path: str | os.PathLike, title: str = "") -> None:
    """Write the correspondence curve as a PNG (atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    fig, ax = plt.subplots(figsize=(4.5, 3.5), dpi=120)
    ax.plot(scores.thresholds, scores.fraction, lw=2)
    ax.set_xlabel("geodesic error / sqrt(area)")
    ax.set_ylabel("fraction of vertices")
    ax.set_xlim(scores.thresholds[0], scores.thresholds[-1])
    ax.set_ylim(0, 1.01)
    ax.grid(alpha=0.3)
    ax.set_title(title or f"mean error {scores.mean_error:.3f}, within 0.10: {scores.within(0.10):.2f}")
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format="png"), binary=True)
    plt.close(fig)
