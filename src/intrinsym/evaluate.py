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
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from . import geodesics, mesh
from .files import atomic_write


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


def load_symmetry_map(path: str | os.PathLike, n_vertices: int | None = None) -> np.ndarray:
    """Read a symmetry map as a 0-based (N,) int64 array.

    Formats: TOSCA ``.sym`` (one 1-based index per line), KIDS ``sym.txt`` (1-based
    indices in ``%e`` notation, any whitespace) and ``.npy`` (0-based integers).

    Raises
    ------
    mesh.InputError
        On unreadable files, non-integers or indices out of range.
    """
    p = Path(path)
    try:
        if p.suffix.lower() == ".npy":
            raw = np.load(p, allow_pickle=False)
            values, base = np.asarray(raw).ravel(), 0
        else:
            values, base = np.array(p.read_text().split(), dtype=np.float64), 1
    except (OSError, ValueError) as err:
        raise mesh.InputError(f"{path}: cannot read a symmetry map ({err})") from None
    if values.size == 0:
        raise mesh.InputError(f"{path}: empty symmetry map")
    if not np.all(np.isfinite(values)) or np.any(values != np.round(values)):
        raise mesh.InputError(f"{path}: symmetry map holds non-integer entries")
    sym = values.astype(np.int64) - base
    if n_vertices is not None and len(sym) != n_vertices:
        raise mesh.InputError(f"{path}: symmetry map has {len(sym)} entries, the mesh {n_vertices} vertices")
    if sym.min() < 0 or sym.max() >= len(sym):
        raise mesh.InputError(f"{path}: symmetry map index out of range")
    return sym


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
    shape: mesh.Shape,
    sym: np.ndarray,
    seed: int = 0,
    near: float = 0.10,
    peak: float = 0.05,
) -> MarginalScores:
    """Score marginals on the input mesh they were computed on.

    Parameters
    ----------
    marginals : (S, T) array
    source_vertex, target_vertex : (S,), (T,) int
        Input-mesh vertex of every source and target sample.
    shape : mesh.Shape
        The input mesh (as loaded; it is cleaned and normalised to unit area here).
    sym : (N_in,) int
        Ground-truth symmetric image of every input vertex.
    seed : int
        Seed of the decoy choice.
    """
    cleaned, vmap = mesh.clean(shape)
    area = mesh.surface_area(cleaned)
    graph = geodesics.surface_graph(cleaned.vertices / np.sqrt(area), cleaned.faces)
    src = vmap[np.asarray(source_vertex)]
    tgt = vmap[np.asarray(target_vertex)]
    mir = vmap[np.asarray(sym)[source_vertex]]
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


def save_scores(scores: MarginalScores, path: str | os.PathLike) -> None:
    """Write the scores as JSON (atomically)."""
    atomic_write(path, lambda f: json.dump(scores.as_dict(), f, indent=2))
