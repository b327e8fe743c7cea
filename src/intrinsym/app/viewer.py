"""A self-contained interactive HTML viewer of a saved result (``intrinsym view OUT``).

One file, no network access needed: the page (``static/viewer.html``, a small
hand-written WebGL2 viewer) gets the mesh, the marginals
(:meth:`~intrinsym.result.result.Result.mixed_marginals`: a match's two modes, each
with its confidence), the per-vertex weights of
Eq. 9, the symmetries and the run's parameters and scores inlined as zlib-compressed
base64 arrays, which the browser inflates with its built-in ``DecompressionStream``.

The page opens on two views of the mesh: the best symmetry (:func:`best_symmetry`), a
few of its sample pairs marked by same-coloured discs (:func:`pair_marks`), beside the
marginal of the source sample ``intrinsym render`` shows
(:func:`intrinsym.app.viz.default_source`), the camera facing that marginal's top. Its run
panel groups sizes, seconds, BP and the main parameters, the rest folded
(:func:`run_panel`).

Sizes: marginals are stored as uint8 per row, scaled so each row's maximum is 255 (the
heat map is max-normalised anyway); each vertex keeps its ``k`` nearest target samples
with uint8 Gaussian weights, so a click costs N x k multiply-adds in the browser.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
import zlib
from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import InputError
from ..evaluation.evaluate import load_confidence, load_symmetry_map
from ..extract.records import part_vertices
from ..files import atomic_write
from ..mesh.shape import Shape
from ..result import coloring
from ..result.result import Result
from . import viz

MAX_SYMMETRIES = 20
"""The viewer lists at most this many symmetries (the best ranked, and the one shown first)."""

MAX_MARKS = 12
"""Sample pairs marked on the symmetry shown alone (same-coloured discs on a pair's two ends)."""

ALIKE = 0.9
"""Two symmetries of one kind whose parts overlap this much (IoU) are listed as one."""

MAIN_PARAMETERS = ("n_source", "n_target", "unary", "schedule", "trivial_weight", "peak_threshold", "d_error")
"""The parameters the run panel shows unfolded; the others are folded."""


def pack(array: np.ndarray) -> str:
    """zlib-compressed, base64-encoded bytes of an array (native little-endian order).

    Parameters
    ----------
    array : ndarray

    Returns
    -------
    str
    """
    return base64.b64encode(zlib.compress(np.ascontiguousarray(array).tobytes(), 6)).decode("ascii")


def quantize_rows(marginals: np.ndarray) -> np.ndarray:
    """(S, T) uint8: every row scaled so that its maximum is 255, then rounded.

    Parameters
    ----------
    marginals : (S, T) array_like

    Returns
    -------
    (S, T) uint8
    """
    m = np.asarray(marginals, dtype=np.float64)
    top = m.max(axis=1, keepdims=True)
    return np.rint(255.0 * m / np.where(top > 0, top, 1.0)).astype(np.uint8)


def part_masks(records: Sequence[Mapping[str, Any]], n_vertices: int) -> np.ndarray:
    """(len(records), N) uint8: bit 0 = vertex in the source part, bit 1 = in the image.

    Parameters
    ----------
    records : sequence of dict
        ``symmetries.json`` entries.
    n_vertices : int

    Returns
    -------
    (len(records), N) uint8
    """
    out = np.zeros((len(records), n_vertices), dtype=np.uint8)
    for row, rec in zip(out, records):
        part, image = part_vertices(rec)
        row[part] |= 1
        row[image] |= 2
    return out


def best_symmetry(records: Sequence[Mapping[str, Any]]) -> int:
    """Index of the symmetry the page shows first.

    The global symmetry when there is one, else ``detect``'s partial symmetry map (kind
    "self map"), else the highest-scoring symmetry that is not the identity (the
    highest-scoring one when all are).

    Parameters
    ----------
    records : sequence of dict
        ``symmetries.json`` entries (``kind``, ``score``).

    Returns
    -------
    int
        -1 when ``records`` is empty.
    """
    kinds = [rec.get("kind") for rec in records]
    for dominant in ("global", "self map"):
        if dominant in kinds:
            return kinds.index(dominant)
    candidates = [i for i, kind in enumerate(kinds) if kind != "identity"] or list(range(len(records)))
    return max(candidates, key=lambda i: float(records[i].get("score", 0.0)), default=-1)


def shown_symmetries(records: Sequence[Mapping[str, Any]]) -> tuple[list[int], int]:
    """Indices of the listed symmetries, and the position of the best among them.

    The first :data:`MAX_SYMMETRIES`; the best (:func:`best_symmetry`) takes the last
    place when it ranks below them.

    Parameters
    ----------
    records : sequence of dict

    Returns
    -------
    indices : list of int
        Into ``records``.
    best : int
        Into ``indices``; -1 when ``records`` is empty.
    """
    best = best_symmetry(records)
    indices = list(range(min(len(records), MAX_SYMMETRIES)))
    if best >= MAX_SYMMETRIES:
        indices[-1] = best
    return indices, indices.index(best) if best >= 0 else -1


def pair_marks(record: Mapping[str, Any], vertices: np.ndarray, n: int = MAX_MARKS) -> list[list[int]]:
    """Up to ``n`` sample pairs of a symmetry, spread over its source part.

    Farthest-point order over the pairs' source vertices, from the first pair.

    Parameters
    ----------
    record : dict
        A ``symmetries.json`` entry (``pairs``: [source vertex, target vertex]).
    vertices : (N, 3) array_like
        The mesh's vertices.
    n : int

    Returns
    -------
    list of [int, int]
        [source vertex, target vertex] per chosen pair.
    """
    pairs = np.asarray(record.get("pairs", []), dtype=np.int64).reshape(-1, 2)
    if not len(pairs) or n < 1:
        return []
    points = np.asarray(vertices, dtype=np.float64)[pairs[:, 0]]
    chosen = [0]
    distance = np.linalg.norm(points - points[0], axis=1)
    while len(chosen) < min(n, len(pairs)) and distance.max() > 0:
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return pairs[chosen].tolist()


def _flatten(value: Any, prefix: str = "") -> dict[str, Any]:
    """Nested dicts as one dict with dotted keys; None entries left out."""
    if not isinstance(value, Mapping):
        return {} if value is None else {prefix: value}
    out: dict[str, Any] = {}
    for key, item in value.items():
        out.update(_flatten(item, f"{prefix}.{key}" if prefix else str(key)))
    return out


def run_panel(result: Result, n_vertices: int) -> dict[str, dict[str, Any]]:
    """The run panel's groups: what the page shows of ``run.json``.

    Parameters
    ----------
    result : Result
    n_vertices : int
        Vertices of the mesh shown.

    Returns
    -------
    dict
        ``sizes`` (|Ps|, |Pt|, edges, mesh vertices), ``seconds`` (per stage and the
        total), ``bp`` (backend, iterations, converged), ``parameters``
        (:data:`MAIN_PARAMETERS`) and ``more`` (everything else, dotted keys, folded
        on the page); each maps a row label to its value.
    """
    info = dataclasses.asdict(result.info)
    sizes, seconds, bp = info.pop("sizes"), info.pop("seconds"), info.pop("bp")
    params = {key: value for key, value in vars(result.params).items() if value is not None}
    bp_shown = ("backend", "iterations", "converged")
    more = {
        **_flatten(info),
        **_flatten({k: v for k, v in sizes.items() if k not in ("source", "target", "edges")}, "sizes"),
        **_flatten({k: v for k, v in bp.items() if k not in (*bp_shown, "history")}, "bp"),
        **{k: v for k, v in params.items() if k not in MAIN_PARAMETERS},
    }
    return {
        "sizes": {
            "|Ps|": sizes["source"],
            "|Pt|": sizes["target"],
            "edges": sizes["edges"],
            "mesh vertices": n_vertices,
        },
        "seconds": {**seconds, "total": sum(seconds.values())},
        "bp": {key: bp[key] for key in bp_shown},
        "parameters": {key: params.get(key) for key in MAIN_PARAMETERS},
        "more": more,
    }


def _overlaps(a: np.ndarray, b: np.ndarray, share: float) -> bool:
    """Whether two non-empty vertex masks share at least ``share`` of their union."""
    union = int(np.count_nonzero(a | b))
    return union > 0 and int(np.count_nonzero(a & b)) >= share * union


def merge_alike(records: Sequence[Mapping[str, Any]], n_vertices: int, overlap: float = ALIKE) -> list[list[int]]:
    """Groups of symmetries the same within a tolerance, for display: each group holds a
    symmetry (the best ranked first) and those of the same kind below it whose source
    part and image part each overlap its own by at least ``overlap`` (intersection over
    union of the input vertices).

    Parameters
    ----------
    records : sequence of dict
        ``symmetries.json`` entries, in rank order.
    n_vertices : int
    overlap : float

    Returns
    -------
    list of list of int
        Indices into ``records``, in rank order of each group's first.
    """
    masks = part_masks(records, n_vertices)
    groups: list[list[int]] = []
    for i, rec in enumerate(records):
        for group in groups:
            j = group[0]
            if records[j].get("kind") != rec.get("kind"):
                continue
            if all(_overlaps((masks[j] & bit) > 0, (masks[i] & bit) > 0, overlap) for bit in (1, 2)):
                group.append(i)
                break
        else:
            groups.append([i])
    return groups


def _symmetry_data(symmetries: Sequence[Mapping[str, Any]], vertices: np.ndarray) -> dict[str, Any]:
    """The page's symmetry list (self-matching; those alike merged, :func:`merge_alike`),
    part masks and the one shown first."""
    groups = merge_alike(symmetries, len(vertices))
    # the best stays listed: a group holding it is shown by it
    best_index = best_symmetry(symmetries)
    kept = [best_index if best_index in group else group[0] for group in groups]
    alike = {k: len(group) - 1 for k, group in zip(kept, groups)}
    merged = [symmetries[i] for i in kept]
    positions, best = shown_symmetries(merged)
    indices = [kept[p] for p in positions]
    shown = [symmetries[i] for i in indices]
    return {
        "parts": pack(part_masks(shown, len(vertices))),
        "symmetries": [
            {
                "rank": i + 1,
                "kind": s.get("kind", "?"),
                "score": float(s.get("score", 0.0)),
                "n_pairs": len(s.get("pairs", [])),
                "marks": pair_marks(s, vertices),
                "alike": alike[i],
            }
            for i, s in zip(indices, shown)
        ],
        "symmetries_note": "none: symmetries.json is absent",
        "initial_symmetry": best,
    }


def _weight_data(result: Result, shape: Shape, k: int) -> dict[str, Any]:
    """The Eq. 9 interpolation: each vertex's ``k`` nearest targets and uint8 weights."""
    sigma = viz.target_spacing(result.target_points)
    index, weight = viz.gaussian_weights(shape.vertices, result.target_points, sigma, k)
    index_type = np.uint16 if len(result.target_points) <= np.iinfo(np.uint16).max + 1 else np.uint32
    return {
        "k": index.shape[1],
        "index_bytes": np.dtype(index_type).itemsize,
        "weight_index": pack(index.astype(index_type)),
        "weight_value": pack(np.rint(255.0 * weight).astype(np.uint8)),
    }


def payload(
    result: Result,
    shape: Shape,
    symmetries: list[dict],
    scores: dict | None,
    up: str = "y",
    k: int = 12,
    confidence: np.ndarray | None = None,
    symmetry_map: np.ndarray | None = None,
) -> dict:
    """Everything the page needs, JSON-ready.

    Parameters
    ----------
    result : Result
    shape : Shape
        The mesh the marginals live on (the target shape), input coordinates.
    symmetries : list of dict
        ``symmetries.json`` entries (vertex indices of ``shape``); see
        :func:`shown_symmetries` for those listed.
    scores : dict or None
        ``scores.json``, when the run was evaluated.
    up : {"x", "y", "z"}
        World axis shown upwards at first.
    k : int
        Target samples per vertex in the Eq. 9 interpolation.
    confidence : (N,) float array or None
        ``symmetry_confidence.npy``: the page can colour the symmetry view by it.
    symmetry_map : (N,) int array or None
        ``symmetry_map.npy``: the page opens on it, each side in its colour or each point
        coloured like its partner (:func:`map_data`).

    Returns
    -------
    dict
        ``initial_source`` (:func:`intrinsym.app.viz.default_source`) and
        ``initial_symmetry`` (into ``symmetries``, -1 for none) are the page's state on
        load; ``run`` is :func:`run_panel`.

    Raises
    ------
    InputError
        When ``shape`` is a point cloud.
    """
    if shape.faces is None:
        raise InputError(f"{shape.path}: the viewer needs a triangle mesh, not a point cloud")
    self_match = result.info.mode != "match"
    data: dict[str, Any] = {
        "name": Path(shape.path).name,
        "self_match": self_match,
        "up_frame": viz.UP_FRAMES[up].ravel().tolist(),
        "n_source": len(result.source_points),
        "n_target": len(result.target_points),
        "positions": pack(shape.vertices.astype(np.float32)),
        "faces": pack(shape.faces.astype(np.uint32)),
        "source_points": pack(result.source_points.astype(np.float32)),
        "marginals": pack(quantize_rows(result.mixed_marginals())),
        **_weight_data(result, shape, k),
        **_symmetry_data(symmetries if self_match else [], shape.vertices),
        "initial_source": viz.default_source(result),
        "run": run_panel(result, len(shape.vertices)),
        "scores": scores,
    }
    if self_match and symmetry_map is not None and (symmetry_map >= 0).any():
        data.update(map_data(shape, symmetry_map))
    if self_match and confidence is not None and len(confidence) == len(shape.vertices) and confidence.any():
        data["confidence"] = pack(np.asarray(confidence, dtype=np.float32))
        data["global_confidence"] = float(np.mean(confidence))
    if not self_match:
        data["symmetries_note"] = "not shown for two-shape matching"
    return data


def map_data(shape: Shape, symmetry_map: np.ndarray) -> dict[str, Any]:
    """The global symmetry map's colours (:func:`intrinsym.result.coloring.vertex_colors`: ``side``
    and ``partner``, uint8 RGB per vertex), the legend of each colouring, its counts and
    ``map_axis``, the mean direction from a point of one side to its image (the camera
    opens across it, both sides in view)."""
    side = coloring.sides(shape, symmetry_map)
    one = np.flatnonzero(side == 0)
    across = np.mean(shape.vertices[one] - shape.vertices[symmetry_map[one]], axis=0) if len(one) else np.zeros(3)
    colors = {"side": coloring.side_colors(side), "partner": coloring.vertex_colors(shape, symmetry_map, "partner")}
    return {
        "map_colors": {mode: pack(np.round(255 * rgb).astype(np.uint8)) for mode, rgb in colors.items()},
        "legends": {
            mode: [[label, coloring.hex_color(rgb)] for label, rgb in coloring.legend(mode)] for mode in coloring.MODES
        },
        "map_axis": (across / max(float(np.linalg.norm(across)), 1e-300)).tolist(),
        "map_counts": {
            "vertices": len(side),
            "no partner": int(np.count_nonzero(side == -1)),
            "fixed": int(np.count_nonzero(side == 2)),
        },
    }


#: How the page gets a number JSON cannot hold (its JSON parser rejects ``NaN``).
NOT_FINITE = {math.inf: "Infinity", -math.inf: "-Infinity"}


def _finite(value: Any) -> Any:
    """``value`` (JSON-ready) with every float that is not finite as a string: "NaN",
    "Infinity" or "-Infinity" (:data:`NOT_FINITE`)."""
    if isinstance(value, float) and not math.isfinite(value):
        return NOT_FINITE.get(value, "NaN")
    if isinstance(value, Mapping):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(item) for item in value]
    return value


def render_html(data: dict) -> str:
    """The page with ``data`` inlined: strict JSON (numbers that are not finite as
    strings, :func:`_finite`) with every ``<`` escaped.

    Parameters
    ----------
    data : dict
        :func:`payload`.

    Returns
    -------
    str
    """
    template = resources.files("intrinsym.app").joinpath("static/viewer.html").read_text(encoding="utf-8")
    text = json.dumps(_finite(data), separators=(",", ":"), allow_nan=False)
    # "<" occurs in JSON only inside strings, where "\u003c" is the same character; a
    # "<" there could end the <script> element ("</script") or change how the browser
    # reads it ("<!--<script>").
    return template.replace("__DATA__", text.replace("<", "\\u003c"))


def write(
    out_dir: str | Path,
    html_path: str | Path | None = None,
    mesh_path: str | Path | None = None,
    up: str = "y",
) -> Path:
    """Write the viewer of a saved result; returns the HTML path.

    Parameters
    ----------
    out_dir : path
        Directory written by ``Result.save`` (``symmetries.json``, ``scores.json``,
        ``symmetry_map.npy`` and ``symmetry_confidence.npy`` are used when present).
    html_path : path, optional
        Default ``out_dir/viewer.html``.
    mesh_path : path, optional
        See :func:`intrinsym.app.viz.load_shapes`.
    up : {"x", "y", "z"}

    Returns
    -------
    Path
    """
    out = Path(out_dir)
    result = Result.load(out)
    shape, _ = viz.load_shapes(result, mesh_path)
    scores_path = out / "scores.json"
    try:
        scores = json.loads(scores_path.read_text()) if scores_path.is_file() else None
    except (OSError, ValueError) as err:
        raise InputError(f"{scores_path}: cannot read it ({err}); run intrinsym evaluate again") from None
    conf_path = out / "symmetry_confidence.npy"
    conf = load_confidence(conf_path, len(shape.vertices)) if conf_path.is_file() else None
    map_path = out / "symmetry_map.npy"
    found = load_symmetry_map(map_path, len(shape.vertices), allow_missing=True) if map_path.is_file() else None
    html = render_html(
        payload(result, shape, viz.load_symmetries(out), scores, up, confidence=conf, symmetry_map=found)
    )
    path = Path(html_path) if html_path is not None else out / "viewer.html"

    def write_html(f: IO[str]) -> None:
        f.write(html)

    atomic_write(path, write_html)
    return path
