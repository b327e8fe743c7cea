"""Ground truth of a partial symmetry: each vertex's partner, "no partner", or not scored.

A truth map gives every vertex of a shape the vertex its symmetric partner is, or
:data:`NO_PARTNER` (-1) where the partner was cut away, or :data:`NOT_SCORED` (-2) where
it is too close to call. :func:`partner_truth` makes one from each vertex's true point
and mirror point on a complete reference shape; :func:`load_shrec16` reads them from the
SHREC'16 "Partial Matching of Deformable Shapes" files (``X.baryc_gt``,
``X.baryc_gt_sym``: per vertex of X, a 1-based triangle of the null shape and three
barycentric weights).

Protocol (distances in units of sqrt(area) of the reference shape): vertex i's partner
is the vertex j* whose true point lies nearest i's mirror point, at distance d(i); i is
partnered when d(i) <= :data:`PARTNERED`, unpartnered when d(i) > :data:`UNPARTNERED`,
not scored between.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import InputError
from ..geodesics.geodesics import mesh_edges
from ..mesh.io import load
from ..mesh.shape import Shape, surface_area
from .evaluate import load_symmetry_map, map_errors

#: Truth-map entry of a vertex whose partner is missing.
NO_PARTNER = -1
#: Truth-map entry of a vertex that is not scored (its partner is neither clearly there nor clearly missing).
NOT_SCORED = -2
#: A vertex is partnered when its mirror point lies within this of a vertex's true point.
PARTNERED = 0.02
#: ... and unpartnered when it lies farther than this from every one.
UNPARTNERED = 0.05


@dataclass(frozen=True)
class PartialTruth:
    """A partial symmetry's ground truth on a shape.

    Attributes
    ----------
    partner : (N,) int64
        The partner vertex j* of every vertex, :data:`NO_PARTNER` or :data:`NOT_SCORED`.
    distance : (N,) float64
        d(i): from the vertex's mirror point to the nearest true point of a vertex, in
        units of ``unit``.
    unit : float
        The unit of length, in the shape's units: sqrt(area) of the reference shape.
    """

    partner: np.ndarray
    distance: np.ndarray
    unit: float

    @property
    def partnered(self) -> np.ndarray:
        """(N,) bool: vertices with a partner."""
        return self.partner >= 0

    @property
    def unpartnered(self) -> np.ndarray:
        """(N,) bool: vertices whose partner is missing."""
        return self.partner == NO_PARTNER


def partner_truth(points: np.ndarray, mirror: np.ndarray, unit: float) -> PartialTruth:
    """The truth map of a shape from its vertices' true and mirror points.

    Parameters
    ----------
    points : (N, 3) float
        g(i): each vertex's true point on the reference shape.
    mirror : (N, 3) float
        s(i): the mirror of that point, on the reference shape.
    unit : float
        sqrt(area) of the reference shape, in its units.
    """
    distance, nearest = cKDTree(np.asarray(points, dtype=np.float64)).query(np.asarray(mirror, dtype=np.float64))
    distance = distance / unit
    partner = np.where(distance <= PARTNERED, nearest, np.where(distance > UNPARTNERED, NO_PARTNER, NOT_SCORED))
    return PartialTruth(partner.astype(np.int64), distance, float(unit))


def load_barycentric(path: str | os.PathLike, reference: Shape, n_vertices: int) -> np.ndarray:
    """(n_vertices, 3) float64: the points a SHREC'16 barycentric file places on ``reference``.

    Each row is ``tri w1 w2 w3``: a 1-based triangle of ``reference`` and the weights of
    its three corners (in face order).

    Raises
    ------
    InputError
        Unreadable file, a wrong row count or width, a triangle out of range.
    """
    try:
        rows = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: cannot read barycentric coordinates ({err})") from None
    if rows.shape != (n_vertices, 4):
        raise InputError(f"{path}: {rows.shape[0]} rows of {rows.shape[1]} numbers, expected {n_vertices} rows of 4")
    assert reference.faces is not None
    tri = rows[:, 0].astype(np.int64) - 1
    if not np.all(np.isfinite(rows)) or tri.min() < 0 or tri.max() >= len(reference.faces):
        raise InputError(f"{path}: triangle index out of range of {reference.path or 'the reference shape'}")
    corners = reference.vertices[reference.faces[tri]]
    return np.einsum("nk,nkd->nd", rows[:, 1:], corners)


def null_shape_path(partial: str | os.PathLike) -> Path:
    """``<set>/null/<class>.off`` for a SHREC'16 shape ``<set>/<kind>/<kind>_<class>_shape_<k>.off``."""
    p = Path(partial)
    parts = p.stem.split("_")
    if len(parts) < 4 or parts[-2] != "shape":
        raise InputError(f"{partial}: not a SHREC'16 shape name (<kind>_<class>_shape_<k>.off)")
    return p.parent.parent / "null" / f"{'_'.join(parts[1:-2])}.off"


def shrec16_truth(shape: Shape, partial: str | os.PathLike, null: str | os.PathLike | None = None) -> PartialTruth:
    """The partial-symmetry truth of a SHREC'16 shape already read.

    Parameters
    ----------
    shape : Shape
        ``X.off`` as read.
    partial : path
        ``X.off`` or either ground-truth file: ``X.baryc_gt`` and ``X.baryc_gt_sym`` lie
        beside it.
    null : path, optional
        The complete reference shape (default: :func:`null_shape_path`).

    Returns
    -------
    PartialTruth
        Lengths in units of sqrt(area) of the null shape.
    """
    base = Path(partial).with_suffix("")
    reference = load(null if null is not None else null_shape_path(base.with_suffix(".off")))
    n = len(shape.vertices)
    points = load_barycentric(f"{base}.baryc_gt", reference, n)
    mirror = load_barycentric(f"{base}.baryc_gt_sym", reference, n)
    return partner_truth(points, mirror, float(np.sqrt(surface_area(reference))))


def load_shrec16(partial: str | os.PathLike, null: str | os.PathLike | None = None) -> tuple[Shape, PartialTruth]:
    """A SHREC'16 partial shape ``X.off`` and its truth (:func:`shrec16_truth`)."""
    shape = load(partial)
    return shape, shrec16_truth(shape, partial, null)


def load_truth(path: str | os.PathLike, shape: Shape, reference: str | os.PathLike | None = None) -> PartialTruth:
    """A ground-truth file as a :class:`PartialTruth` of ``shape``.

    Parameters
    ----------
    path : path
        A SHREC'16 ``.baryc_gt_sym`` (with ``.baryc_gt`` beside it), or a map that
        :func:`intrinsym.evaluation.evaluate.load_symmetry_map` reads (-1: no partner, -2: not scored).
    shape : Shape
        The mesh the truth describes.
    reference : path, optional
        The complete shape whose sqrt(area) is the unit of length: for SHREC'16 files the
        null shape their barycentric points lie on (default :func:`null_shape_path`);
        otherwise default ``shape`` itself.
    """
    if Path(path).suffix == ".baryc_gt_sym":
        return shrec16_truth(shape, path, reference)
    partner = load_symmetry_map(path, len(shape.vertices), allow_missing=True)
    unit = np.sqrt(surface_area(load(reference) if reference is not None else shape))
    return PartialTruth(partner, np.full(len(partner), np.nan), float(unit))


@dataclass(frozen=True)
class PartialMapScores:
    """A symmetry map scored against a :class:`PartialTruth` (lengths in its ``unit``).

    Attributes
    ----------
    partnered_within_005, partnered_within_010 : float
        Share of the partnered vertices whose image lies within 0.05 / 0.10 of the
        partner, by the graph geodesic on the shape (mesh edges); nan without any.
    unpartnered_unmapped : float
        Share of the unpartnered vertices the map leaves without an image; nan without any.
    balanced : float
        The mean of ``partnered_within_005`` and ``unpartnered_unmapped`` (the one that is
        not nan when the other is): the truth scores 1, "no partner anywhere" 0.5.
    mean_error : float
        Mean error over the partnered vertices the map gives an image (nan: none).
    n_partnered, n_unpartnered : int
    errors : (n_partnered,) float64
        Each partnered vertex's error (inf without an image), in vertex order.
    """

    partnered_within_005: float
    partnered_within_010: float
    unpartnered_unmapped: float
    balanced: float
    mean_error: float
    n_partnered: int
    n_unpartnered: int
    errors: np.ndarray

    def as_dict(self) -> dict:
        """The scalars, for ``scores.json``."""
        return {k: v for k, v in vars(self).items() if k != "errors"}


def edge_graph(shape: Shape, unit: float) -> sp.csr_matrix:
    """(N, N) symmetric CSR: the mesh edges of ``shape`` with their lengths over ``unit``.

    The protocol's graph geodesic (not :func:`intrinsym.geodesics.geodesics.surface_graph`'s
    shortcut chords), so that scores agree with those measured elsewhere on these files.
    """
    if shape.faces is None:
        raise InputError(f"{shape.path or 'shape'}: partial-symmetry scores need a triangle mesh")
    edges = mesh_edges(shape.faces)
    length = np.linalg.norm(shape.vertices[edges[:, 0]] - shape.vertices[edges[:, 1]], axis=1) / unit
    n = len(shape.vertices)
    graph = sp.coo_matrix((np.r_[length, length], (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])))
    return sp.csr_matrix(graph, shape=(n, n))


def _share(mask: np.ndarray) -> float:
    return float(mask.mean()) if len(mask) else float("nan")


def score_partial(predicted: np.ndarray, shape: Shape, truth: PartialTruth) -> PartialMapScores:
    """Score a symmetry map (image vertex of every vertex, -1 for none) against ``truth``."""
    pred = np.asarray(predicted, dtype=np.int64)
    if len(pred) != len(truth.partner):
        raise InputError(f"the map has {len(pred)} entries, the truth {len(truth.partner)}")
    on = truth.partnered
    errors = map_errors(pred[on], truth.partner[on], edge_graph(shape, truth.unit))
    near, far = _share(errors <= 0.05), _share(pred[truth.unpartnered] < 0)
    finite = errors[np.isfinite(errors)]
    return PartialMapScores(
        partnered_within_005=near,
        partnered_within_010=_share(errors <= 0.10),
        unpartnered_unmapped=far,
        balanced=float(np.nanmean([near, far])) if np.isfinite([near, far]).any() else float("nan"),
        mean_error=float(finite.mean()) if len(finite) else float("nan"),
        n_partnered=int(on.sum()),
        n_unpartnered=int(truth.unpartnered.sum()),
        errors=errors,
    )


def part_iou(in_parts: np.ndarray, truth: PartialTruth) -> float:
    """IoU of a symmetry's parts (source and target vertices, (N,) bool) with the
    truth's partnered vertices, over the scored vertices."""
    scored = truth.partner != NOT_SCORED
    mine, theirs = np.asarray(in_parts, dtype=bool) & scored, truth.partnered
    union = (mine | theirs).sum()
    return float((mine & theirs).sum() / union) if union else float("nan")


def partial_report(predicted: np.ndarray, shape: Shape, truth: PartialTruth, best_parts: np.ndarray | None) -> dict:
    """What ``intrinsym evaluate`` reports of a map against a partial truth: the scalars of
    :func:`score_partial` and, with ``best_parts`` ((N,) bool, the best-ranked
    symmetry's two parts), their :func:`part_iou` under ``"iou"``."""
    report = score_partial(predicted, shape, truth).as_dict()
    report["iou"] = None if best_parts is None else part_iou(best_parts, truth)
    report["unit"] = truth.unit
    return report
