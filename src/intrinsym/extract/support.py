"""What symmetry extraction needs beside the marginals, and its arrays in ``result.npz``.

:class:`SourceGraph` is the source graph in CSR form with geodesic edge lengths;
:class:`Support` holds the geodesics and Voronoi cells computed before or for BP, and
converts to and from the arrays stored beside a result's own (:meth:`Support.to_arrays`,
:meth:`Support.from_arrays`). All lengths are in units of sqrt(surface area).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..geodesics.geodesics import SparseDistances


@dataclass(frozen=True)
class SourceGraph:
    """CSR adjacency of the undirected source graph with geodesic edge lengths.

    Attributes
    ----------
    ptr : (S+1,) int64
    neighbour : (2E,) int64
    length : (2E,) float64
    """

    ptr: np.ndarray
    neighbour: np.ndarray
    length: np.ndarray

    @classmethod
    def from_edges(cls, edges: np.ndarray, edge_length: np.ndarray, n_source: int) -> SourceGraph:
        """Build from (E, 2) edges into the source samples and their (E,) lengths."""
        e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        a = np.concatenate([e[:, 0], e[:, 1]])
        b = np.concatenate([e[:, 1], e[:, 0]])
        w = np.concatenate([edge_length, edge_length]).astype(np.float64)
        order = np.lexsort((b, a))
        ptr = np.zeros(n_source + 1, dtype=np.int64)
        np.cumsum(np.bincount(a, minlength=n_source), out=ptr[1:])
        return cls(ptr, b[order], w[order])


@dataclass(frozen=True)
class Support:
    """What extraction needs beside the marginals, all computed before or for BP.

    Attributes
    ----------
    edge_length : (E,) float64
        Geodesic length of every source-graph edge.
    targets : SparseDistances
        Target-target geodesics up to ``targets.radius``, rows sorted by distance.
    vertex_source : (N_a,) int64
        Source sample whose geodesic Voronoi cell holds each input vertex of the source
        shape (-1 where none).
    vertex_target : (N_b,) int64
        The same for the target samples on the target shape.
    self_match : bool
        Source and target are one shape (enables the identity kind).
    source_mesh_vertices, target_mesh_vertices : (N_a, 3), (N_b, 3) float64, optional
        The input mesh coordinates of both shapes, in the frame of the sample positions
        (for :func:`intrinsym.globalmap.vertex_maps.fitted_vertex_map`).
    """

    edge_length: np.ndarray
    targets: SparseDistances
    vertex_source: np.ndarray
    vertex_target: np.ndarray
    self_match: bool
    source_mesh_vertices: np.ndarray | None = None
    target_mesh_vertices: np.ndarray | None = None

    #: Keys always stored.
    KEYS: ClassVar[tuple[str, ...]] = (
        "edge_length",
        "vertex_source",
        "vertex_target",
        "target_distance_indptr",
        "target_distance_index",
        "target_distance",
        "target_distance_radius",
        "self_match",
    )
    #: Keys stored when present.
    OPTIONAL_KEYS: ClassVar[tuple[str, ...]] = ("source_mesh_vertices", "target_mesh_vertices")
    #: Names the optional keys had in format version 1; :meth:`from_arrays` reads them too.
    OLD_KEYS: ClassVar[dict[str, str]] = {
        "source_mesh_vertices": "source_vertices",
        "target_mesh_vertices": "target_vertices",
    }

    def to_arrays(self) -> dict[str, np.ndarray | np.generic]:
        """Arrays to store (under :attr:`KEYS` and :attr:`OPTIONAL_KEYS`) beside a
        result's own arrays; when self-matching, the one shape's vertices are stored once."""
        t = self.targets
        stored = self.OPTIONAL_KEYS[:1] if self.self_match else self.OPTIONAL_KEYS
        arrays: dict[str, np.ndarray | np.generic] = {
            k: np.asarray(getattr(self, k), dtype=np.float64) for k in stored if getattr(self, k) is not None
        }
        return arrays | {
            "edge_length": np.asarray(self.edge_length, dtype=np.float64),
            "vertex_source": np.asarray(self.vertex_source, dtype=np.int64),
            "vertex_target": np.asarray(self.vertex_target, dtype=np.int64),
            "target_distance_indptr": t.indptr.astype(np.int64),
            "target_distance_index": t.indices.astype(np.int32),
            "target_distance": t.dist.astype(np.float64),
            "target_distance_radius": np.float64(t.radius),
            "self_match": np.bool_(self.self_match),
        }

    @classmethod
    def stored_in(cls, names: Sequence[str] | Mapping[str, object]) -> bool:
        """Whether arrays with these names (e.g. ``np.load(...).files``) hold a support."""
        return all(key in names for key in cls.KEYS)

    @classmethod
    def from_arrays(cls, z: Mapping[str, np.ndarray]) -> Support:
        """Inverse of :meth:`to_arrays`.

        ``z`` may be any mapping of the stored arrays (a dict or an open ``np.load``
        file) and may hold other keys. Optional keys may be missing; the version 1 names
        of the mesh coordinates (:attr:`OLD_KEYS`) are read when the new ones are absent.
        """
        targets = SparseDistances(
            z["target_distance_indptr"].astype(np.int64),
            z["target_distance_index"].astype(np.int64),
            z["target_distance"].astype(np.float64),
            float(z["target_distance_radius"]),
        )
        self_match = bool(z["self_match"])

        def optional(key: str) -> np.ndarray | None:
            for name in (key, cls.OLD_KEYS[key]):
                if name in z:
                    return z[name]
            return None

        source_mesh_vertices = optional("source_mesh_vertices")
        target_mesh_vertices = source_mesh_vertices if self_match else optional("target_mesh_vertices")
        return cls(
            z["edge_length"],
            targets,
            z["vertex_source"],
            z["vertex_target"],
            self_match,
            source_mesh_vertices,
            target_mesh_vertices,
        )
