"""Every parameter of the pipeline, each described once.

Each :class:`Params` field carries its help text, paper value and unit in its
``dataclasses.field`` metadata (:func:`describe` reads them); the command-line options
(:mod:`intrinsym.app.cli`) and ``docs/parameters.md`` (:func:`markdown_table`) are generated
from them. Lengths are in units of sqrt(surface area), so every default is scale-free.
"""

from __future__ import annotations

import dataclasses
import math
import textwrap
import types
import typing
from dataclasses import dataclass
from typing import Any, Literal, get_args, get_origin

from .errors import ParameterError
from .extract.reflection import RETURN_RADIUS
from .extract.symmetry import ExtractParams
from .spectral.laplacian import FINE_PER_COARSE

Schedule = Literal["auto", "colour", "serial", "residual", "flooding"]
Backend = Literal["auto", "cpu", "gpu"]
DType = Literal["float32", "float64"]
Potential = Literal["calibrated", "paper"]
Calibration = Literal["local", "both", "offset", "descriptor", "row"]
MatchScale = Literal["auto", "larger", "each"]
Proposals = Literal["descriptors", "marginals", "both"]

#: Unary descriptor terms selectable by name; "a*b" multiplies their potentials.
UNARY_TERMS = ("spin", "spin-multi", "wks", "hks")
#: ``match`` takes the smaller shape for a part of the larger (``match_scale="auto"``: one
#: common unit; ``partial_unary``) when its area is below this share of the larger's:
#: posed frames of one object keep their area within a few per cent (Sumner's horse
#: frames 0.977-1), a SHREC'16 partial shape keeps 0.12-0.93 of it (docs/results.md).
PARTIAL_AREA = 0.95
#: The trivial match's weight when ``trivial_weight="auto"`` keeps the identity.
NO_PARTNER_WEIGHT = 0.7
#: The global map is seeded ZoomOut's (vertex-precise) unless it keeps this much less
#: marginal mass (within ``mass_radius``) than the extraction's map (resolved to the
#: sample spacing); a spectral candidate replaces the model's map only when it keeps this
#: much more (:func:`intrinsym.globalmap.choose_global_map`; measured in
#: docs/notes/2026-11-28-results-behind-the-defaults.md).
MAP_MARGIN = 0.1
#: A mesh with fewer vertices than this many times the larger sample count is
#: midpoint-subdivided (each round quadruples it) until it has that many: the working
#: shape the samples, geodesics and descriptors live on (measured in
#: docs/notes/2026-11-28-speed-behind-the-defaults.md).
WORK_PER_SAMPLE = 2
#: Targets nearest a calibration point on the surface that the "offset" rule pairs it with.
OFFSET_TARGETS = 3

#: Largest accepted ``eigenpairs`` and ``zoomout_final``: the eigensolver's time grows
#: steeply with it, and the WKS and ZoomOut use far fewer.
MAX_EIGENPAIRS = 1000
#: Largest accepted ``energies`` (the signatures are (points, energies) arrays).
MAX_ENERGIES = 10000
#: Largest accepted ``spin_bins`` (each spin image holds spin_bins^2 bytes per point).
MAX_SPIN_BINS = 128
#: Largest accepted ``spin_cloud`` (24 bytes per point, twice).
MAX_SPIN_CLOUD = 10_000_000

#: Command-line sections, in the order the help lists them.
GROUPS = ("sampling", "unary", "pairwise", "bp", "trivial match", "extraction", "global map")


def _p(
    default: Any,
    help: str,
    group: str,
    *,
    paper: str | None = None,
    unit: str | None = None,
    flag: str | None = None,
    off_flag: str | None = None,
    self_match: bool = False,
    match_only: bool = False,
) -> Any:
    """A :class:`Params` field with its documentation.

    ``flag`` overrides the command-line option (default ``--field-name``); ``off_flag``
    names a boolean's negative option (default ``--no-...``); ``self_match`` marks a
    field that only ``detect`` uses, ``match_only`` one that only ``match`` uses.
    """
    meta = {
        "help": help,
        "group": group,
        "paper": paper,
        "unit": unit,
        "flag": flag,
        "off_flag": off_flag,
        "self_match": self_match,
        "match_only": match_only,
    }
    return dataclasses.field(default=default, metadata=meta)


AREA = "sqrt(area)"


@dataclass(frozen=True)
class Params:
    """Every parameter of the pipeline; see ``docs/parameters.md`` for the table.

    Each field's meaning, paper value and unit are in its metadata
    (:func:`describe`). Values are checked on construction
    (:class:`~intrinsym.errors.ParameterError`); whether the machine can run them
    (a GPU for ``backend="gpu"``) is checked when a run starts.
    """

    n_source: int | None = _p(
        250,
        "number of source samples |Ps|; ignored when --source-spacing is set",
        "sampling",
        paper="111-479 (Table 1)",
        flag="--source",
    )
    n_target: int | None = _p(
        4000,
        "number of target samples |Pt| (match of a part and its whole: --part-targets of it, and a part as "
        "the target its share of the whole's, by area); ignored when --target-spacing is set",
        "sampling",
        paper="6000-12722 (Table 1)",
        flag="--target",
    )
    part_targets: float = _p(
        0.75,
        f"share of --target a match samples when its smaller shape has less than {PARTIAL_AREA} of the larger's "
        "area (a part and its whole): on the 125 SHREC'16 pairs 0.75 keeps every mean score within 0.008 of "
        "1's in 0.84x the time, 0.5 loses precision",
        "sampling",
        match_only=True,
    )
    source_spacing: float | None = _p(None, "Poisson-disc radius of Ps, instead of a count", "sampling", unit=AREA)
    target_spacing: float | None = _p(None, "Poisson-disc radius of Pt, instead of a count", "sampling", unit=AREA)
    seed: int = _p(0, "random seed of the sampling and the BP orders", "sampling")
    match_scale: MatchScale = _p(
        "auto",
        "unit of length of the two shapes: 'larger' divides both by sqrt(area) of the larger one, keeping "
        "their relative size (inputs in the same units: a part matched to a whole); 'each' normalises each "
        "to unit area (whole shapes, whatever their units); 'auto': 'larger' when the smaller has less than "
        f"{PARTIAL_AREA} of the larger's area, else 'each' (give 'each' for a part in other units)",
        "sampling",
        flag="--scale",
        match_only=True,
    )
    spin_bins: int = _p(16, "spin image size in bins per side", "unary", paper="not stated")
    spin_radius: float = _p(
        0.25,
        "spin image support radius; the support must dwarf the offset between a point and its nearest target",
        "unary",
        paper="not stated",
        unit=AREA,
    )
    spin_levels: int = _p(8, "intensity levels of the NMI entropies (Eq. 2-4)", "unary")
    spin_cloud: int = _p(40000, "dense area-uniform surface points the spin images are built from", "unary")
    gamma: float = _p(0.01, "robustness gamma of the unary (Eq. 5); potential 'paper' only", "unary", paper="0.01")
    unary: str = _p(
        "wks*spin",
        "unary descriptor terms from spin, spin-multi (NMI averaged over 0.5, 1 and 2 "
        "spin radii), wks, hks, joined by '*' (their potentials multiply)",
        "unary",
        paper="spin",
    )
    partial_unary: str = _p(
        "spin",
        f"unary terms of a match whose smaller shape has less than {PARTIAL_AREA} of the larger's area (a "
        "part matched to a whole): a part's spectral terms differ from the whole's",
        "unary",
        match_only=True,
    )
    potential: Potential = _p(
        "calibrated",
        "similarity-to-potential map: 'paper' is Eq. 5 with gamma on NMI' "
        "(one spin term only); 'calibrated' is exp(-d^2 / 2 sigma^2) per term, "
        "sigma measured as --calibration says, floored at --unary-floor",
        "unary",
        paper="paper",
    )
    eigenpairs: int = _p(100, "Laplace-Beltrami eigenpairs of the WKS / HKS", "unary")
    eigen_coarse: int = _p(
        8000,
        f"vertices of the decimated copy a mesh of more than {FINE_PER_COARSE} times as many is first solved on for "
        "the eigenpairs (then refined on the mesh itself: intrinsym.spectral.laplacian.two_grid_eigenpairs); "
        "0 solves on the mesh alone",
        "unary",
    )
    energies: int = _p(100, "log-energies of the WKS, diffusion times of the HKS", "unary")
    calibration: Calibration = _p(
        "local",
        "how each calibrated width sigma is measured: 'offset', the median descriptor distance from "
        "points to the 3 targets nearest them on the surface; 'descriptor', to the --calibration-k "
        "nearest targets in descriptor space; 'both', the larger; 'local', 'both' raised per source "
        "sample to its own offset spread (self-matching); 'row', each source sample's distances from its "
        "nearest target in descriptor space, in --row-width times their spread to its median one",
        "unary",
    )
    partial_calibration: Calibration = _p(
        "row",
        f"--calibration of a match whose smaller shape has less than {PARTIAL_AREA} of the larger's area (a "
        "part matched to a whole): between a part and a whole in another pose a true match lies only "
        "slightly nearer in descriptor space than the rest, and widths measured on the whole leave the "
        "unary flat",
        "unary",
        match_only=True,
    )
    calibration_k: int = _p(7, "nearest targets in descriptor space of the 'descriptor' rule", "unary")
    row_width: float = _p(
        0.2,
        "width of the 'row' rule's Gaussian, in units of a source sample's spread of descriptor distances "
        "from its nearest target to its median one",
        "unary",
    )
    unary_floor: float = _p(1e-3, "smallest calibrated unary potential, in (0, 1)", "unary")
    rho: float = _p(0.4, "truncation rho of the pairwise term (Eq. 6)", "pairwise", paper="0.4")
    tolerance: float = _p(
        1.5,
        "half-width delta of the pairwise ring: lambda is chosen so that psi = rho^2 at |d(s,q) - d(fs,fq)| = delta",
        "pairwise",
        unit="target spacings",
    )
    lam: float | None = _p(
        None,
        "raw lambda of Eq. 6, overrides --tolerance (not scale-free)",
        "pairwise",
        paper="1e6 (units not stated)",
        unit="1 / (input length)^2",
        flag="--lambda",
    )
    schedule: Schedule = _p(
        "auto",
        "BP message schedule: 'colour', serial sweeps whose independent updates run "
        "as one batch; 'serial', node by node (the paper's); 'residual', 'colour' in "
        "which a node sends only while its inputs change; 'flooding', all at once; "
        "'auto', 'residual' on the CPU and 'colour' on the GPU",
        "bp",
        paper="serial",
    )
    iterations: int = _p(100, "maximum BP iterations T", "bp", paper="100")
    bp_tol: float = _p(
        1e-2,
        "stop BP when the largest change of a max-normalised message is below this (the mean scores of "
        "3e-3 within 0.004 on the 36 complete shapes and the 125 SHREC'16 shapes and pairs, with 0.71x the "
        "BP iterations on the complete ones)",
        "bp",
    )
    damping: float = _p(0.0, "message damping, in [0, 1)", "bp")
    backend: Backend = _p(
        "auto",
        "where BP (and, with it, the global map's nearest-neighbour searches) runs: 'auto' is the GPU "
        "when CuPy sees a CUDA device, the schedule is not 'residual' and dtype is float32, else the CPU",
        "bp",
    )
    dtype: DType = _p("float32", "storage of messages and marginals", "bp")
    passes: int | None = _p(
        None,
        "BP passes; each further pass removes the earlier passes' argmax from the unary "
        "and finds another mode (default: 1 for detect, 2 for match)",
        "bp",
    )
    pass_radius: float = _p(0.08, "radius about each row's argmax that a further pass removes", "bp", unit=AREA)
    mode_width: float = _p(
        1.0,
        "width of the Gaussian about each mode's images that BP given the mode keeps (a match's mode marginals)",
        "bp",
        unit="target spacings",
        match_only=True,
    )
    remove_trivial: bool = _p(
        True,
        "weaken the trivial match (targets within --trivial-radius of the source sample) to --trivial-weight",
        "trivial match",
        paper="off (identity kept)",
        off_flag="--keep-trivial",
        self_match=True,
    )
    trivial_radius: float = _p(0.08, "radius of the trivial match", "trivial match", unit=AREA, self_match=True)
    trivial_weight: float | Literal["auto"] = _p(
        "auto",
        "the trivial match's largest unary as a fraction of the row's largest elsewhere, in [0, 1); 0 "
        "removes it, above 0 it stays as the answer 'no symmetric partner'; 'auto': 0, unless BP's argmax "
        "keeps fewer than --isometry-threshold of the source edges' lengths and acts as a reflection on "
        "fewer than --reflection-threshold of the samples, then BP runs again at 0.7",
        "trivial match",
        self_match=True,
    )
    isometry_threshold: float = _p(
        0.85,
        "share of source edges whose length BP's argmax keeps within --d-error or "
        "one target spacing, below which --trivial-weight auto keeps the identity (unless "
        "--reflection-threshold is met)",
        "trivial match",
        self_match=True,
    )
    unsure_radius: float = _p(
        1.25,
        "BP again at --trivial-radius times this when the global symmetry passes --reflection-threshold but not "
        "--isometry-threshold; the global map of lower mean local distortion is kept (1: off)",
        "trivial match",
        self_match=True,
    )
    reflection_threshold: float = _p(
        0.55,
        "share of source samples at which BP's argmax acts as a reflection (applied twice, it returns them "
        f"to within {RETURN_RADIUS}, and it reverses the order of their neighbours around them), from which "
        "--trivial-weight auto removes the identity whatever --isometry-threshold says",
        "trivial match",
        self_match=True,
    )
    peak_threshold: float = _p(
        ExtractParams.threshold, "peak threshold t on the max-normalised marginal", "extraction", paper="0.5-0.75"
    )
    d_error: float = _p(
        ExtractParams.d_error, "geodesic error bound of the region growing", "extraction", paper="0.001-0.15", unit=AREA
    )
    report_identity: bool = _p(
        False,
        "also list the identity symmetries (kind 'identity') in symmetries.json; "
        "they arise where the trivial match stays in the model",
        "extraction",
        self_match=True,
    )
    unary_seeds: bool = _p(
        True, "also grow symmetries from the unary's peaks, not only the marginals'", "extraction", paper="off"
    )
    vertex_fit: float = _p(
        ExtractParams.vertex_fit,
        "largest relative residual of the local linear fits that "
        "extend the global map to every input vertex; 0 gives each "
        "vertex its sample's image",
        "global map",
    )
    zoomout: bool = _p(
        True,
        "refine the global symmetry's sample pairs by ZoomOut in the Laplace-Beltrami "
        "eigenfunctions into the symmetry map (symmetry_map.npy); ignores --vertex-fit",
        "global map",
        paper="off",
        self_match=True,
    )
    zoomout_seed: int = _p(
        16,
        "eigenfunctions fitted to the global symmetry's pairs (ZoomOut's first level)",
        "global map",
        self_match=True,
    )
    zoomout_final: int = _p(50, "eigenfunctions of ZoomOut's last level", "global map", self_match=True)
    mass_radius: float = _p(
        0.1,
        "radius around a sample's image within which its marginal mass counts for a map: "
        "the candidate global maps are judged by it, and symmetry_mass.npy holds it",
        "global map",
        unit=AREA,
        self_match=True,
    )
    refine_anchors: int = _p(
        20,
        "move each vertex's global-map image to where its geodesic distances to this many "
        "nearest source samples (fewer at the tip of a limb: those within reach) are best kept "
        "from the samples' marginal peaks (geodesic trilateration); 0: no refinement",
        "global map",
        paper="off",
        self_match=True,
    )
    smooth_map: bool = _p(
        True,
        "project the refined global map once onto the Laplace-Beltrami eigenfunctions (a "
        "least-squares functional map on every vertex) and move each image, by steepest "
        "descent over the geodesic graph from where it is, to the vertex nearest its "
        "projection: removes the trilateration's vertex-to-vertex noise",
        "global map",
        paper="off",
        self_match=True,
    )
    fallback_mass: float = _p(
        0.6,
        "below this kept marginal mass of the chosen global map, the spectral baseline's "
        "candidates (sign search + ZoomOut) are scored by the marginals too, and the best "
        "replaces it when it keeps clearly more",
        "global map",
        self_match=True,
    )
    part_fmap: bool = _p(
        True,
        "a part matched to its whole (the smaller shape the source) also gets a partial "
        "functional map (Rodola et al. 2017), and the vertex map of the two that changes "
        "fewer of the part's geodesic distances is kept, refined by ZoomOut and trilaterated "
        "from the anchors it keeps the distances of, each where that keeps more of them, "
        "a trilaterated map refined once more, and replaced by the map located from a "
        "consistent cluster of spin-image matches where that keeps more still (run.json: part_map)",
        "global map",
        paper="off",
        off_flag="--no-part-fmap",
        match_only=True,
    )
    part_hypotheses: int = _p(
        1,
        "with part_fmap, the hypotheses drawn from consistent clusters of spin-image matches "
        "(game-theoretic matching) and weighed against the part's kept map: one costs "
        "1.5-2.3 s of a SHREC'16 pair alone on two cores; 0 draws none",
        "global map",
        paper="0",
        match_only=True,
    )
    part_proposals: Proposals = _p(
        "descriptors",
        "the images a part's hypotheses offer each anchor: the whole's samples nearest it in "
        "spin-image space (descriptors), the peaks of BP's marginal at the part's sample nearest "
        "it (marginals), or both (part_hypotheses from each); on the 125 SHREC'16 pairs before "
        "the blend within 0.10 0.897 / 0.889 / 0.905, both taking 1.17x the time of the slowest "
        "pairs alone",
        "global map",
        match_only=True,
    )
    self_hypotheses: int = _p(
        1,
        "where detect finds no global symmetry on a mesh, the hypotheses drawn from consistent clusters of "
        "spin-image self-matches (trivial matches left out), weighed against the extraction's map: each map "
        "is cut to -1 where it does not keep the distances around a vertex, and of those whose images look "
        "like their vertices the one mapping the most vertices is kept: each costs 2-9 s on a SHREC'16 shape "
        "on two cores; 0 draws none and keeps the extraction's map",
        "global map",
        paper="0",
        self_match=True,
    )

    def __post_init__(self) -> None:
        for name, value in _choices().items():
            if getattr(self, name) not in value:
                raise ParameterError(f"{name} must be one of {value}, got {getattr(self, name)!r}")
        for f in describe():
            value = getattr(self, f.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise ParameterError(f"{f.name} must be a finite number, got {value}")
        checks = [
            (self.n_source is None and self.source_spacing is None, "give n_source or source_spacing"),
            (self.n_target is None and self.target_spacing is None, "give n_target or target_spacing"),
            (self.n_source is not None and self.n_source < 2, "n_source must be at least 2"),
            (self.n_target is not None and self.n_target < 2, "n_target must be at least 2"),
            (not 0 < self.part_targets <= 1, "part_targets must lie in (0, 1]"),
            (self.source_spacing is not None and self.source_spacing <= 0, "source_spacing must be positive"),
            (self.target_spacing is not None and self.target_spacing <= 0, "target_spacing must be positive"),
            (self.seed < 0, "seed must be at least 0"),
            (self.refine_anchors < 0, "refine_anchors must be at least 0"),
            (self.part_hypotheses < 0, "part_hypotheses must be at least 0"),
            (self.self_hypotheses < 0, "self_hypotheses must be at least 0"),
            (not 2 <= self.spin_bins <= MAX_SPIN_BINS, f"spin_bins must lie in [2, {MAX_SPIN_BINS}]"),
            (not 1 <= self.spin_cloud <= MAX_SPIN_CLOUD, f"spin_cloud must lie in [1, {MAX_SPIN_CLOUD}]"),
            (self.spin_radius <= 0, "spin_radius must be positive"),
            (not 2 <= self.spin_levels <= 255, "spin_levels must lie in [2, 255]"),
            (self.gamma <= 0, "gamma must be positive"),
            (not 0 < self.rho < 1, "rho must lie in (0, 1)"),
            (self.tolerance <= 0, "tolerance must be positive"),
            (self.lam is not None and self.lam <= 0, "lam must be positive"),
            (self.iterations < 1, "iterations must be at least 1"),
            (not 0 <= self.damping < 1, "damping must lie in [0, 1)"),
            (self.trivial_radius < 0, "trivial_radius must be non-negative"),
            (
                self.trivial_weight != "auto"
                and not (isinstance(self.trivial_weight, (int, float)) and 0 <= self.trivial_weight < 1),
                "trivial_weight must be 'auto' or lie in [0, 1)",
            ),
            (not 0 <= self.isometry_threshold <= 1, "isometry_threshold must lie in [0, 1]"),
            (not 0 <= self.reflection_threshold <= 1, "reflection_threshold must lie in [0, 1]"),
            (not self.unsure_radius >= 1, "unsure_radius must be at least 1"),
            (not 0 <= self.fallback_mass <= 1, "fallback_mass must lie in [0, 1]"),
            (not self.mass_radius > 0, "mass_radius must be positive"),
            (self.passes is not None and self.passes < 1, "passes must be at least 1"),
            (self.pass_radius <= 0, "pass_radius must be positive"),
            (not self.mode_width > 0, "mode_width must be positive"),
            *(
                (
                    any(t not in UNARY_TERMS for t in terms) or len(set(terms)) < len(terms),
                    f"{name} must be distinct terms of {UNARY_TERMS} joined by '*'",
                )
                for name, terms in (("unary", self.unary_terms), ("partial_unary", self.partial_unary.split("*")))
            ),
            (
                self.potential == "paper" and not {self.unary, self.partial_unary} <= {"spin", "spin-multi"},
                "potential 'paper' (Eq. 5) applies to a single spin-image term only",
            ),
            (not 2 <= self.eigenpairs <= MAX_EIGENPAIRS, f"eigenpairs must lie in [2, {MAX_EIGENPAIRS}]"),
            (self.eigen_coarse < 0, "eigen_coarse must be at least 0"),
            (not 2 <= self.energies <= MAX_ENERGIES, f"energies must lie in [2, {MAX_ENERGIES}]"),
            (self.calibration_k < 1, "calibration_k must be at least 1"),
            (not self.row_width > 0, "row_width must be positive"),
            (
                self.n_target is not None and self.calibration_k > self.n_target,
                f"calibration_k must be at most n_target ({self.n_target})",
            ),
            (self.zoomout_final > MAX_EIGENPAIRS, f"zoomout_final must be at most {MAX_EIGENPAIRS}"),
            (not 0 < self.unary_floor < 1, "unary_floor must lie in (0, 1)"),
            (not 1 <= self.zoomout_seed <= self.zoomout_final, "need 1 <= zoomout_seed <= zoomout_final"),
        ]
        for bad, message in checks:
            if bad:
                raise ParameterError(message)
        try:
            self.extraction()
        except ValueError as err:
            raise ParameterError(str(err)) from None

    @property
    def unary_terms(self) -> list[str]:
        """The descriptor terms of ``unary``."""
        return self.unary.split("*")

    def extraction(self, no_partner: bool = False) -> ExtractParams:
        """The symmetry-extraction parameters; ``no_partner``: the trivial match was kept
        at a weight (:meth:`intrinsym.result.result.Result.extraction_params` knows whether)."""
        return ExtractParams(
            threshold=self.peak_threshold,
            d_error=self.d_error,
            unary_seeds=self.unary_seeds,
            vertex_fit=self.vertex_fit,
            no_partner=no_partner,
            keep_identity=self.report_identity,
        )


PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    # The paper's Sec. 5 constants: rho 0.4, gamma 0.01, serial schedule, 100 iterations,
    # and its model as written, identity included. Its lambda = 1e6 is a raw number in
    # unstated units; read as a ring half a target spacing wide, it reproduces the
    # paper's behaviour (BP converging in a handful of iterations, sharpening the unary
    # rather than smearing it). With remove_trivial=True on top, the identity is removed
    # outright (no "auto" test).
    "paper": dict(
        rho=0.4,
        gamma=0.01,
        schedule="serial",
        iterations=100,
        remove_trivial=False,
        tolerance=0.5,
        unary="spin",
        potential="paper",
        unary_seeds=False,
        vertex_fit=0.0,
        zoomout=False,
        refine_anchors=0,
        smooth_map=False,
        part_fmap=False,
        part_hypotheses=0,
        self_hypotheses=0,
        passes=1,
        trivial_weight=0.0,
    ),
}


def make_params(preset: str = "default", **overrides: Any) -> Params:
    """Parameters of a named preset ("default" or "paper") with overrides applied."""
    if preset not in PRESETS:
        raise ParameterError(f"unknown preset {preset!r}; expected one of {sorted(PRESETS)}")
    names = {f.name for f in dataclasses.fields(Params)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ParameterError(f"unknown parameter(s): {', '.join(unknown)}")
    return Params(**{**PRESETS[preset], **overrides})


@dataclass(frozen=True)
class Field:
    """One parameter as the CLI and the docs show it.

    Attributes
    ----------
    name : str
        The :class:`Params` field.
    flag, off_flag : str
        Command-line option; a boolean's negative option (None otherwise).
    kind : type
        int, float, str or bool, the value's type on the command line.
    choices : tuple of str or None
        The allowed values of an enumeration.
    words : tuple of str
        Words a number field also takes (``trivial_weight``'s "auto").
    optional : bool
        Whether None is a value (unset).
    default : object
    help, group : str
    paper, unit : str or None
    self_match : bool
        Only ``detect`` uses it.
    match_only : bool
        Only ``match`` uses it.
    """

    name: str
    flag: str
    off_flag: str | None
    kind: type
    choices: tuple[str, ...] | None
    words: tuple[str, ...]
    optional: bool
    default: Any
    help: str
    group: str
    paper: str | None
    unit: str | None
    self_match: bool
    match_only: bool

    def parse(self, text: str) -> Any:
        """The value a text (a manifest cell, ``NAME=VALUE``) gives this parameter;
        :class:`~intrinsym.errors.ParameterError` naming it where the text is no value."""
        if self.kind is bool:
            lowered = text.lower()
            if lowered not in ("true", "false", "1", "0", "yes", "no"):
                raise ParameterError(f"{self.name}: {text!r} is not a boolean")
            return lowered in ("true", "1", "yes")
        if text in self.words or (self.choices and text in self.choices):
            return text
        try:
            return self.kind(text)
        except ValueError:
            raise ParameterError(f"{self.name}: {text!r} is not a {self.kind.__name__}") from None


def _type_parts(hint: Any) -> tuple[list[Any], bool]:
    """The non-None members of a type hint and whether None is one."""
    parts = list(get_args(hint)) if get_origin(hint) in (typing.Union, types.UnionType) else [hint]
    return [a for a in parts if a is not type(None)], type(None) in parts


def _choices() -> dict[str, tuple[str, ...]]:
    """The enumerations of :class:`Params`: field -> allowed values."""
    hints = typing.get_type_hints(Params)
    return {name: get_args(hint) for name, hint in hints.items() if get_origin(hint) is Literal}


def describe() -> list[Field]:
    """Every :class:`Params` field with its documentation, in declaration order."""
    hints = typing.get_type_hints(Params)
    out = []
    for f in dataclasses.fields(Params):
        parts, optional = _type_parts(hints[f.name])
        literal = tuple(w for a in parts if get_origin(a) is Literal for w in get_args(a))
        kind = next((a for a in parts if isinstance(a, type)), str)
        choices = literal if literal and kind is str else None
        words = literal if literal and kind is not str else ()
        m = f.metadata
        flag = m["flag"] or "--" + f.name.replace("_", "-")
        off = (m["off_flag"] or "--no-" + flag[2:]) if kind is bool else None
        fixed = (m["help"], m["group"], m["paper"], m["unit"], m["self_match"], m["match_only"])
        out.append(Field(f.name, flag, off, kind, choices, words, optional, f.default, *fixed))
    return out


def _field_docs() -> str:
    """The numpydoc "Parameters" section of :class:`Params`, one entry per field from its
    metadata: ``help(intrinsym.Params)`` shows what the CLI's help and the docs show."""
    lines = ["", "    Parameters", "    ----------"]
    for f in describe():
        kind = f.kind.__name__ + (" or None" if f.optional else "")
        if f.choices:
            kind = "{" + ", ".join(repr(c) for c in f.choices) + "}"
        lines.append(f"    {f.name} : {kind}, default {f.default!r}")
        notes = [f"unit {f.unit}" if f.unit else "", f"paper: {f.paper}" if f.paper else ""]
        text = f.help + "".join(f" ({n})" for n in notes if n)
        lines.extend(
            f"        {line}" for line in textwrap.wrap(text, 80, break_long_words=False, break_on_hyphens=False)
        )
    return "\n".join(lines) + "\n"


Params.__doc__ = (Params.__doc__ or "").rstrip() + "\n" + _field_docs()


def markdown_table() -> str:
    """``docs/parameters.md``: every parameter with flag, default, paper value and unit."""
    lines = [
        "# Parameters",
        "",
        "Generated from `intrinsym.params.Params` by `python docs/generate_parameters.py`; do not edit by hand.",
        "Lengths are in units of sqrt(surface area). The Python name is the `Params` field;",
        '`intrinsym detect` / `match` take the flag. "detect only" and "match only" mark the options of one',
        "mode.",
        "",
    ]
    for group in GROUPS:
        lines += [
            f"## {group.capitalize()}",
            "",
            "| field | flag | default | paper | unit | meaning |",
            "|---|---|---|---|---|---|",
        ]
        for f in describe():
            if f.group != group:
                continue
            flag = f"`{f.flag}`" + (f" / `{f.off_flag}`" if f.off_flag else "")
            values = f.choices or f.words
            choices = f" {'One of' if f.choices else 'Or'} {', '.join(f'`{c}`' for c in values)}." if values else ""
            where = " (detect only)" if f.self_match else " (match only)" if f.match_only else ""
            text = f"{f.help}.{choices}{where}".replace("|", "\\|")
            paper = (f.paper or "").replace("|", "\\|")
            lines.append(f"| `{f.name}` | {flag} | `{f.default!r}` | {paper} | {f.unit or ''} | {text} |")
        lines.append("")
    lines += [
        "## Presets",
        "",
        "`--preset paper` sets: " + ", ".join(f"`{k}={v!r}`" for k, v in PRESETS["paper"].items()) + ".",
        "",
    ]
    return "\n".join(lines)
