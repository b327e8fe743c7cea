"""The two answers of a match: the best map and the best map up to the symmetry.

Matching two shapes with an intrinsic symmetry has (at least) two right answers, the
identity and the symmetric swap; BP's marginals may hold both, or settle on one. Instead
of one map, :func:`two_modes` reports both: mode 0 is the result's map
(:meth:`~intrinsym.result.result.Result.symmetry_map`), mode 1 the best map up to the
symmetry. Given the target's own symmetry map (``Result.target_symmetry``, e.g. a
``detect`` of the target: it is computed once per target and reused for every shape
matched to it), mode 1 is that symmetry applied after mode 0. Without it, mode 1 is the
best map that sends most source samples far from where mode 0 does: the best-ranked
extracted symmetry of that kind, else each sample's strongest target away from mode 0's
image; BP's first pass mostly settles on one answer (docs/limitations.md), and this
map is right on far fewer vertices than the composed one. Each mode gets a
quality from the model itself, which does not favour a mode because BP settled on it
(the mean unary at the mode's images times the share of source edges whose length the
mode keeps), and the two confidences are the qualities' shares: a symmetric pair gets
about one half each. Lengths in units of sqrt(area).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..extract.extract import consistency, normalise_rows
from ..extract.support import SourceGraph
from ..extract.symmetry import Symmetry
from ..globalmap.confidence import sample_images

if TYPE_CHECKING:
    from .result import Result

#: Two maps are apart at a sample when its images lie farther than this apart.
APART = 0.1
#: A mode with at least this share of the two qualities is an answer in its own right.
BOTH_SHARE = 0.1


@dataclass(frozen=True)
class Modes:
    """The two answers of a match and how far each is to be believed.

    Attributes
    ----------
    maps : (2, N_a) int64
        Per input vertex of the source shape, its image vertex on the target under each
        mode; -1 where the mode says nothing (mode 1 everywhere when there is none).
    images : (2, S) int64
        Target sample of every source sample under each mode, -1 for none.
    quality : (2,) float64
        Mean max-normalised unary at the mode's images times the share of source edges
        whose length it keeps (within ``d_error``); 0 for a missing mode.
    confidence : (2,) float64
        ``quality`` over its sum: the share of the evidence for each mode.
    """

    maps: np.ndarray
    images: np.ndarray
    quality: np.ndarray
    confidence: np.ndarray

    @property
    def both(self) -> bool:
        """Whether the second mode holds at least :data:`BOTH_SHARE` of the evidence."""
        return bool(self.confidence[1] >= BOTH_SHARE)

    def as_dict(self) -> dict:
        """``modes.json``'s content."""
        return {
            "quality": [float(q) for q in self.quality],
            "confidence": [float(c) for c in self.confidence],
            "both": self.both,
            "apart": APART,
        }


def _apart(result: Result, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(S,) bool: samples both map whose images lie farther than :data:`APART` apart."""
    assert result.support is not None
    t = result.support.targets
    out = np.zeros(len(first), dtype=bool)
    for s in np.flatnonzero((first >= 0) & (second >= 0)):
        lo, hi = t.indptr[first[s]], t.indptr[first[s] + 1]
        near = t.indices[lo:hi][t.dist[lo:hi] <= APART]
        out[s] = second[s] not in near
    return out


def _away(result: Result, image: np.ndarray) -> np.ndarray:
    """(S,) int64: each sample's strongest target (first-pass marginal) farther than
    :data:`APART` from ``image``."""
    assert result.support is not None
    t = result.support.targets
    m = np.array(result.marginals, dtype=np.float64)
    for s in np.flatnonzero(image >= 0):
        lo, hi = t.indptr[image[s]], t.indptr[image[s] + 1]
        m[s, t.indices[lo:hi][t.dist[lo:hi] <= APART]] = -1.0
    return m.argmax(axis=1).astype(np.int64)


def _quality(result: Result, image: np.ndarray, graph: SourceGraph) -> float:
    assert result.support is not None
    mapped = np.flatnonzero(image >= 0)
    if not len(mapped):
        return 0.0
    unary = normalise_rows(np.asarray(result.unary, dtype=np.float64))
    kept = consistency(image, graph, result.support.targets, result.params.d_error)
    return float(unary[mapped, image[mapped]].sum() / len(image) * kept)


def _composed(result: Result, symmetry: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mode 0's map and the target's ``symmetry`` applied after it, as (2, N_a) vertex
    maps and (2, S) sample images."""
    first = result.symmetry_map()
    second = np.where(first >= 0, symmetry[np.maximum(first, 0)], -1).astype(np.int64)
    maps = np.stack([first, second])
    assert result.support is not None
    cells = result.support.vertex_target
    return maps, np.stack([sample_images(m, result.source_point_vertex, cells) for m in maps])


def two_modes(result: Result) -> Modes:
    """The best map of a result and the best map up to the symmetry, with their confidences.

    Parameters
    ----------
    result : Result
        With ``support`` and ``extraction`` (a run's, or after
        :func:`intrinsym.pipeline.extract_result`).

    Returns
    -------
    Modes
    """
    if result.support is None or result.extraction is None:
        raise ValueError("the result has no extraction")
    n_s = len(result.source_points)
    graph = SourceGraph.from_edges(result.edges, result.support.edge_length, n_s)
    if result.target_symmetry is not None:
        maps, images = _composed(result, np.asarray(result.target_symmetry, dtype=np.int64))
        return _rated(result, maps, images, graph)
    best = result.extraction.global_symmetry
    first = best.image(n_s) if best is not None else np.asarray(result.marginals).argmax(axis=1).astype(np.int64)
    second = None
    for sym in result.extraction.symmetries:
        image = sym.image(n_s)
        if sym is not best and _apart(result, first, image).sum() * 2 > min((first >= 0).sum(), (image >= 0).sum()):
            second = image
            break
    if second is None:
        second = _away(result, first)
    source = np.flatnonzero(second >= 0)
    maps = np.stack([result.symmetry_map(), result.fitted_map(Symmetry(source, second[source], 0.0, 1.0, "partial"))])
    return _rated(result, maps, np.stack([first, second]), graph)


def _rated(result: Result, maps: np.ndarray, images: np.ndarray, graph: SourceGraph) -> Modes:
    """The two modes with the qualities and confidences of their sample ``images``."""
    quality = np.array([_quality(result, image, graph) for image in images])
    total = quality.sum()
    confidence = quality / total if total > 0 else np.array([1.0, 0.0])
    return Modes(maps, images, quality, confidence)
