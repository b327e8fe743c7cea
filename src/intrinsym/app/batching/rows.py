"""One summary row per item, from a result in memory or from its folder, and the
scores of ``intrinsym evaluate`` against a ground truth.

A row is a flat dict of plain values (str, int, float, bool, None), one column per
key; :data:`COLUMNS` orders them in the table (the ``seconds_<stage>`` columns follow
``seconds``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import IntrinsymError
from ...evaluation import evaluate, symmetry_group
from ...mesh.io import load
from ...result.result import Result, saved_global_confidence
from ...result.runinfo import RunInfo
from .items import Item, stored_key

#: Columns of the summary, in order (stage seconds are inserted after "seconds").
COLUMNS = (
    "name",
    "class",
    "mode",
    "input",
    "target_input",
    "key",
    "status",
    "error",
    "worker",
    "vertices",
    "working_vertices",
    "n_source",
    "n_target",
    "edges",
    "seconds",
    "wall_seconds",
    "peak_memory_mb",
    "bp_iterations",
    "bp_converged",
    "bp_max_change",
    "symmetries",
    "global_symmetry",
    "global_score",
    "global_confidence",
    "mirror_hit",
    "peak_recall",
    "decoy_recall",
    "breadth",
    "map_within_0.05",
    "map_within_0.10",
    "map_area_within_0.05",
    "map_area_within_0.10",
    "map_mean_error",
    "map_coverage",
    "map_distortion",
    "truth_distortion",
    "confidence_ece",
)
#: Per-vertex arrays of a result folder, one value per input vertex.
VERTEX_ARRAYS = ("symmetry_map.npy", "symmetry_mass.npy", "symmetry_confidence.npy")
#: Scores of ``intrinsym evaluate`` that become columns: marginal scores, then the map's.
MARGINAL_SCORES = ("mirror_hit", "peak_recall", "decoy_recall", "breadth")
MAP_SCORES = ("within_0.05", "within_0.10", "area_within_0.05", "area_within_0.10", "mean_error", "coverage")


def base_row(item: Item, key: str, status: str, error: str | None = None) -> dict[str, Any]:
    """The columns every row has, whatever became of the item."""
    return {
        "name": item.name,
        "class": item.group,
        "mode": item.mode,
        "input": item.mesh,
        "target_input": item.target,
        "key": key,
        "status": status,
        "error": error,
    }


def result_row(
    item: Item,
    key: str,
    status: str,
    info: RunInfo,
    symmetries: Sequence[tuple[str, float]],
    vertices: int | None,
    scores: dict[str, Any] | None,
    global_confidence: float | None = None,
) -> dict[str, Any]:
    """The row of a finished item.

    Parameters
    ----------
    item : Item
    key : str
        Its content key.
    status : {"done", "skipped"}
    info : RunInfo
    symmetries : sequence of (kind, score)
        The extracted symmetries, best first.
    vertices : int or None
        Vertices of the (source) input mesh.
    scores : dict or None
        ``intrinsym evaluate``'s report (``scores.json``), when there is a ground truth.
    global_confidence : float or None
        The expected share of vertices mapped within 0.05 of their true image
        (:meth:`intrinsym.Result.global_confidence`), when there is a global symmetry.
    """
    row = base_row(item, key, status)
    glob = next((score for kind, score in symmetries if kind == "global"), None)
    row.update(
        vertices=vertices,
        working_vertices=info.sizes.source_working_vertices,
        n_source=info.sizes.source,
        n_target=info.sizes.target,
        edges=info.sizes.edges,
        seconds=float(sum(info.seconds.values())),
        bp_iterations=info.bp.iterations,
        bp_converged=info.bp.converged,
        bp_max_change=info.bp.max_change,
        symmetries=len(symmetries),
        global_symmetry=glob is not None,
        global_score=glob,
        global_confidence=global_confidence,
    )
    row.update({f"seconds_{stage}": float(value) for stage, value in info.seconds.items()})
    if scores:
        row.update({name: scores.get(name) for name in MARGINAL_SCORES})
        row.update({f"map_{name}": scores.get("map", {}).get(name) for name in MAP_SCORES})
        row["map_distortion"] = scores.get("map", {}).get("distortion", {}).get("above_0.05")
        row["truth_distortion"] = scores.get("truth_distortion", {}).get("above_0.05")
        row["confidence_ece"] = scores.get("confidence", {}).get("expected_calibration_error")
    return row


def row_of_result(item: Item, key: str, result: Result, scores: dict[str, Any] | None) -> dict[str, Any]:
    """:func:`result_row` of a result in memory."""
    found = [] if result.extraction is None else [(s.kind, float(s.score)) for s in result.extraction.symmetries]
    vertices = None if result.support is None else len(result.support.vertex_source)
    return result_row(item, key, "done", result.info, found, vertices, scores, result.global_confidence())


def row_of_folder(item: Item, key: str, folder: Path, status: str = "skipped") -> dict[str, Any]:
    """:func:`result_row` of a complete result folder (``scores.json`` when present)."""
    run = json.loads((folder / "run.json").read_text())
    run.pop("params", None)
    listed = json.loads((folder / "symmetries.json").read_text())
    vertices = len(np.load(folder / "symmetry_map.npy", mmap_mode="r"))
    scores_file = folder / "scores.json"
    scores = json.loads(scores_file.read_text()) if scores_file.is_file() else None
    found = [(str(r["kind"]), float(r["score"])) for r in listed]
    conf = saved_global_confidence(folder, any(kind == "global" for kind, _ in found))
    return result_row(item, key, status, RunInfo.from_dict(run), found, vertices, scores, conf)


def finished_row(item: Item, key: str, folder: Path, status: str = "skipped") -> dict[str, Any] | None:
    """:func:`row_of_folder` of a folder that holds a complete result with the content key
    ``key``; None when it holds none, or when one of its files cannot be read (a
    truncated or overwritten ``symmetry_map.npy`` or ``symmetry_confidence.npy``, one
    per-vertex array of another length than the others): the item is to run again."""
    if stored_key(folder) != key:
        return None
    try:
        row = row_of_folder(item, key, folder, status)
        lengths = {len(np.load(folder / name, mmap_mode="r")) for name in VERTEX_ARRAYS if (folder / name).is_file()}
    except (OSError, ValueError, EOFError, KeyError, TypeError, IntrinsymError):
        return None
    return row if lengths == {row["vertices"]} else None


def score(result: Result, mesh: str, symmetry_map: str, labels: str | None) -> dict[str, Any]:
    """``intrinsym evaluate``'s report of a result (:func:`intrinsym.evaluation.evaluate.evaluation_report`),
    against the nearest of the true maps ``symmetry_map`` holds (:mod:`intrinsym.evaluation.symmetry_group`).

    Parameters
    ----------
    result : Result
    mesh, symmetry_map, labels : str
        Where the mesh, the ground truth and the part labels can be read (the item's own
        paths, or copies of their bytes).
    """
    shape = load(mesh)
    n = len(shape.vertices)
    has_map = result.extraction is not None and result.support is not None
    found = result.symmetry_map() if has_map else None
    truths = symmetry_group.load_truths([symmetry_map], shape)
    nearest, group = symmetry_group.group_report(truths, found, (), shape)
    report, _ = evaluate.evaluation_report(
        result.marginals,
        result.source_point_vertex,
        result.target_point_vertex,
        found,
        shape,
        truths[nearest].partner,
        labels=evaluate.load_labels(labels, n) if labels and has_map else None,
        confidence=result.symmetry_confidence() if has_map else None,
    )
    return {**report, "group": group}
