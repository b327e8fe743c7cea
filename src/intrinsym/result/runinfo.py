"""What a run records about itself (``run.json``): sizes, resolved constants, seconds,
BP statistics, the identity decision, the ZoomOut guard, inputs and versions.

Every record is a frozen dataclass; :meth:`RunInfo.to_dict` / :meth:`RunInfo.from_dict`
are the JSON form (format :data:`FORMAT_VERSION`; older files load too: version 1, written
before the field had a version, version 2, whose identity decision recorded the round
trip alone as ``involution``, dropped on reading, version 3, whose folder holds no
extraction, and version 4, whose ``result.npz`` calls the global map ``zoomout_map``).
"""

from __future__ import annotations

import dataclasses
import platform
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..globalmap.part_map import PartMapStats
from ..globalmap.self_hypothesis import SelfMapStats

#: Version of the result folder's format (``run.json``'s ``format_version``).
FORMAT_VERSION = 5

#: What format 3 replaced by the reflection test: the round trip alone (``identity``'s
#: statistic and threshold, and the parameter), dropped when an older file is read.
_ROUND_TRIP_KEYS = ("involution", "involution_threshold")


def stored_params(run: dict[str, Any]) -> dict[str, Any]:
    """``run.json``'s ``params`` in the current format's names (for ``Params(**...)``)."""
    params = dict(run["params"])
    if run.get("format_version", 1) < 3:
        for key in _ROUND_TRIP_KEYS:
            params.pop(key, None)
    return params


@dataclass(frozen=True)
class Sizes:
    """Sizes of the model.

    Attributes
    ----------
    source, target : int
        |Ps| and |Pt|.
    edges, directed_edges : int
        Source-graph edges, and messages per direction.
    max_degree : int
    target_distance_entries : int
        Stored target-to-target geodesics (the pairwise term's rings).
    source_working_vertices, target_working_vertices : int
        Vertices of the working (cleaned, possibly subdivided) shapes.
    """

    source: int
    target: int
    edges: int
    directed_edges: int
    max_degree: int
    target_distance_entries: int
    source_working_vertices: int
    target_working_vertices: int


@dataclass(frozen=True)
class Resolved:
    """Constants the run derived from the parameters, in normalised units (unit sqrt(area)).

    Attributes
    ----------
    lambda_normalised, lambda_input_units : float
        lambda of Eq. 6, normalised and in 1 / (input length)^2.
    delta : float
        Half-width of the pairwise ring.
    target_spacing, target_radius : float
        Spacing of the targets; radius of the stored target rings.
    unary_floor : float
        Smallest unary potential.
    scale : float
        Input length per normalised length (sqrt of the input surface area).
    """

    lambda_normalised: float
    lambda_input_units: float
    delta: float
    target_spacing: float
    target_radius: float
    unary_floor: float
    scale: float


@dataclass(frozen=True)
class PassStats:
    """Convergence of one BP pass after the first."""

    iterations: int
    converged: bool
    max_change: float


@dataclass(frozen=True)
class BPStats:
    """Belief propagation of the first pass (the marginals), and the further passes.

    Attributes
    ----------
    backend : str
        "cpu" or "gpu".
    iterations : int
    converged : bool
    max_change : float
        Largest max-normalised message change of the last iteration.
    history : tuple of float
        That change per iteration.
    seconds_per_iteration, setup_seconds : float
    message_updates : int
    passes : tuple of PassStats
    modes : tuple of PassStats
        BP given each mode of a match (``Result.mode_marginals``), for the modes that
        have images.
    schedule : str
        The schedule that ran ("auto" resolved; empty in a run.json written before
        it was recorded).
    """

    backend: str
    iterations: int
    converged: bool
    max_change: float
    history: tuple[float, ...]
    seconds_per_iteration: float
    setup_seconds: float
    message_updates: int
    passes: tuple[PassStats, ...] = ()
    schedule: str = ""
    modes: tuple[PassStats, ...] = ()


@dataclass(frozen=True)
class IdentityDecision:
    """How the trivial match was treated (self-matching with ``remove_trivial``).

    Attributes
    ----------
    weight : float
        The trivial match's weight BP used (0: removed).
    isometry : float or None
        With ``trivial_weight="auto"``: the share of source edges BP's argmax kept.
    threshold : float or None
        The threshold it was compared with.
    removed_iterations : int or None
        BP iterations of the run with the identity removed, when BP ran again with it kept.
    reflection : float or None
        With ``trivial_weight="auto"``: the share of source samples at which BP's argmax
        acted as a reflection (:func:`intrinsym.extract.reflection.reflection`).
    reflection_threshold : float or None
        The threshold it was compared with.
    wider_radius : float or None
        When the global symmetry was kept by the reflection test alone: the trivial radius
        of the second BP (``unsure_radius`` times ``trivial_radius``).
    distortion, wider_distortion : float or None
        The mean local distortion of the two runs' global maps (sqrt(area) units; None
        where a run gave none).
    wider_kept : bool or None
        Whether the second run's result was kept (its map the less distorted).
    """

    weight: float
    isometry: float | None = None
    threshold: float | None = None
    removed_iterations: int | None = None
    reflection: float | None = None
    reflection_threshold: float | None = None
    wider_radius: float | None = None
    distortion: float | None = None
    wider_distortion: float | None = None
    wider_kept: bool | None = None


@dataclass(frozen=True)
class ZoomOutStats:
    """The seeded ZoomOut refinement of the global symmetry.

    Attributes
    ----------
    agreement : float
        Share of the global symmetry's sample pairs the refined map keeps.
    used : bool
        Whether the refined map passed the guard and is the symmetry map.
    """

    agreement: float
    used: bool


@dataclass(frozen=True)
class GlobalMapStats:
    """How the global map was chosen (:func:`intrinsym.globalmap.globalmap.choose_global_map`).

    Attributes
    ----------
    source : str
        The winning candidate: "extraction", "zoomout" or "spectral".
    mass : float
        Marginal mass the global map keeps, in [0, 1] (:func:`intrinsym.globalmap.confidence.kept_mass`;
        not a calibrated probability).
    masses : dict of str to float
        Kept mass of every candidate tried.
    refined : float
        Share of the input vertices whose image the trilateration moved
        (:func:`intrinsym.globalmap.refine.trilaterate`; 0 without it).
    smoothed : float
        Share of the input vertices whose image the spectral smoothing then moved
        (:func:`intrinsym.globalmap.refine.spectral_descent`; 0 without it or where it was refused).
    carried : float
        Share of the input vertices on connected components with fewer than three
        source samples, carried there by the rigid motion of the surface around them
        (:func:`intrinsym.globalmap.vertex_maps.carried_to_components`; 0 on a connected shape, and
        where no component holds three samples to carry the others by).
    """

    source: str
    mass: float
    masses: dict[str, float] = field(default_factory=dict)
    refined: float = 0.0
    smoothed: float = 0.0
    carried: float = 0.0


@dataclass(frozen=True)
class RunInfo:
    """Everything ``run.json`` records besides the parameters.

    Attributes
    ----------
    mode : {"detect", "match"}
    input : str
        The (source) input's path, or "None".
    target_input : str or None
        The target input's path (match).
    preset : str
    sizes : Sizes
    resolved : Resolved
    seconds : dict of str to float
        Seconds per stage, in order.
    bp : BPStats
    identity : IdentityDecision or None
    zoomout : ZoomOutStats or None
    global_map : GlobalMapStats or None
    versions : dict of str to str
    content_key : str or None
        Hash of the input bytes, the resolved parameters and the package version
        (``intrinsym batch`` skips an item whose folder holds its key).
    part : bool
        Match: the smaller shape was taken for a part of the larger (less than
        ``PARTIAL_AREA`` of its area; one unit, ``partial_unary``).
    target_part : bool
        Match: the target is that part (the source the whole); the result's
        ``global_map`` is the inverse of the part's own match to the whole, -1 ("no
        match") where the source has no counterpart on the part.
    part_map : PartMapStats or None
        Match with ``part``: which of the part's vertex maps was kept and how much each
        changes the part's distances (for a whole matched to its part, the part's
        extraction map the result inverts); the score of the confidence.
    self_map : SelfMapStats or None
        Detect without a global symmetry (a mesh, ``self_hypotheses`` at least 1): which
        partial symmetry map was kept (``global_map``) and how much of the shape each
        candidate maps.
    """

    mode: str
    input: str
    sizes: Sizes
    resolved: Resolved
    seconds: dict[str, float]
    bp: BPStats
    preset: str = "default"
    target_input: str | None = None
    identity: IdentityDecision | None = None
    zoomout: ZoomOutStats | None = None
    global_map: GlobalMapStats | None = None
    versions: dict[str, str] = field(default_factory=dict)
    content_key: str | None = None
    part: bool = False
    target_part: bool = False
    part_map: PartMapStats | None = None
    self_map: SelfMapStats | None = None

    @property
    def no_partner(self) -> bool:
        """Whether BP kept the trivial match at a weight (the answer "no partner")."""
        return self.identity is not None and self.identity.weight > 0

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (``run.json`` without ``params``); None entries left out."""
        out = {"format_version": FORMAT_VERSION, **dataclasses.asdict(self)}
        out["bp"]["history"] = list(self.bp.history)
        if out["identity"] is not None:
            out["identity"] = {k: v for k, v in out["identity"].items() if v is not None}
        return {k: v for k, v in out.items() if v is not None}

    @classmethod
    def from_dict(cls, run: dict[str, Any]) -> RunInfo:
        """Read :meth:`to_dict`'s form, or an older ``run.json`` (see the module)."""
        sizes = dict(run["sizes"])
        version = run.get("format_version", 1)
        if version < 2:
            sizes["source_working_vertices"] = sizes.pop("source_vertices")
            sizes["target_working_vertices"] = sizes.pop("target_vertices")
        bp = dict(run["bp"])
        bp["history"] = tuple(bp.get("history", ()))
        bp["passes"] = tuple(PassStats(**q) for q in bp.get("passes", ()))
        bp["modes"] = tuple(PassStats(**q) for q in bp.get("modes", ()))
        identity = run.get("identity")
        if identity and version < 3:
            identity = {k: v for k, v in identity.items() if k not in _ROUND_TRIP_KEYS}
        zoomout = run.get("zoomout")
        global_map = run.get("global_map")
        part_map = run.get("part_map")
        self_map = run.get("self_map")
        return cls(
            mode=run["mode"],
            input=run["input"],
            target_input=run.get("target_input"),
            preset=run.get("preset", "default"),
            sizes=Sizes(**sizes),
            resolved=Resolved(**run["resolved"]),
            seconds=dict(run["seconds"]),
            bp=BPStats(**bp),
            identity=IdentityDecision(**identity) if identity else None,
            zoomout=ZoomOutStats(**zoomout) if zoomout else None,
            global_map=GlobalMapStats(**global_map) if global_map else None,
            versions=dict(run.get("versions", {})),
            content_key=run.get("content_key"),
            part=bool(run.get("part", False)),
            target_part=bool(run.get("target_part", False)),
            part_map=PartMapStats(**part_map) if part_map else None,
            self_map=SelfMapStats(**self_map) if self_map else None,
        )


def versions() -> dict[str, str]:
    """Versions of intrinsym, Python and the numerical libraries."""
    import importlib.metadata

    import numba
    import scipy

    from .._version import __version__

    return {
        "intrinsym": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "trimesh": importlib.metadata.version("trimesh"),
    }
