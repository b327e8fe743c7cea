"""Scores against a symmetry group: several true maps, each found symmetry scored against
its nearest one.

A shape with many symmetries (the generated star's 19, a cube's 47) has as many right
answers; scored against one of them, a found map equal to another is a failure. Here the
ground truth is a list of maps (a ``.npy`` of shape (K, N), as ``intrinsym generate``
writes ``STEM.maps.npy``, or several files) and

* the global map is scored against the true map it is nearest to: the one of least mean
  error, each vertex's error capped at :data:`CAP` (a vertex without an image counts as
  :data:`CAP`), over the vertices the true map gives an image;
* every extracted symmetry (``symmetries.json``) is scored by its sample pairs against
  the true map nearest to them, in the same sense.

Distances are geodesic, in units of sqrt(surface area), as in :mod:`intrinsym.evaluation.evaluate`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..files import read_npy
from ..geodesics import geodesics
from ..mesh.io import load
from ..mesh.shape import Shape, surface_area
from .partial_truth import PartialTruth, load_truth

#: Error (sqrt(area) units) at which a vertex counts as missed when choosing the nearest map.
CAP = 0.25
#: The error within which a pair counts as right in the per-symmetry scores.
WITHIN = 0.10


def _group_rows(path: str | os.PathLike, n_vertices: int) -> np.ndarray | None:
    """(K, N) int64 maps of a 2-D ``.npy``; None for any other file (one map)."""
    if Path(path).suffix.lower() != ".npy":
        return None
    try:
        raw = np.asarray(read_npy(Path(path)))
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: cannot read a symmetry map ({err})") from None
    if raw.ndim != 2:
        return None
    if raw.shape[1] != n_vertices or raw.shape[0] == 0:
        raise InputError(f"{path}: symmetry maps of shape {raw.shape}, expected (K, {n_vertices}) for the mesh")
    if not np.issubdtype(raw.dtype, np.integer) and not (np.all(np.isfinite(raw)) and np.all(raw == np.round(raw))):
        raise InputError(f"{path}: symmetry maps hold non-integer entries")
    maps = raw.astype(np.int64)
    if maps.min() < -2 or maps.max() >= n_vertices:
        raise InputError(f"{path}: symmetry map index out of range")
    return maps


def load_truths(
    paths: Sequence[str | os.PathLike], shape: Shape, reference: str | os.PathLike | None = None
) -> list[PartialTruth]:
    """Every true map the files hold, in order.

    Parameters
    ----------
    paths : sequence of path
        Files :func:`intrinsym.evaluation.partial_truth.load_truth` reads (one map each), or ``.npy``
        files of shape (K, N) (K maps; -1: no partner, -2: not scored).
    shape : Shape
        The mesh the maps describe.
    reference : path, optional
        As in :func:`intrinsym.evaluation.partial_truth.load_truth`.
    """
    n = len(shape.vertices)
    truths: list[PartialTruth] = []
    for path in paths:
        maps = _group_rows(path, n)
        if maps is None:
            truths.append(load_truth(path, shape, reference))
            continue
        unit = float(np.sqrt(surface_area(load(reference) if reference is not None else shape)))
        truths += [PartialTruth(row, np.full(n, np.nan), unit) for row in maps]
    return truths


def capped_errors(pairs: np.ndarray, truths: np.ndarray, unit: tuple) -> np.ndarray:
    """(K, P) geodesic error of P [vertex, image] pairs under each of K true maps,
    capped at :data:`CAP`; NaN where a map gives the vertex no image.

    Parameters
    ----------
    pairs : (P, 2) int
        Input vertex and its found image (-1 for none: error :data:`CAP`).
    truths : (K, N) int
        True maps.
    unit : tuple
        ``geodesics.unit_area_graph(shape)``.
    """
    _, vmap, graph = unit
    p = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    true = np.asarray(truths, dtype=np.int64)[:, p[:, 0]]
    err = np.full(true.shape, CAP)
    err[true < 0] = np.nan
    k, i = np.nonzero((true >= 0) & (p[:, 1] >= 0)[None, :])
    if len(i):
        found = geodesics.pair_distances(graph, np.column_stack([vmap[p[i, 1]], vmap[true[k, i]]]), limit=CAP)
        err[k, i] = np.minimum(found, CAP)
    return err


def _mean(err: np.ndarray) -> np.ndarray:
    """(K,) mean over the scored entries of each row; CAP for a row with none."""
    counts = np.sum(~np.isnan(err), axis=1)
    return np.where(counts > 0, np.nansum(err, axis=1) / np.maximum(counts, 1), CAP)


def nearest_map(predicted: np.ndarray, truths: np.ndarray, unit: tuple) -> int:
    """Index of the true map (K, N) nearest to a found map (N,) (-1: no image)."""
    pred = np.asarray(predicted, dtype=np.int64)
    if len(truths) == 1:
        return 0
    err = capped_errors(np.column_stack([np.arange(len(pred)), pred]), truths, unit)
    return int(np.argmin(_mean(err)))


def symmetry_scores(records: Sequence[Mapping[str, Any]], truths: np.ndarray, unit: tuple) -> list[dict[str, Any]]:
    """Each extracted symmetry (``symmetries.json`` entries, in rank order) against its
    nearest true map: ``rank``, ``truth`` (index of that map), ``pairs`` (scored sample
    pairs), ``within_0.10`` (share of them whose image lies within 0.10 of the true one)
    and ``mean_error`` (capped at :data:`CAP`; None without a scored pair)."""
    out = []
    for rank, record in enumerate(records):
        err = capped_errors(np.asarray(record["pairs"], dtype=np.int64), truths, unit)
        best = int(np.argmin(_mean(err)))
        row = err[best][~np.isnan(err[best])]
        out.append(
            {
                "rank": rank,
                "truth": best,
                "pairs": len(row),
                "within_0.10": round(float(np.mean(row <= WITHIN)), 6) if len(row) else None,
                "mean_error": round(float(np.mean(row)), 6) if len(row) else None,
            }
        )
    return out


def group_report(
    truths: Sequence[PartialTruth],
    predicted: np.ndarray | None,
    records: Sequence[Mapping[str, Any]],
    shape: Shape,
) -> tuple[int, dict[str, Any]]:
    """The true map the scores of :func:`intrinsym.evaluation.evaluate.evaluation_report` use, and
    the ``"group"`` section of ``scores.json``.

    Parameters
    ----------
    truths : sequence of PartialTruth
        :func:`load_truths`.
    predicted : (N,) int or None
        The found global map (-1: no image); None without one (the first map is used).
    records : sequence of mapping
        The extracted symmetries (``symmetries.json`` entries).
    shape : Shape

    Returns
    -------
    nearest : int
        Index of the true map nearest to ``predicted``.
    group : dict
        ``maps`` (K), ``nearest`` and ``symmetries`` (:func:`symmetry_scores`).
    """
    maps = np.stack([t.partner for t in truths])
    unit = geodesics.unit_area_graph(shape) if len(maps) > 1 or records else None
    nearest = 0 if predicted is None or unit is None else nearest_map(predicted, maps, unit)
    scores = symmetry_scores(records, maps, unit) if unit is not None else []
    return nearest, {"maps": len(maps), "nearest": nearest, "symmetries": scores}


def group_lines(group: Mapping[str, Any], shown: int = 5) -> list[str]:
    """What ``intrinsym evaluate`` prints of :func:`group_report`'s section: the map the
    scores used (with several) and the best ``shown`` symmetries against their nearest maps."""
    lines = []
    if group["maps"] > 1:
        lines.append(
            f"ground truth: {group['maps']} true maps; the scores above use map {group['nearest']}, the nearest"
        )
    for s in group["symmetries"][:shown]:
        if s["pairs"]:
            lines.append(
                f"symmetry {s['rank'] + 1}: nearest true map {s['truth']}, {s['within_0.10']:.3f} of its "
                f"{s['pairs']} sample pairs within 0.10 sqrt(area), mean error {s['mean_error']:.3f} sqrt(area)"
            )
    return lines
