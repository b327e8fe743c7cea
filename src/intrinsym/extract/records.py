"""The entries of ``symmetries.json``: extracted symmetries in input-vertex indices.

Each entry holds ``kind``, ``score``, ``consistency``, ``source_vertex_index`` and
``target_vertex_index`` (the input vertices of the source part and of its image) and
``pairs`` ([source vertex, target vertex] of every sample pair). Files of format
version 1 named the two vertex lists ``source_vertices`` / ``target_vertices``;
:func:`part_vertices` reads both.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ._kernels import dilate
from .support import Support

if TYPE_CHECKING:
    from .extract import Symmetry

#: Version 2 name of each vertex list and its version 1 name.
VERTEX_LISTS = {"source_vertex_index": "source_vertices", "target_vertex_index": "target_vertices"}


def records(
    symmetries: Sequence[Symmetry],
    source_vertex: np.ndarray,
    target_vertex: np.ndarray,
    support: Support,
) -> list[dict[str, Any]]:
    """JSON-ready symmetries in input-vertex indices (the ``symmetries.json`` entries).

    ``source_vertex_index`` lists the input vertices in the Voronoi cells of the part's
    source samples; ``target_vertex_index`` those in the cells of the target samples
    within half the median source edge of an image sample (the image of a source cell
    is about that wide). ``pairs`` are [source vertex, target vertex] of every sample
    pair.

    Parameters
    ----------
    symmetries : sequence of Symmetry
    source_vertex, target_vertex : (S,), (T,) int64
        Input vertex of every source and target sample.
    support : Support
    """
    t = support.targets
    radius = 0.5 * float(np.median(support.edge_length)) if len(support.edge_length) else 0.0
    out = []
    for sym in symmetries:
        in_source = np.zeros(len(source_vertex) + 1, dtype=bool)
        in_source[sym.source] = True
        near = np.zeros(len(target_vertex) + 1, dtype=bool)
        dilate(near[:-1], sym.target, t.indptr, t.indices, t.dist, radius)
        out.append(
            {
                "kind": sym.kind,
                "score": round(float(sym.score), 6),
                "consistency": round(float(sym.consistency), 6),
                "source_vertex_index": np.flatnonzero(in_source[support.vertex_source]).tolist(),
                "target_vertex_index": np.flatnonzero(near[support.vertex_target]).tolist(),
                "pairs": np.column_stack([source_vertex[sym.source], target_vertex[sym.target]]).tolist(),
            }
        )
    return out


def cut_to_map(record: dict[str, Any], vertex_map: np.ndarray, one_mesh: bool) -> None:
    """Cut a global symmetry's entry to where its vertex map acts, in place.

    A global symmetry's parts are every sample, but its map (``symmetry_map.npy``) leaves
    -1 where a vertex has no partner (the side cut away, a hole's mirror). The source part
    keeps the vertices the map gives an image; on one mesh (``detect``, where a global
    symmetry is its own inverse) the image part keeps them too, so that the parts are the
    region that has its symmetry.

    Parameters
    ----------
    record : dict
        A ``symmetries.json`` entry (:func:`records`).
    vertex_map : (N,) int
        Its vertex map, -1 where it gives no image.
    one_mesh : bool
        Source and image parts index the same mesh.
    """
    mapped = np.asarray(vertex_map) >= 0
    keys = list(VERTEX_LISTS)[: 2 if one_mesh else 1]
    for key in keys:
        part = np.asarray(record[key], dtype=np.int64)
        record[key] = part[mapped[part]].tolist()


def part_vertices(record: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(source part, image part) input-vertex indices of a ``symmetries.json`` entry,
    int64; reads the version 1 key names too."""
    lists = []
    for key, old in VERTEX_LISTS.items():
        values = record[key] if key in record else record[old]
        lists.append(np.asarray(values, dtype=np.int64))
    return lists[0], lists[1]


def part_mask(record: Mapping[str, Any], n: int) -> np.ndarray:
    """(n,) bool: the input vertices of both parts of a ``symmetries.json`` entry."""
    mask = np.zeros(n, dtype=bool)
    for part in part_vertices(record):
        mask[part] = True
    return mask
