"""End-to-end detection: shape -> samples -> geodesics -> descriptors -> MRF -> BP.

:func:`detect` matches a shape to itself (partial intrinsic symmetries); :func:`match`
matches shape A to shape B (the paper's ambiguous two-shape case). Both return a
:class:`Result` whose :meth:`Result.save` writes ``result.npz`` and ``run.json``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from . import bp, descriptors, extract, geodesics, mesh, model, sampling, spectral
from .files import atomic_write

class ParameterError(ValueError):
    """An invalid parameter value or combination (a user error, reported in one line)."""


PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    # The paper's Sec. 5 constants: rho 0.4, gamma 0.01, serial schedule, 100 iterations,
    # and its model as written, identity included. Its lambda = 1e6 is a raw number in
    # unstated units; read as a ring half a target spacing wide, it reproduces the
    # paper's behaviour (BP converging in a handful of iterations, sharpening the unary
    # rather than smearing it); 1.5 spacings measured a far weaker model on TOSCA cat0.
    # With remove_trivial=True on top, the identity is removed outright (no "auto" test).
    "paper": dict(rho=0.4, gamma=0.01, schedule="serial", iterations=100, remove_trivial=False, tolerance=0.5,
                  unary="spin", potential="paper", unary_seeds=False, vertex_fit=0.0, zoomout=False, passes=1,
                  trivial_weight=0.0),
}

#: Smallest fraction of the global symmetry's sample pairs that the seeded ZoomOut map
#: must keep (:func:`intrinsym.extract.agreement`), else the extraction's map stays: a
#: guard against ZoomOut drifting to another symmetry (measured on TOSCA / KIDS: 0.94-1.00).
ZOOMOUT_AGREEMENT = 0.5
#: The trivial match's weight when ``trivial_weight="auto"`` keeps the identity (the
#: generated partial shape, 250 / 4000, seeds 0-2: off-limb peak mass median 0.07-0.08
#: and limb mirror hit 0.95-1.00 at 0.7; 0.3 left the body's invented self-map).
NO_PARTNER_WEIGHT = 0.7
#: Unary descriptor terms selectable by name; "a*b" multiplies their potentials.
UNARY_TERMS = ("spin", "spin-multi", "wks", "hks")
#: Similarity-to-potential maps: Eq. 5 with gamma, or calibrated Gaussians.
POTENTIALS = ("paper", "calibrated")
#: How the calibrated potential measures each descriptor's spread (:func:`_unary`).
CALIBRATIONS = ("both", "offset", "descriptor", "local")
#: Targets nearest a calibration point on the surface that the "offset" rule pairs it with.
OFFSET_TARGETS = 3
#: Support radii of the multi-scale spin image, in multiples of ``spin_radius``.
SPIN_SCALES = (0.5, 1.0, 2.0)


@dataclass(frozen=True)
class Params:
    """Every parameter of the pipeline. Lengths are in units of sqrt(surface area).

    Attributes
    ----------
    n_source, n_target : int or None
        Sizes of Ps and Pt (the paper's Table 1 uses |Ps| 111-479, |Pt| 6000-12722, with Pt
        about 4x denser per unit length than Ps). Ignored when the matching spacing is set.
    source_spacing, target_spacing : float or None
        Poisson-disc radius of Ps / Pt instead of a count.
    spin_bins : int
        Spin images are spin_bins x spin_bins (paper: not stated; J&H use 10-20).
    spin_radius : float
        Support radius of a spin image (paper: not stated). 0.25 measured best of
        0.1-0.3 on TOSCA cat0 (mirror hit of the unary alone 0.95 against 0.78 at 0.1):
        the support must dwarf the offset between a point and its nearest target.
    spin_levels : int
        Intensity levels for the NMI entropies (Eq. 2-4).
    spin_cloud : int
        Size of the dense area-uniform surface sample the spin images are built from.
    gamma : float
        Robustness of the unary, Eq. 5 (paper: 0.01).
    rho : float
        Truncation of the pairwise term, Eq. 6 (paper: 0.4).
    tolerance : float
        Half-width delta of the pairwise ring, in target spacings: lambda is chosen so
        that psi = rho^2 at |d(s,q) - d(fs,fq)| = delta. Scale-free.
    lam : float or None
        Raw lambda of Eq. 6 in 1 / (input length unit)^2 (paper: 1e6 in its units);
        overrides ``tolerance``. Not scale-free, by definition.
    schedule : {"serial", "colour", "residual", "flooding"}
        BP message schedule (:func:`intrinsym.bp.belief_propagation`). "colour" (default)
        is a serial schedule whose independent updates run as one batch; "serial" is the
        paper's node-by-node sweeps; "residual" is "colour" that lets a node send only
        while its inputs still change; "flooding" updates all messages at once.
    iterations : int
        Maximum BP iterations T (paper: 100).
    bp_tol : float
        Stop BP when the largest change of a max-normalised message is below this.
    damping : float
        Message damping in [0, 1).
    backend : {"auto", "cpu", "gpu"}
        Where BP runs (:func:`intrinsym.bp.resolve_backend`): "auto" is the GPU when
        CuPy sees a CUDA device, the schedule is not "residual" and ``dtype`` is
        float32, else the CPU.
    remove_trivial : bool
        Weaken the trivial match, the targets within ``trivial_radius`` of the source
        sample (self-matching only; :func:`intrinsym.model.suppress_trivial`).
    trivial_radius : float
    trivial_weight : float or "auto"
        The trivial match's largest unary as a fraction of the row's largest beyond
        ``trivial_radius``, in [0, 1); 0 removes it. Above 0 the identity stays in the
        model as the answer "no symmetric partner", so points without one keep their
        mass at home instead of on a self-map that BP invents (beyond the paper): 0.7
        cleared the generated partial shape's body, but on a posed human with a weak
        unary (TOSCA victoria1) 0.5 already let the identity take the torso (BP mirror
        hit 0.99 -> 0.81). "auto" (default): 0, unless the argmax of BP's marginals
        keeps fewer than ``isometry_threshold`` of the source edges' lengths within
        ``d_error`` or one target spacing, the larger (no global near-isometry: the
        shape's symmetries are partial at most); then BP runs again at
        :data:`NO_PARTNER_WEIGHT`. Below about 100 / 1000 samples the test separates
        little: the targets are too coarse to tell a rough self-map from a true one.
    isometry_threshold : float
        The share of kept edge lengths below which "auto" keeps the identity, in [0, 1].
    passes : int or None
        BP passes; None: 1 when self-matching (the trivial-match removal already takes
        out the identity's mode), 2 when matching two shapes (identity and swap).
        Loopy BP settles on about one mode of a multi-modal posterior (one of a star's
        symmetries; the left/right swap of two frames, not their identity); each
        further pass reruns BP with the earlier passes' argmax removed from the unary
        (:func:`intrinsym.model.suppress_peaks`) and its mode joins the extraction
        (beyond the paper). ``marginals`` stay the first pass's, the others are
        ``Result.pass_marginals``.
    pass_radius : float
        Radius about each row's argmax that a further pass removes.
    seed : int
    dtype : {"float32", "float64"}
        Storage of messages and marginals.
    unary : str
        Descriptor terms of the unary, from ``UNARY_TERMS`` joined by "*" (their
        potentials multiply): "spin" (the paper's spin-image NMI), "spin-multi" (NMI
        averaged over radii ``SPIN_SCALES`` x ``spin_radius``), "wks" / "hks" (log
        wave- / heat-kernel signatures of Laplace-Beltrami eigenpairs).
    potential : {"calibrated", "paper"}
        "paper": Eq. 5 with ``gamma`` on NMI' (spin terms only). "calibrated":
        exp(-d^2 / 2 sigma^2) per term, sigma measured as ``calibration`` says, the
        product floored at ``unary_floor``.
    eigenpairs : int
        Laplace-Beltrami eigenpairs of the WKS / HKS.
    energies : int
        Log-energies of the WKS, diffusion times of the HKS.
    calibration : {"both", "offset", "descriptor", "local"}
        How sigma is measured. "offset": the median descriptor distance from points of
        the target shape to the ``OFFSET_TARGETS`` targets nearest them on the surface,
        i.e. of true matches at the sampling offset. "descriptor": the median distance
        to the ``calibration_k`` nearest targets in descriptor space; on a shape with
        many exact symmetries these all sit at about zero distance and sigma collapses.
        "both": the larger of the two, which keeps the slack a descriptor needs where it
        is not invariant under the symmetry sought (a global WKS on a partial symmetry).
        "local": "both", and when self-matching each source sample's width is raised to
        its own offset spread (the median distance to its ``OFFSET_TARGETS`` nearest
        targets), for points where the descriptor changes fastest (cone points); in
        two-shape matching it is "both".
    calibration_k : int
    unary_floor : float
        Smallest calibrated potential, in (0, 1).
    peak_threshold, d_error : float
        Symmetry extraction (paper Sec. 5.1): peak threshold t on the max-normalised
        marginal (paper: 0.5-0.75) and geodesic error bound of the region growing
        (paper: 0.001-0.15); see :class:`intrinsym.extract.ExtractParams`.
    report_identity : bool
        Also list the identity symmetries (kind "identity") among the extracted ones
        (``symmetries.json``). They arise where the trivial match stays in the model
        (``remove_trivial`` off, as in the paper, or a ``trivial_weight`` above 0).
    unary_seeds : bool
        Also grow symmetries from the peaks of the unary, not only of the marginals
        (beyond the paper; :func:`intrinsym.extract.extract`).
    vertex_fit : float
        Largest relative residual of the local linear fits that extend the global map
        to the input vertices (``symmetry_map.npy``); 0 gives each vertex its sample's
        image (beyond the paper; :func:`intrinsym.extract.fitted_vertex_map`).
    zoomout : bool
        Self-matching: the global map of the input vertices (``symmetry_map.npy``) is
        the global symmetry's sample pairs refined by ZoomOut in the Laplace-Beltrami
        eigenfunctions (:func:`intrinsym.spectral.seeded_symmetry`, the first
        ``zoomout_seed`` of them fitted to the pairs, up to ``zoomout_final``), instead of
        the extraction's cell map; ignores ``vertex_fit`` (beyond the paper).
    zoomout_seed, zoomout_final : int
        Eigenfunctions of the seed and of the last ZoomOut level.
    """

    n_source: int | None = 250
    n_target: int | None = 4000
    source_spacing: float | None = None
    target_spacing: float | None = None
    spin_bins: int = 16
    spin_radius: float = 0.25
    spin_levels: int = 8
    spin_cloud: int = 40000
    gamma: float = 0.01
    rho: float = 0.4
    tolerance: float = 1.5
    lam: float | None = None
    schedule: str = "colour"
    iterations: int = 100
    bp_tol: float = 1e-4
    damping: float = 0.0
    backend: str = "auto"
    remove_trivial: bool = True
    trivial_radius: float = 0.08
    trivial_weight: float | str = "auto"
    isometry_threshold: float = 0.85
    passes: int | None = None
    pass_radius: float = 0.08
    seed: int = 0
    dtype: str = "float32"
    unary: str = "wks*spin"
    potential: str = "calibrated"
    eigenpairs: int = 100
    energies: int = 100
    calibration: str = "local"
    calibration_k: int = 7
    unary_floor: float = 1e-3
    peak_threshold: float = extract.ExtractParams.threshold
    d_error: float = extract.ExtractParams.d_error
    report_identity: bool = False
    unary_seeds: bool = True
    vertex_fit: float = extract.ExtractParams.vertex_fit
    zoomout: bool = True
    zoomout_seed: int = 16
    zoomout_final: int = 50

    def __post_init__(self) -> None:
        checks = [
            (self.n_source is None and self.source_spacing is None, "give n_source or source_spacing"),
            (self.n_target is None and self.target_spacing is None, "give n_target or target_spacing"),
            (self.n_source is not None and self.n_source < 2, "n_source must be at least 2"),
            (self.n_target is not None and self.n_target < 2, "n_target must be at least 2"),
            (self.spin_bins < 2, "spin_bins must be at least 2"),
            (self.spin_radius <= 0, "spin_radius must be positive"),
            (not 2 <= self.spin_levels <= 255, "spin_levels must lie in [2, 255]"),
            (self.gamma <= 0, "gamma must be positive"),
            (not 0 < self.rho < 1, "rho must lie in (0, 1)"),
            (self.tolerance <= 0, "tolerance must be positive"),
            (self.lam is not None and self.lam <= 0, "lam must be positive"),
            (self.schedule not in bp.SCHEDULES, f"schedule must be one of {bp.SCHEDULES}"),
            (self.iterations < 1, "iterations must be at least 1"),
            (not 0 <= self.damping < 1, "damping must lie in [0, 1)"),
            (self.backend not in bp.BACKENDS, f"backend must be one of {bp.BACKENDS}"),
            (self.trivial_radius < 0, "trivial_radius must be non-negative"),
            (self.trivial_weight != "auto" and not (isinstance(self.trivial_weight, (int, float))
                                                    and 0 <= self.trivial_weight < 1),
             "trivial_weight must be 'auto' or lie in [0, 1)"),
            (not 0 <= self.isometry_threshold <= 1, "isometry_threshold must lie in [0, 1]"),
            (self.passes is not None and self.passes < 1, "passes must be at least 1"),
            (self.pass_radius <= 0, "pass_radius must be positive"),
            (self.dtype not in ("float32", "float64"), "dtype must be float32 or float64"),
            (any(t not in UNARY_TERMS for t in self.unary_terms) or len(set(self.unary_terms)) < len(self.unary_terms),
             f"unary must be distinct terms of {UNARY_TERMS} joined by '*'"),
            (self.potential not in POTENTIALS, f"potential must be one of {POTENTIALS}"),
            (self.potential == "paper" and self.unary not in ("spin", "spin-multi"),
             "potential 'paper' (Eq. 5) applies to a single spin-image term only"),
            (self.eigenpairs < 2, "eigenpairs must be at least 2"),
            (self.energies < 2, "energies must be at least 2"),
            (self.calibration not in CALIBRATIONS, f"calibration must be one of {CALIBRATIONS}"),
            (self.calibration_k < 1, "calibration_k must be at least 1"),
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
        if self.backend == "gpu":
            try:
                bp.resolve_backend(self.backend, self.schedule)
            except ValueError as err:
                raise ParameterError(str(err)) from None

    @property
    def unary_terms(self) -> list[str]:
        """The descriptor terms of ``unary``."""
        return self.unary.split("*")

    def extraction(self, no_partner: bool = False) -> extract.ExtractParams:
        """The symmetry-extraction parameters; ``no_partner``: the trivial match was kept
        at a weight (:attr:`Result.extraction_params` knows whether it was)."""
        return extract.ExtractParams(threshold=self.peak_threshold, d_error=self.d_error, unary_seeds=self.unary_seeds,
                                     vertex_fit=self.vertex_fit, no_partner=no_partner,
                                     keep_identity=self.report_identity)


def _extraction_params(p: Params, identity: dict) -> extract.ExtractParams:
    """``p.extraction()``, with ``no_partner`` when BP kept the trivial match at a weight
    (``identity``: ``run.json``'s record of it, empty when there was none)."""
    return p.extraction(no_partner=identity.get("weight", 0.0) > 0)


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
class Surface:
    """A cleaned shape, normalised to unit sqrt(area), with what the stages need.

    Attributes
    ----------
    shape : mesh.Shape
        Normalised (centred, unit area), cleaned, possibly subdivided working shape.
    input_vertices : (N_in, 3) float64
        Vertices of the file as read, for output coordinates.
    vertex_map : (N_in,) int64
        Working vertex representing each input vertex.
    center : (3,) float64
    scale : float
        Input length per normalised length (sqrt of the input surface area).
    graph : scipy.sparse.csr_matrix
        Geodesic graph of the working shape.
    normals : (N, 3) float64
    """

    shape: mesh.Shape
    input_vertices: np.ndarray
    vertex_map: np.ndarray
    center: np.ndarray
    scale: float
    graph: Any
    normals: np.ndarray

    def to_input(self, points: np.ndarray) -> np.ndarray:
        """Normalised coordinates -> the input file's coordinates."""
        return points * self.scale + self.center

    def nearest_input_vertex(self, points: np.ndarray) -> np.ndarray:
        """Index of the input vertex nearest each normalised point, (n,) int64."""
        _, idx = cKDTree(self.input_vertices).query(self.to_input(points))
        return idx.astype(np.int64)


def prepare(shape: mesh.Shape, min_vertices: int = 0) -> Surface:
    """Clean, normalise to unit surface area and (for meshes) subdivide a shape.

    Parameters
    ----------
    shape : mesh.Shape
    min_vertices : int
        Meshes with fewer vertices are midpoint-subdivided until they have this many, so
        that the dense target sampling has a surface to choose from.
    """
    cleaned, vertex_map = mesh.clean(shape)
    area = mesh.surface_area(cleaned)
    if not np.isfinite(area) or area <= 0:
        raise mesh.InputError(f"{shape.path or 'input'}: the surface has zero area")
    center = cleaned.vertices.mean(axis=0)
    scale = float(np.sqrt(area))
    vertices = (cleaned.vertices - center) / scale
    faces = cleaned.faces
    if faces is not None and len(vertices) < min_vertices:
        vertices, faces = sampling.subdivide_to(vertices, faces, min_vertices)
    work = mesh.Shape(vertices, faces, shape.path)
    return Surface(
        shape=work,
        input_vertices=np.asarray(shape.vertices, dtype=np.float64),
        vertex_map=vertex_map,
        center=center,
        scale=scale,
        graph=geodesics.surface_graph(vertices, faces),
        normals=mesh.vertex_normals(work),
    )


def _as_shape(obj: str | os.PathLike | mesh.Shape | tuple) -> mesh.Shape:
    if isinstance(obj, mesh.Shape):
        return obj
    if isinstance(obj, (str, os.PathLike)):
        return mesh.load(obj)
    if isinstance(obj, tuple):
        return mesh.from_arrays(*obj)
    if hasattr(obj, "vertices"):  # a trimesh.Trimesh or PointCloud
        faces = getattr(obj, "faces", None)
        return mesh.from_arrays(np.asarray(obj.vertices), None if faces is None else np.asarray(faces))
    raise TypeError(f"cannot read a shape from {type(obj).__name__}")


def _sample(surface: Surface, n: int | None, spacing: float | None, seed: int) -> np.ndarray:
    """Poisson-disc sample of working vertices, by count or by spacing."""
    verts = surface.shape.vertices
    if spacing is not None:
        chosen = sampling.farthest_point_sampling(verts, spacing=spacing, seed=seed)
    elif n > len(verts):
        raise ParameterError(f"{surface.shape.path or 'shape'}: asked for {n} samples but the surface has {len(verts)} points")
    else:
        chosen = sampling.farthest_point_sampling(verts, n=n, seed=seed)
    # Index order, not selection order: near-ties in the farthest-point order flip with
    # rounding (e.g. after a change of units), the chosen set does not.
    return np.sort(chosen)


def _spin(surface: Surface, vertices: np.ndarray, p: Params, radius: float) -> np.ndarray:
    """Quantised spin images of working vertices with support ``radius``, (n, bins^2) uint8."""
    shape = surface.shape
    if shape.is_cloud:
        cloud = shape.vertices
    else:
        cloud = sampling.area_uniform_points(shape.vertices, shape.faces, p.spin_cloud, seed=p.seed)[0]
    images = descriptors.spin_images(
        shape.vertices[vertices], surface.normals[vertices], cloud, radius, p.spin_bins
    )
    return descriptors.quantize(images, p.spin_levels)


def _spectrum(surface: Surface, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Laplace-Beltrami eigenpairs of the working shape: (K,) values, (N, K) vectors,
    K = ``k`` (at most N - 1)."""
    shape = surface.shape
    return descriptors.eigenpairs(shape.vertices, shape.faces, min(k, len(shape.vertices) - 1))


Spectrum = tuple[np.ndarray, np.ndarray]


def _spectra(src: Surface, tgt: Surface, p: Params, self_match: bool) -> tuple[Spectrum, Spectrum] | None:
    """Eigenpairs of source and target, computed once for the unary's "wks" / "hks"
    terms (``p.eigenpairs``) and the seeded ZoomOut (``p.zoomout_final`` + 1 at least);
    None when neither needs them."""
    spectral_terms = bool({"wks", "hks"} & set(p.unary_terms))
    if not spectral_terms and not (self_match and p.zoomout):
        return None
    a = _spectrum(src, p.eigenpairs if spectral_terms else p.zoomout_final + 1)
    return a, (a if tgt is src else _spectrum(tgt, p.eigenpairs))


def _term_distances(
    term: str, queries: list[tuple[Surface, np.ndarray]], tgt: Surface, pt: np.ndarray, p: Params,
    spectrum: Callable[[Surface], Spectrum],
) -> list[np.ndarray]:
    """Descriptor distances of one unary term from each query point set to the targets.

    1 - NMI' for spin images (averaged over radii ``SPIN_SCALES`` for "spin-multi"), the
    Euclidean distance of log signatures for "wks" and "hks", on the energy / time grid
    of the first query's surface (the source), so that two shapes' signatures compare.

    Returns
    -------
    list of (len(points), T) float64, one per ``(surface, points)`` of ``queries``.
    """
    if term in ("spin", "spin-multi"):
        radii = [p.spin_radius * c for c in (SPIN_SCALES if term == "spin-multi" else (1.0,))]
        images = [_spin(tgt, pt, p, r) for r in radii]
        return [
            1.0 - np.mean([descriptors.nmi(_spin(surface, points, p, r), b, p.spin_levels)
                           for r, b in zip(radii, images)], axis=0).astype(np.float64)
            for surface, points in queries
        ]
    grid = spectrum(queries[0][0])[0]
    if term == "wks":
        energies, sigma = descriptors.wks_energies(grid, p.energies)

        def signature(surface: Surface, points: np.ndarray) -> np.ndarray:
            ev, phi = spectrum(surface)
            return descriptors.wave_kernel_signature(ev, phi[points], energies, sigma)
    else:
        times = descriptors.hks_times(grid, p.energies)

        def signature(surface: Surface, points: np.ndarray) -> np.ndarray:
            ev, phi = spectrum(surface)
            return descriptors.heat_kernel_signature(ev, phi[points], times)
    b = signature(tgt, pt)
    return [cdist(signature(surface, points), b) for surface, points in queries]


def _near_targets(surface: Surface, points: np.ndarray, pt: np.ndarray, radius: float) -> np.ndarray:
    """(len(points), T) geodesic distances from working vertices to the targets, inf
    beyond ``radius``."""
    return geodesics.distances_from(surface.graph, points, limit=radius)[:, pt]


def _nearest_targets(dist: np.ndarray, k: int) -> np.ndarray:
    """(m, k) the k targets nearest each row of ``dist`` ((m, T), inf where unknown);
    -1 where fewer than k are within reach."""
    k = min(k, dist.shape[1])
    near = np.argpartition(dist, k - 1, axis=1)[:, :k]
    return np.where(np.isfinite(np.take_along_axis(dist, near, axis=1)), near, -1)


def _offset_calibrated(p: Params) -> bool:
    """Whether the unary's widths use the "offset" rule (alone or in "both")."""
    return p.potential == "calibrated" and p.calibration != "descriptor"


def _unary(
    src: Surface, tgt: Surface, ps: np.ndarray, pt: np.ndarray, p: Params,
    spectra: tuple[Spectrum, Spectrum] | None, spacing: float, near_source: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Unary potentials of the terms named by ``p.unary`` and their floor.

    Each term gives an (S, T) descriptor distance (:func:`_term_distances`; "wks" and
    "hks" use ``spectra``, the eigenpairs of source and target, see :func:`_spectra`);
    ``p.potential`` maps them to potentials. The "offset" calibration measures each
    term's spread on true matches: from calibration points on the target shape (the
    source samples when self-matching, else a Poisson sample of the same size) to the
    ``OFFSET_TARGETS`` targets nearest them on the surface, ``spacing`` apart. When
    self-matching, ``near_source`` ((S, T), from :func:`_near_targets` out to at least
    ``(OFFSET_TARGETS + 2) * spacing``) gives the source samples' distances to them.

    Returns
    -------
    unary : (S, T) float64
    floor : float
        The smallest value the potential map can take.
    """
    def spectrum(surface: Surface) -> Spectrum:
        return spectra[0] if surface is src else spectra[1]

    offset = _offset_calibrated(p)
    queries = [(src, ps)]
    if offset and tgt is not src:
        queries.append((tgt, _sample(tgt, len(ps), None, p.seed + 2)))
    per_term = [_term_distances(term, queries, tgt, pt, p, spectrum) for term in p.unary_terms]
    distances = [d[0] for d in per_term]
    if p.potential == "paper":
        return model.nmi_potential(1.0 - distances[0], p.gamma), model.potential_floor(p.gamma)
    scales = [0.0] * len(distances)
    if offset:
        if near_source is None or tgt is not src:
            near_source = _near_targets(tgt, queries[-1][1], pt, (OFFSET_TARGETS + 2) * spacing)
        near = _nearest_targets(near_source, OFFSET_TARGETS)
        scales = [model.descriptor_scale(d[-1], near=near) for d in per_term]
    if p.calibration != "offset":
        scales = [max(s, model.descriptor_scale(d, p.calibration_k)) for s, d in zip(scales, distances)]
    if p.calibration == "local" and tgt is src:
        scales = [np.maximum(s, model.row_scales(d, near))[:, None] for s, d in zip(scales, distances)]
    return model.calibrated_potential(distances, scales, p.unary_floor), p.unary_floor


@dataclass
class Result:
    """What a run produced; see :meth:`save` for the file layout.

    Attributes
    ----------
    source_points : (S, 3) float64
        Source samples in the input's coordinates.
    target_points : (T, 3) float64
        Target samples in the (target) input's coordinates.
    source_vertex, target_vertex : (S,), (T,) int64
        Nearest input vertex of each sample.
    edges : (E, 2) int64
        Source-graph edges (i < j) into the source samples.
    unary : (S, T) float32
        Phi of Eq. 5 (after trivial-match removal when enabled).
    marginals : (S, T) float32
        Beliefs of Eq. 8, rows summing to 1.
    params : Params
    info : dict
        Sizes, seconds per stage, BP statistics, inputs and versions (``run.json``).
    support : extract.Support or None
        Geodesics and Voronoi cells the symmetry extraction needs (``result.npz``, keys
        :attr:`extract.Support.KEYS`).
    extraction : extract.Extraction or None
        Symmetries (``symmetries.json``) and the global one (``symmetry_map.npy``).
    global_map : (N_in,) int64 or None
        Image of every input vertex under the global symmetry when detection refined it
        (``Params.zoomout``); None: ``symmetry_map.npy`` is the extraction's
        (:func:`intrinsym.extract.fitted_vertex_map`). Stored in ``result.npz``.
    pass_marginals : (P - 1, S, T) float32 or None
        Marginals (rows summing to 1) of the BP passes after the first
        (``Params.passes``); None for one pass. Stored in ``result.npz``; their unaries
        follow from ``unary`` (:attr:`passes`).
    """

    source_points: np.ndarray
    target_points: np.ndarray
    source_vertex: np.ndarray
    target_vertex: np.ndarray
    edges: np.ndarray
    unary: np.ndarray
    marginals: np.ndarray
    params: Params
    info: dict = field(default_factory=dict)
    support: extract.Support | None = None
    extraction: extract.Extraction | None = None
    global_map: np.ndarray | None = None
    pass_marginals: np.ndarray | None = None

    ARRAYS = ("source_points", "target_points", "source_vertex", "target_vertex", "edges", "unary", "marginals")

    def extraction_params(self) -> extract.ExtractParams:
        """The extraction parameters this result was extracted with (``no_partner`` from
        the trivial weight BP used, ``info["identity"]``)."""
        return _extraction_params(self.params, self.info.get("identity", {}))

    def mrf(self) -> model.MRF:
        """The MRF of BP's first pass (``unary``, the source graph, the target rings and
        the resolved lambda); needs ``support``."""
        if self.support is None:
            raise ValueError("the result has no support (geodesics) to rebuild its MRF from")
        return model.MRF(self.unary, self.edges, self.support.edge_length, self.support.targets,
                         self.info["resolved"]["lambda_normalised"], self.params.rho)

    @property
    def passes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(marginals, unary) of every BP pass after the first, as the extraction takes
        them: each pass's unary is the one before it with the argmax of the pass before
        it removed (:func:`intrinsym.model.suppress_peaks`), as :func:`detect` ran them."""
        if self.pass_marginals is None:
            return []
        floor = self.info["resolved"]["unary_floor"]
        out, unary = [], self.unary
        for before, marginals in zip([self.marginals, *self.pass_marginals], self.pass_marginals):
            unary = model.suppress_peaks(unary, before, self.support.targets, self.params.pass_radius, floor)
            out.append((marginals, unary))
        return out

    def save(self, out_dir: str | os.PathLike) -> Path:
        """Write ``out_dir/result.npz`` and ``out_dir/run.json`` (atomically), and with an
        extraction ``symmetries.json`` and ``symmetry_map.npy``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        arrays = {name: getattr(self, name) for name in self.ARRAYS}
        if self.support is not None:
            arrays.update(self.support.to_arrays())
        if self.global_map is not None:
            arrays["global_map"] = np.asarray(self.global_map, dtype=np.int64)
        if self.pass_marginals is not None:
            arrays["pass_marginals"] = np.asarray(self.pass_marginals, dtype=np.float32)
        run = {"params": dataclasses.asdict(self.params), **self.info}
        atomic_write(out / "result.npz", lambda f: np.savez_compressed(f, **arrays), binary=True)
        atomic_write(out / "run.json", lambda f: json.dump(run, f, indent=2))
        if self.support is not None and self.extraction is not None:
            listed = extract.records(self.extraction.symmetries, self.source_vertex, self.target_vertex, self.support)
            atomic_write(out / "symmetries.json", lambda f: json.dump(listed, f))
            vmap = self.symmetry_map()
            atomic_write(out / "symmetry_map.npy", lambda f: np.save(f, vmap), binary=True)
        return out

    def symmetry_map(self) -> np.ndarray:
        """(N_in,) int64: the image of every input vertex under the global symmetry
        (``symmetry_map.npy``), -1 everywhere when there is none.

        The seeded ZoomOut map when detection made one (``global_map``), else the
        extraction's (:func:`intrinsym.extract.fitted_vertex_map`). Needs ``support``
        and ``extraction``.
        """
        if self.support is None or self.extraction is None:
            raise ValueError("the result has no extraction")
        g = self.extraction.global_index
        if g < 0:
            return np.full(len(self.support.vertex_source), -1, dtype=np.int64)
        if self.global_map is not None:
            return np.asarray(self.global_map, dtype=np.int64)
        return extract.fitted_vertex_map(self.extraction.symmetries[g], self.support, self.edges, self.source_points,
                                         self.target_points, self.target_vertex, self.extraction.params)

    @classmethod
    def load(cls, out_dir: str | os.PathLike) -> Result:
        """Read a result written by :meth:`save`."""
        out = Path(out_dir)
        with np.load(out / "result.npz") as z:
            arrays = {name: z[name] for name in cls.ARRAYS}
            has_support = all(key in z.files for key in extract.Support.KEYS)
            keys = extract.Support.KEYS + tuple(k for k in extract.Support.OPTIONAL_KEYS if k in z.files)
            support = extract.Support.from_arrays({k: z[k] for k in keys}) if has_support else None
            optional = {key: z[key] for key in ("global_map", "pass_marginals") if key in z.files}
        run = json.loads((out / "run.json").read_text())
        params = Params(**run.pop("params"))
        return cls(**arrays, params=params, info=run, support=support, **optional)


def _versions() -> dict[str, str]:
    import numba
    import scipy
    import trimesh

    from . import __version__

    return {
        "intrinsym": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "trimesh": trimesh.__version__,
    }


class _Clock:
    """Seconds per named stage."""

    def __init__(self, log: Callable[[str], None] | None) -> None:
        self.seconds: dict[str, float] = {}
        self.log = log
        self._t = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + now - self._t
        self._t = now
        if self.log is not None:
            self.log(f"{stage}: {self.seconds[stage]:.2f} s")


def _model_bytes(n_s: int, n_t: int, n_edges: int, itemsize: int, passes: int = 1) -> int:
    """Rough peak of the arrays sized by |Ps| x |Pt| and |E| x |Pt|."""
    return (6 + 2 * (passes - 1)) * n_s * n_t * 4 + 2 * n_edges * n_t * itemsize


def _solve(
    src: Surface,
    tgt: Surface,
    ps: np.ndarray,
    pt: np.ndarray,
    p: Params,
    clock: _Clock,
    self_match: bool,
    log: Callable[[str], None] | None,
) -> Result:
    """Stages shared by detect and match, from the samples onwards."""
    path = src.shape.path
    t_spacing = p.target_spacing or sampling.spacing_for_count(1.0, len(pt))
    edges = geodesics.voronoi_adjacency(src.graph, ps)
    if len(edges) == 0:
        raise ParameterError(f"{path or 'shape'}: the source samples form no neighbourhood graph")
    edge_length = geodesics.pair_distances(src.graph, ps[edges])
    dtype = np.dtype(p.dtype)
    n_passes = p.passes if p.passes is not None else 1 if self_match else 2
    mesh.check_memory(_model_bytes(len(ps), len(pt), len(edges), dtype.itemsize, n_passes), "the model", path)
    if p.lam is not None:
        lam = p.lam * src.scale**2
    else:
        lam = model.lambda_for_tolerance(p.tolerance * t_spacing, p.rho)
    delta = model.truncation_width(lam, p.rho)
    ring = float(edge_length.max() + delta)  # the exact message needs this much
    targets = geodesics.local_distances(tgt.graph, pt, max(ring, p.pass_radius) if n_passes > 1 else ring)
    clock.lap("geodesics")

    spectra = _spectra(src, tgt, p, self_match)
    # one Dijkstra per source sample serves the calibration and the trivial match
    trivial = self_match and p.remove_trivial and p.trivial_radius > 0
    reach = max((OFFSET_TARGETS + 2) * t_spacing if _offset_calibrated(p) else 0.0,
                p.trivial_radius if trivial else 0.0)
    near = _near_targets(src, ps, pt, reach) if self_match and reach > 0 else None
    unary, floor = _unary(src, tgt, ps, pt, p, spectra, t_spacing, near)
    clock.lap("descriptors")
    auto = p.trivial_weight == "auto"
    weight = 0.0 if auto else p.trivial_weight

    def weakened(weight: float) -> np.ndarray:
        return (model.suppress_trivial(unary, near, p.trivial_radius, floor, weight) if trivial else unary
                ).astype(np.float32)

    mrf = model.MRF(weakened(weight), edges, edge_length, targets, lam, p.rho)
    clock.lap("unary")

    def progress(it: int, change: float) -> None:
        if log is not None:
            log(f"bp iteration {it}: max message change {change:.3g}")

    def run_bp() -> bp.BPResult:
        return bp.belief_propagation(mrf, p.schedule, p.iterations, p.bp_tol, p.damping, p.seed, dtype.type,
                                     progress, backend=p.backend)

    runs = [run_bp()]
    identity = {"weight": float(weight)} if trivial else {}
    if trivial and auto:
        # With the identity removed every row puts its mass somewhere, and on a shape
        # without a global symmetry BP invents a self-map that keeps short distances
        # only roughly (the generated partial shape: 0.76-0.79 of the edges, seeds 0-4);
        # a true, posed symmetry's argmax keeps 0.90 (victoria1) to 1.00 (TOSCA, KIDS).
        kept = extract.consistency(runs[0].marginals.argmax(axis=1),
                                   extract.SourceGraph.from_edges(edges, edge_length, len(ps)), targets,
                                   max(p.d_error, t_spacing))
        identity |= {"isometry": kept, "threshold": p.isometry_threshold}
        if kept < p.isometry_threshold:
            identity["weight"] = NO_PARTNER_WEIGHT
            identity["removed_iterations"] = runs[0].iterations
            mrf = dataclasses.replace(mrf, unary=weakened(NO_PARTNER_WEIGHT))
            runs = [run_bp()]
    unary = mrf.unary
    marginals = [runs[0].marginals.astype(np.float32)]
    passes = []
    for _ in range(1, n_passes):
        # Result.passes derives these unaries again from the stored marginals
        mrf = dataclasses.replace(mrf, unary=model.suppress_peaks(mrf.unary, marginals[-1], targets,
                                                                  p.pass_radius, floor))
        runs.append(run_bp())
        marginals.append(runs[-1].marginals.astype(np.float32))
        passes.append((marginals[-1], mrf.unary))
    res = runs[0]
    clock.lap("bp")
    support = extract.Support(
        edge_length=edge_length,
        targets=targets,
        vertex_source=geodesics.voronoi_cells(src.graph, ps)[src.vertex_map],
        vertex_target=geodesics.voronoi_cells(tgt.graph, pt)[tgt.vertex_map],
        self_match=self_match,
        source_vertices=src.input_vertices,
        target_vertices=tgt.input_vertices,
    )
    extraction = extract.from_result(
        marginals[0], edges, support, src.shape.vertices[ps], tgt.shape.vertices[pt],
        _extraction_params(p, identity), unary=unary,
        passes=passes,
    )
    clock.lap("extract")
    source_vertex = src.nearest_input_vertex(src.shape.vertices[ps])
    global_map, zoomout = None, {}
    if self_match and p.zoomout and extraction.global_index >= 0:
        global_map, kept = seeded_global_map(src, ps, pt, source_vertex, extraction.symmetries[extraction.global_index],
                                             support, spectra[0][1], p)
        zoomout = {"zoomout": {"agreement": kept, "used": global_map is not None}}
        clock.lap("zoomout")
    info = {
        "sizes": {
            "source": int(len(ps)),
            "target": int(len(pt)),
            "edges": int(len(edges)),
            "directed_edges": int(2 * len(edges)),
            "max_degree": int(np.bincount(edges.ravel(), minlength=len(ps)).max()),
            "target_distance_entries": int(len(targets.dist)),
            "source_vertices": int(len(src.shape.vertices)),
            "target_vertices": int(len(tgt.shape.vertices)),
        },
        "resolved": {
            "lambda_normalised": lam,
            "lambda_input_units": lam / src.scale**2,
            "delta": delta,
            "target_spacing": t_spacing,
            "target_radius": targets.radius,
            "unary_floor": floor,
            "scale": src.scale,
        },
        "seconds": clock.seconds,
        "bp": {
            "backend": res.backend,
            "iterations": res.iterations,
            "converged": res.converged,
            "max_change": res.max_change,
            "history": res.history,
            "seconds_per_iteration": float(np.mean(res.seconds)),
            "setup_seconds": res.setup_seconds,
            "message_updates": int(sum(res.updates)),
            "passes": [{"iterations": run.iterations, "converged": run.converged, "max_change": run.max_change}
                       for run in runs[1:]],
        },
        **zoomout,
        **({"identity": identity} if identity else {}),
        "versions": _versions(),
    }
    return Result(
        source_points=src.to_input(src.shape.vertices[ps]),
        target_points=tgt.to_input(tgt.shape.vertices[pt]),
        source_vertex=source_vertex,
        target_vertex=tgt.nearest_input_vertex(tgt.shape.vertices[pt]),
        edges=edges.astype(np.int64),
        unary=unary,
        marginals=marginals[0],
        params=p,
        info=info,
        support=support,
        extraction=extraction,
        global_map=global_map,
        pass_marginals=np.stack(marginals[1:]) if passes else None,
    )


def seeded_global_map(
    surface: Surface,
    ps: np.ndarray,
    pt: np.ndarray,
    source_vertex: np.ndarray,
    symmetry: extract.Symmetry,
    support: extract.Support,
    evecs: np.ndarray,
    p: Params,
) -> tuple[np.ndarray | None, float]:
    """The global symmetry of a self-matching run refined by seeded ZoomOut.

    The symmetry's sample pairs seed :func:`intrinsym.spectral.seeded_symmetry` on the
    working shape; its map goes back to the input vertices (nearest input vertex) and
    is kept when it sends at least ``ZOOMOUT_AGREEMENT`` of the pairs near their
    targets (:func:`intrinsym.extract.agreement`).

    Parameters
    ----------
    surface : Surface
    ps, pt : (S,), (T,) int64
        Working vertices of the source and target samples.
    source_vertex : (S,) int64
        Input vertex of every source sample.
    symmetry : extract.Symmetry
        The global symmetry (sample indices).
    support : extract.Support
    evecs : (N, K) float array
        Laplace-Beltrami eigenfunctions of the working shape, constant first.
    p : Params

    Returns
    -------
    global_map : (N_in,) int64 or None
        Image of every input vertex; None when the guard rejects the map.
    agreement : float
    """
    vertices = surface.shape.vertices
    # only the working vertices of input vertices are mapped, onto those same vertices
    image = spectral.seeded_symmetry(vertices, evecs, ps[symmetry.source], pt[symmetry.target], p.zoomout_seed,
                                     p.zoomout_final, points=surface.vertex_map,
                                     candidates=np.unique(surface.vertex_map))
    global_map = surface.nearest_input_vertex(vertices[image])
    kept = extract.agreement(symmetry, global_map, source_vertex, support)
    return (global_map if kept >= ZOOMOUT_AGREEMENT else None), kept


def _min_vertices(p: Params) -> int:
    return 3 * max(p.n_source or 0, p.n_target or 0)


def detect(
    shape: str | os.PathLike | mesh.Shape | tuple,
    preset: str = "default",
    log: Callable[[str], None] | None = None,
    **params: Any,
) -> Result:
    """Marginals of the self-matching MRF: where may every source sample map on the shape?

    Parameters
    ----------
    shape : path, mesh.Shape, (vertices, faces) tuple or trimesh object
        A triangle mesh or a point cloud (faces None).
    preset : {"default", "paper"}
    log : callable(str), optional
        Receives one line per finished stage and BP iteration.
    **params
        Any field of :class:`Params`.

    Returns
    -------
    Result
    """
    p = make_params(preset, **params)
    clock = _Clock(log)
    s = _as_shape(shape)
    clock.lap("load")
    surf = prepare(s, _min_vertices(p))
    clock.lap("prepare")
    pt = _sample(surf, p.n_target, p.target_spacing, p.seed)
    ps = _sample(surf, p.n_source, p.source_spacing, p.seed + 1)
    clock.lap("sampling")
    result = _solve(surf, surf, ps, pt, p, clock, True, log)
    result.info = {"mode": "detect", "input": str(s.path), "preset": preset, **result.info}
    return result


def match(
    a: str | os.PathLike | mesh.Shape | tuple,
    b: str | os.PathLike | mesh.Shape | tuple,
    preset: str = "default",
    log: Callable[[str], None] | None = None,
    **params: Any,
) -> Result:
    """Marginals of the two-shape MRF: source samples on A, target labels on B.

    Both shapes are normalised to unit area separately, so near-isometric frames of one
    object match whatever their units. Parameters as in :func:`detect`; the trivial
    match does not apply.
    """
    p = make_params(preset, **params)
    clock = _Clock(log)
    sa, sb = _as_shape(a), _as_shape(b)
    clock.lap("load")
    surf_a = prepare(sa, _min_vertices(p))
    surf_b = prepare(sb, _min_vertices(p))
    clock.lap("prepare")
    pt = _sample(surf_b, p.n_target, p.target_spacing, p.seed)
    ps = _sample(surf_a, p.n_source, p.source_spacing, p.seed + 1)
    clock.lap("sampling")
    result = _solve(surf_a, surf_b, ps, pt, p, clock, False, log)
    result.info = {"mode": "match", "input": str(sa.path), "target_input": str(sb.path), "preset": preset, **result.info}
    return result
