"""A self-contained interactive HTML viewer of a saved result (``intrinsym view OUT``).

One file, no network access needed: the page (``static/viewer.html``, a small
hand-written WebGL2 viewer) gets the mesh, the marginals, the per-vertex weights of
Eq. 9, the symmetries and the run's parameters and scores inlined as zlib-compressed
base64 arrays, which the browser inflates with its built-in ``DecompressionStream``.

Sizes: marginals are stored as uint8 per row, scaled so each row's maximum is 255 (the
heat map is max-normalised anyway); each vertex keeps its ``k`` nearest target samples
with uint8 Gaussian weights, so a click costs N x k multiply-adds in the browser.
"""

from __future__ import annotations

import base64
import json
import zlib
from importlib import resources
from pathlib import Path

import numpy as np

from . import mesh, viz
from .files import atomic_write
from .pipeline import Result

MAX_SYMMETRIES = 20
"""The viewer lists at most this many symmetries (the best ranked)."""


def pack(array: np.ndarray) -> str:
    """zlib-compressed, base64-encoded bytes of an array (native little-endian order)."""
    return base64.b64encode(zlib.compress(np.ascontiguousarray(array).tobytes(), 6)).decode("ascii")


def quantize_rows(marginals: np.ndarray) -> np.ndarray:
    """(S, T) uint8: every row scaled so that its maximum is 255, then rounded."""
    m = np.asarray(marginals, dtype=np.float64)
    top = m.max(axis=1, keepdims=True)
    return np.rint(255.0 * m / np.where(top > 0, top, 1.0)).astype(np.uint8)


def part_masks(records: list[dict], n_vertices: int) -> np.ndarray:
    """(len(records), N) uint8: bit 0 = vertex in the source part, bit 1 = in the image."""
    out = np.zeros((len(records), n_vertices), dtype=np.uint8)
    for row, rec in zip(out, records):
        row[np.asarray(rec["source_vertices"], dtype=np.int64)] |= 1
        row[np.asarray(rec["target_vertices"], dtype=np.int64)] |= 2
    return out


def payload(
    result: Result,
    shape: mesh.Shape,
    symmetries: list[dict],
    scores: dict | None,
    up: str = "y",
    k: int = 12,
) -> dict:
    """Everything the page needs, JSON-ready.

    Parameters
    ----------
    result : Result
    shape : mesh.Shape
        The mesh the marginals live on (the target shape), input coordinates.
    symmetries : list of dict
        ``symmetries.json`` entries (vertex indices of ``shape``); the first
        :data:`MAX_SYMMETRIES` are shown.
    scores : dict or None
        ``scores.json``, when the run was evaluated.
    up : {"x", "y", "z"}
        World axis shown upwards at first.
    k : int
        Target samples per vertex in the Eq. 9 interpolation.
    """
    n_target = len(result.target_points)
    sigma = viz.target_spacing(result.target_points)
    index, weight = viz.gaussian_weights(shape.vertices, result.target_points, sigma, k)
    index_type = np.uint16 if n_target <= np.iinfo(np.uint16).max + 1 else np.uint32
    shown = symmetries[:MAX_SYMMETRIES]
    self_match = result.info.get("mode") != "match"
    run = {key: result.info.get(key) for key in ("mode", "input", "target_input", "preset", "sizes", "seconds")}
    run["bp"] = {key: value for key, value in result.info.get("bp", {}).items() if key != "history"}
    run["params"] = {key: value for key, value in vars(result.params).items() if value is not None}
    note = "none: symmetries.json is absent" if not symmetries else ""
    return {
        "name": Path(shape.path).name,
        "self_match": self_match,
        "up_frame": viz.UP_FRAMES[up].ravel().tolist(),
        "n_source": len(result.source_points),
        "n_target": n_target,
        "k": index.shape[1],
        "index_bytes": np.dtype(index_type).itemsize,
        "positions": pack(shape.vertices.astype(np.float32)),
        "faces": pack(shape.faces.astype(np.uint32)),
        "source_points": pack(result.source_points.astype(np.float32)),
        "marginals": pack(quantize_rows(result.marginals)),
        "weight_index": pack(index.astype(index_type)),
        "weight_value": pack(np.rint(255.0 * weight).astype(np.uint8)),
        "parts": pack(part_masks(shown, len(shape.vertices)) if self_match else np.zeros(0, np.uint8)),
        "symmetries": [
            {"kind": s.get("kind", "?"), "score": float(s.get("score", 0.0)), "n_pairs": len(s.get("pairs", []))}
            for s in (shown if self_match else [])
        ],
        "symmetries_note": note or "not shown for two-shape matching",
        "run": run,
        "scores": scores,
    }


def render_html(data: dict) -> str:
    """The page with ``data`` inlined."""
    template = resources.files("intrinsym").joinpath("static/viewer.html").read_text(encoding="utf-8")
    # "</" inside the JSON would end the <script> element; "<\/" is the same JSON string.
    return template.replace("__DATA__", json.dumps(data, separators=(",", ":")).replace("</", "<\\/"))


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
        Directory written by ``Result.save`` (``symmetries.json`` and ``scores.json``
        are used when present).
    html_path : path, optional
        Default ``out_dir/viewer.html``.
    mesh_path : path, optional
        See :func:`intrinsym.viz.load_shapes`.
    up : {"x", "y", "z"}
    """
    out = Path(out_dir)
    result = Result.load(out)
    shape, _ = viz.load_shapes(result, mesh_path)
    if shape.is_cloud:
        raise mesh.InputError(f"{shape.path}: the viewer needs a triangle mesh, not a point cloud")
    scores_path = out / "scores.json"
    scores = json.loads(scores_path.read_text()) if scores_path.is_file() else None
    html = render_html(payload(result, shape, viz.load_symmetries(out), scores, up))
    path = Path(html_path) if html_path is not None else out / "viewer.html"
    atomic_write(path, lambda f: f.write(html))
    return path
