"""The extraction's records: its parameters, a symmetric part pair, and all of a result's.

:class:`ExtractParams` configures :mod:`intrinsym.extract.extract`; a :class:`Symmetry` is one
symmetric part pair (source samples -> target samples); an :class:`Extraction` holds the
ranked symmetries of a result and which one is global (stored in ``result.npz`` as
:attr:`Extraction.KEYS`). Lengths are in units of sqrt(surface area).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["Extraction", "ExtractParams", "Symmetry"]


@dataclass(frozen=True)
class ExtractParams:
    """Parameters of the extraction. Lengths in units of sqrt(surface area).

    Attributes
    ----------
    threshold : float
        Peak threshold t on the max-normalised marginal (paper: t in [0.5, 0.75]).
    d_error : float
        Geodesic error bound of the region growing (paper: d_error in [0.001, 0.15]).
        The default is about two target spacings at the default |Pt| = 4000.
    peak_radius : float
        Distinct peaks of one marginal are at least this far apart (non-maximum
        suppression); also the tolerance within which two maps agree on a point.
    identity_radius : float
        A correspondence is trivial when its target lies within this distance of the
        source point itself (self-matching only); a map seeded at a trivial
        correspondence is the identity, any other map never takes trivial ones.
    global_fraction : float
        The dominant non-identity symmetry is "global" when it covers at least this
        fraction of the source samples (and its pairs average ``threshold`` on the
        normalised marginals).
    seeds_per_sample : int
        :func:`extract` seeds region growings from at most this many (the strongest)
        peaks of each source sample.
    min_fraction : float
        Smallest symmetry that :func:`extract` reports, as a fraction of |Ps| (at least
        one sample).
    max_count : int
        At most this many symmetries per BP pass are reported (the best ranked).
    keep_identity : bool
        Report identity symmetries too.
    unary_seeds : bool
        When :func:`extract` or :func:`query` is given the unary, also seed parts from
        its peaks (beyond the paper; see :func:`extract`).
    no_partner : bool
        The trivial match was kept in the model at a weight (``trivial_weight`` > 0):
        a row whose marginals peak on the identity then says "no symmetric partner",
        and the unary's parts do not grow into it (see :func:`extract`).
    vertex_fit : float
        :func:`intrinsym.globalmap.vertex_maps.fitted_vertex_map` maps the input vertices of a
        sample's Voronoi cell through the linear map fitted to the sample's mapped
        neighbours when every neighbour's relative residual is at most this (beyond the
        paper; 0, the default: each vertex takes its sample's image,
        :func:`intrinsym.globalmap.vertex_maps.vertex_map`).
    """

    threshold: float = 0.5
    d_error: float = 0.03
    peak_radius: float = 0.05
    identity_radius: float = 0.05
    global_fraction: float = 0.5
    seeds_per_sample: int = 6
    min_fraction: float = 0.05
    max_count: int = 32
    keep_identity: bool = False
    unary_seeds: bool = True
    no_partner: bool = False
    vertex_fit: float = 0.0

    def __post_init__(self) -> None:
        checks = [
            (not 0 < self.threshold <= 1, "threshold must lie in (0, 1]"),
            (self.d_error <= 0, "d_error must be positive"),
            (self.peak_radius < 0, "peak_radius must be non-negative"),
            (self.identity_radius < 0, "identity_radius must be non-negative"),
            (not 0 < self.global_fraction <= 1, "global_fraction must lie in (0, 1]"),
            (not 0 <= self.min_fraction <= 1, "min_fraction must lie in [0, 1]"),
            (self.max_count < 1, "max_count must be at least 1"),
            (self.seeds_per_sample < 1, "seeds_per_sample must be at least 1"),
            (self.vertex_fit < 0, "vertex_fit must be non-negative"),
        ]
        for bad, message in checks:
            if bad:
                raise ValueError(message)


@dataclass(frozen=True)
class Symmetry:
    """A symmetric part pair: source samples and their images.

    Attributes
    ----------
    source : (k,) int64
        Source sample indices, ascending.
    target : (k,) int64
        Target sample index of the image of each ``source`` entry.
    score : float
        In [0, 1]: the sum over the pairs of the max-normalised marginal, divided by
        |Ps|, times ``consistency``; 1 = the whole shape, each point at its marginal's
        maximum, every edge geodesically consistent.
    consistency : float
        Fraction of source edges inside the part whose images keep their length within
        ``d_error`` (1.0 for a part without internal edges).
    kind : {"identity", "partial", "global", "self map"}
        "self map": ``detect``'s partial symmetry map of a shape without a global one
        (:func:`intrinsym.extract.extract.mapped_symmetry`), not grown from the marginals:
        its score is its share of the source samples times ``consistency``.
    """

    source: np.ndarray
    target: np.ndarray
    score: float
    consistency: float
    kind: str

    def image(self, n_source: int) -> np.ndarray:
        """(n_source,) int64: target sample of every source sample, -1 outside the part."""
        out = np.full(n_source, -1, dtype=np.int64)
        out[self.source] = self.target
        return out


@dataclass(frozen=True)
class Extraction:
    """All symmetries of a result, ranked, and the dominant global one.

    Attributes
    ----------
    symmetries : list of Symmetry
        Ranked by score, best first (identity included only when asked).
    global_index : int
        Index into ``symmetries`` of the global symmetry, -1 when there is none
        (:attr:`global_symmetry` is that symmetry or None).
    params : ExtractParams
    """

    symmetries: list[Symmetry]
    global_index: int
    params: ExtractParams

    #: The arrays of :meth:`to_arrays` (``result.npz``, format version 4; the parameters
    #: are ``run.json``'s ``extraction_params``).
    KEYS: ClassVar[tuple[str, ...]] = (
        "symmetry_source",
        "symmetry_target",
        "symmetry_size",
        "symmetry_score",
        "symmetry_consistency",
        "symmetry_kind",
        "global_index",
    )
    #: The values of :attr:`Symmetry.kind`.
    KINDS: ClassVar[tuple[str, ...]] = ("identity", "partial", "global", "self map")

    @classmethod
    def stored_in(cls, names: Collection[str]) -> bool:
        """Whether ``names`` (a ``result.npz``'s arrays) hold an extraction."""
        return set(cls.KEYS) <= set(names)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The symmetries as arrays, in rank order: every part's source and target samples
        concatenated (int64), ``symmetry_size`` the pairs of each, its score, consistency
        and kind; and ``global_index`` (0-d)."""
        syms = self.symmetries
        return {
            "symmetry_source": np.concatenate([np.empty(0, np.int64), *(s.source for s in syms)]).astype(np.int64),
            "symmetry_target": np.concatenate([np.empty(0, np.int64), *(s.target for s in syms)]).astype(np.int64),
            "symmetry_size": np.array([len(s.source) for s in syms], dtype=np.int64),
            "symmetry_score": np.array([s.score for s in syms], dtype=np.float64),
            "symmetry_consistency": np.array([s.consistency for s in syms], dtype=np.float64),
            "symmetry_kind": np.array([s.kind for s in syms], dtype=f"U{max(map(len, self.KINDS))}"),
            "global_index": np.array(self.global_index, dtype=np.int64),
        }

    @classmethod
    def from_arrays(
        cls, arrays: Mapping[str, np.ndarray], params: ExtractParams, n_source: int, n_target: int
    ) -> Extraction:
        """The extraction :meth:`to_arrays` wrote, of ``n_source`` source and ``n_target``
        target samples.

        Raises
        ------
        ValueError
            Arrays that do not describe one (sizes that do not add up, a sample or the
            global index out of range, an unknown kind).
        """
        source, target, size = (np.asarray(arrays[key], dtype=np.int64) for key in cls.KEYS[:3])
        scores, consistencies = (np.asarray(arrays[key], dtype=np.float64) for key in cls.KEYS[3:5])
        kinds, index = [str(kind) for kind in arrays["symmetry_kind"]], int(arrays["global_index"])
        problems = [
            (len(target) != len(source) or size.min(initial=0) < 0 or size.sum() != len(source), "part sizes"),
            (not len(scores) == len(consistencies) == len(kinds) == len(size), "symmetry counts"),
            (source.min(initial=0) < 0 or source.max(initial=-1) >= n_source, "source samples"),
            (target.min(initial=0) < 0 or target.max(initial=-1) >= n_target, "target samples"),
            (not -1 <= index < len(size), "global_index"),
            (not set(kinds) <= set(cls.KINDS), "symmetry kinds"),
        ]
        bad = [name for wrong, name in problems if wrong]
        if bad:
            raise ValueError(f"its extraction's {', '.join(bad)} do not fit")
        cuts = np.cumsum(size)[:-1]
        parts = zip(np.split(source, cuts), np.split(target, cuts), scores, consistencies, kinds)
        symmetries = [Symmetry(s, t, float(score), float(c), kind) for s, t, score, c, kind in parts]
        return cls(symmetries if len(size) else [], index, params)

    @property
    def global_symmetry(self) -> Symmetry | None:
        """The global symmetry (``symmetries[global_index]``), None when there is none."""
        return self.symmetries[self.global_index] if self.global_index >= 0 else None

    @property
    def dominant_index(self) -> int:
        """Index into ``symmetries`` of the dominant symmetry: ``detect``'s partial
        symmetry map (kind "self map") when it kept one, else :attr:`grown_index`; -1
        when there is none. On an incomplete shape the symmetry of what is there is
        partial: it is the dominant one, not "nothing"."""
        kinds = [sym.kind for sym in self.symmetries]
        return kinds.index("self map") if "self map" in kinds else self.grown_index

    @property
    def dominant_symmetry(self) -> Symmetry | None:
        """The dominant symmetry (:attr:`dominant_index`), None when there is none."""
        return self.symmetries[self.dominant_index] if self.dominant_index >= 0 else None

    @property
    def grown_index(self) -> int:
        """Index into ``symmetries`` of the dominant symmetry grown from the marginals:
        the global one, else the partial one over the most source samples (the best
        ranked of equals); -1 when there is none."""
        if self.global_index >= 0:
            return self.global_index
        found = [i for i, sym in enumerate(self.symmetries) if sym.kind == "partial"]
        return max(found, key=lambda i: len(self.symmetries[i].source)) if found else -1

    @property
    def grown_symmetry(self) -> Symmetry | None:
        """The dominant symmetry grown from the marginals (:attr:`grown_index`), None when
        there is none."""
        return self.symmetries[self.grown_index] if self.grown_index >= 0 else None


def with_inverse(symmetry: Symmetry, source_points: np.ndarray, target_points: np.ndarray, radius: float) -> Symmetry:
    """A self-matching symmetry joined with its inverse: each source sample off the part
    that lies within ``radius`` of one of the part's images maps to (the target nearest)
    that image's source sample.

    A partial symmetry grown from one side's seeds holds the pairs from that side to the
    other (left leg -> right leg); a reflection sends the other side back as well, and a
    map of the symmetry covers both. Where several images lie near one sample, the
    nearest decides.

    Parameters
    ----------
    symmetry : Symmetry
    source_points, target_points : (S, 3), (T, 3) float
        Sample positions in one frame (self-matching: the same shape).
    radius : float
        In the units of the positions: about half the source sample spacing.
    """
    n = len(source_points)
    image = symmetry.image(n)
    distance, nearest = cKDTree(source_points).query(target_points[symmetry.target])
    own = cKDTree(target_points).query(source_points[symmetry.source])[1]
    order = np.argsort(distance, kind="stable")[::-1]  # the nearest written last wins
    for k in order:
        if distance[k] <= radius and image[nearest[k]] < 0:
            image[nearest[k]] = -2 - own[k]
    image = np.where(image <= -2, -2 - image, image)
    source = np.flatnonzero(image >= 0)
    return Symmetry(source, image[source], symmetry.score, symmetry.consistency, symmetry.kind)
