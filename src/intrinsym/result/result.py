"""What a run produced, and its folder: ``result.npz``, ``run.json``,
``symmetries.json`` and ``symmetry_map.npy`` (``docs/format.md``).

:meth:`Result.save` writes a folder, :meth:`Result.load` reads one, including folders of
the older format versions :mod:`intrinsym.result.runinfo` reads.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, cast

import numpy as np

from .. import resources
from ..errors import ResultError
from ..extract import records
from ..extract.support import Support
from ..extract.symmetry import Extraction, ExtractParams, Symmetry, with_inverse
from ..files import Writer, npz_headers, save_npz, write_set
from ..globalmap.confidence import (
    PART_CALIBRATION,
    PARTIAL_CALIBRATION,
    calibrated,
    carried_confidence,
    disagreement,
    map_mass,
    round_trip,
    score,
)
from ..globalmap.globalmap import supported_map
from ..globalmap.vertex_maps import fitted_vertex_map
from ..mrf import model
from ..params import Params
from .modes import two_modes
from .runinfo import RunInfo, Sizes, stored_params

#: What reading a truncated or corrupt result file raises.
_UNREADABLE = (OSError, EOFError, ValueError, KeyError, TypeError, AttributeError, zipfile.BadZipFile, zlib.error)

#: The older name of each renamed ``result.npz`` array: the sample vertices' of format
#: version 1, the global map's of versions 2 to 4 (version 1 called it ``global_map`` too).
OLD_ARRAYS = {
    "source_point_vertex": "source_vertex",
    "target_point_vertex": "target_vertex",
    "global_map": "zoomout_map",
}


@dataclass
class Result:
    """What a run produced; see :meth:`save` for the file layout.

    Attributes
    ----------
    source_points : (S, 3) float64
        Source samples in the input's coordinates.
    target_points : (T, 3) float64
        Target samples in the (target) input's coordinates.
    source_point_vertex, target_point_vertex : (S,), (T,) int64
        Nearest input vertex of each sample.
    edges : (E, 2) int64
        Source-graph edges (i < j) into the source samples.
    unary : (S, T) float32
        Phi of Eq. 5 (after trivial-match removal when enabled).
    marginals : (S, T) float32
        Beliefs of Eq. 8, rows summing to 1.
    params : Params
    info : RunInfo
        Sizes, seconds per stage, BP statistics, inputs and versions (``run.json``).
    support : Support or None
        Geodesics and Voronoi cells the symmetry extraction needs.
    extraction : Extraction or None
        Symmetries (``symmetries.json``) and the global one.
    global_map : (N_in,) int64 or None
        The global symmetry's dense map the run chose among its candidates (seeded
        ZoomOut's, the extraction's, a spectral one: ``run.json``'s ``global_map``), as the
        image of every input vertex, -1 where it has no support; in ``match`` of a whole to
        its part (``info.target_part``), the part's own match to the whole inverted, -1
        where the source has no counterpart on the part
        (:func:`intrinsym.pipeline.invert_part_match`); None: no global symmetry, or a run
        without the dense map (:meth:`symmetry_map` is then the extraction's).
    pass_marginals : (P - 1, S, T) float32 or None
        Marginals of the BP passes after the first (``Params.passes``); None for one
        pass. Their unaries follow from ``unary`` (:attr:`passes`).
    map_distortion : (N_in,) float32 or None
        The local distortion of ``global_map`` at every input vertex
        (:func:`intrinsym.globalmap.distortion.local_distortion`, sqrt(area) units, NaN where
        unknown), which picks the confidence's calibration table; None without it (a
        result of an earlier version: the first table).
    target_symmetry : (N_b,) int64 or None
        A match's target's own symmetry map (input vertices, -1 where it has none), as
        given to :func:`intrinsym.pipeline.match`: the second of the two modes
        (:func:`intrinsym.result.modes.two_modes`) is it applied after the first; None
        when none was given (and for ``detect``).
    mode_marginals : (2, S, T) float32 or None
        A match's marginals given each of its two modes
        (:func:`intrinsym.result.modes.two_modes`): BP on the unary conditioned on the
        mode's sample images (:func:`intrinsym.mrf.model.condition_on_images`,
        ``Params.mode_width``); a mode without images is BP's first pass. None for
        ``detect`` and for a result of an earlier version.
    """

    source_points: np.ndarray
    target_points: np.ndarray
    source_point_vertex: np.ndarray
    target_point_vertex: np.ndarray
    edges: np.ndarray
    unary: np.ndarray
    marginals: np.ndarray
    params: Params
    info: RunInfo
    support: Support | None = None
    extraction: Extraction | None = None
    global_map: np.ndarray | None = None
    pass_marginals: np.ndarray | None = None
    map_distortion: np.ndarray | None = None
    target_symmetry: np.ndarray | None = None
    mode_marginals: np.ndarray | None = None

    #: Every file of the result set (:meth:`save` writes those the result has).
    FILES: ClassVar[tuple[str, ...]] = (
        "result.npz",
        "run.json",
        "symmetries.json",
        "symmetry_map.npy",
        "symmetry_maps.npy",
        "symmetry_mass.npy",
        "symmetry_confidence.npy",
        "modes.json",
        "mode_maps.npy",
    )
    #: What ``intrinsym evaluate``, ``view`` and ``render`` derive from a result set in its
    #: folder: a new set removes them (:meth:`save`).
    DERIVED: ClassVar[tuple[str, ...]] = ("scores.json", "curve.png", "viewer.html", "figures")
    ARRAYS: ClassVar[tuple[str, ...]] = (
        "source_points",
        "target_points",
        "source_point_vertex",
        "target_point_vertex",
        "edges",
        "unary",
        "marginals",
    )

    @property
    def global_symmetry(self) -> Symmetry | None:
        """The global symmetry (sample pairs), None when there is none or no extraction."""
        return None if self.extraction is None else self.extraction.global_symmetry

    def extraction_params(self) -> ExtractParams:
        """The extraction parameters this result was extracted with (``no_partner`` when
        BP kept the trivial match at a weight)."""
        return self.params.extraction(no_partner=self.info.no_partner)

    def mrf(self) -> model.MRF:
        """The MRF of BP's first pass (``unary``, the source graph, the target rings and
        the resolved lambda); needs ``support``."""
        if self.support is None:
            raise ValueError("the result has no support (geodesics) to rebuild its MRF from")
        return model.MRF(
            self.unary,
            self.edges,
            self.support.edge_length,
            self.support.targets,
            self.info.resolved.lambda_normalised,
            self.params.rho,
        )

    @property
    def passes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(marginals, unary) of every BP pass after the first, as the extraction takes
        them: each pass's unary is the one before it with the argmax of the pass before
        it removed (:func:`intrinsym.mrf.model.suppress_peaks`), as the run made them."""
        if self.pass_marginals is None or self.support is None:
            return []
        floor = self.info.resolved.unary_floor
        out, unary = [], self.unary
        for before, marginals in zip([self.marginals, *self.pass_marginals], self.pass_marginals):
            unary = model.suppress_peaks(unary, before, self.support.targets, self.params.pass_radius, floor)
            out.append((marginals, unary))
        return out

    def mixed_marginals(self) -> np.ndarray:
        """(S, T) float64: the marginals of every mode, each row normalised to sum 1, mixed.

        A match (``mode_marginals``): each mode's marginals weighted by the mode's
        confidence (:func:`~intrinsym.result.modes.two_modes`), the posterior of a source
        sample when the match is one mode or the other. Otherwise every BP pass's
        marginals with the same weight: each pass is BP settled on one mode (a further
        pass removes the earlier passes' argmax from the unary); with one pass it is the
        marginals, normalised.
        """
        tiny = np.finfo(np.float64).tiny
        if self.mode_marginals is not None:
            weights = two_modes(self).confidence
            parts = [np.asarray(m, dtype=np.float64) for m in self.mode_marginals]
        else:
            later = () if self.pass_marginals is None else tuple(self.pass_marginals)
            parts = [np.asarray(m, dtype=np.float64) for m in (self.marginals, *later)]
            weights = np.full(len(parts), 1.0 / len(parts))
        normed = np.stack([m / np.maximum(m.sum(axis=1, keepdims=True), tiny) for m in parts])
        return np.tensordot(weights, normed, axes=1)

    def symmetry_map(self) -> np.ndarray:
        """(N_in,) int64: the image of every input vertex under the dominant symmetry
        (``symmetry_map.npy``; :attr:`intrinsym.extract.symmetry.Extraction.dominant_index`: the
        global one, else the partial one over the most of the shape), -1 where it has no
        support (off its parts; in ``detect``, where the map does not return a vertex to
        itself) and everywhere when there is none.

        The global map the run chose (``global_map``,
        :func:`intrinsym.globalmap.globalmap.choose_global_map`; a whole matched to its
        part: the part's match inverted, -1 where it has no counterpart; a shape without
        a global symmetry: the partial map
        :func:`intrinsym.globalmap.self_hypothesis.self_symmetry_map` kept, ``info.self_map``) when it made one,
        else the extraction's (:func:`intrinsym.globalmap.vertex_maps.fitted_vertex_map`). Needs ``support``
        and ``extraction``.
        """
        if self.support is None or self.extraction is None:
            raise ValueError("the result has no extraction")
        if self.global_map is not None:
            return np.asarray(self.global_map, dtype=np.int64)  # supported_map of the run's global map
        if self.support.source_mesh_vertices is None or not self.support.self_match:
            return self.extraction_map()  # a match maps onto another shape: no round trip
        return supported_map(self.extraction_map(), self.support.source_mesh_vertices, self.info.resolved.scale)

    def extraction_map(self) -> np.ndarray:
        """(N_in,) int64: the extraction's own vertex map of the dominant symmetry grown
        from the marginals (:attr:`intrinsym.extract.symmetry.Extraction.grown_symmetry`;
        :func:`intrinsym.globalmap.vertex_maps.fitted_vertex_map`, -1 off its parts), -1
        everywhere when there is none; the symmetry map when the run chose no other.
        Needs ``support`` and ``extraction``."""
        if self.support is None or self.extraction is None:
            raise ValueError("the result has no extraction")
        sym = self.extraction.grown_symmetry
        if sym is not None and sym.kind == "partial" and self.support.self_match and len(self.edges):
            # a partial symmetry holds one side's pairs; its map covers the other side too
            length = np.linalg.norm(np.diff(self.source_points[self.edges], axis=1)[:, 0], axis=1)
            sym = with_inverse(sym, self.source_points, self.target_points, 0.5 * float(np.median(length)))
        return self.fitted_map(sym)

    def symmetry_maps(self) -> np.ndarray:
        """(K, N_in) int64: the image of every input vertex under each of the K symmetries
        of ``symmetries.json`` in its order (``symmetry_maps.npy``), -1 off its parts; the
        dominant one's row is :meth:`symmetry_map`. Needs ``support`` and ``extraction``."""
        if self.support is None or self.extraction is None:
            raise ValueError("the result has no extraction")
        dominant = self.extraction.dominant_index
        rows = [
            self.symmetry_map() if k == dominant else self.fitted_map(sym)
            for k, sym in enumerate(self.extraction.symmetries)
        ]
        return np.stack(rows) if rows else np.empty((0, len(self.support.vertex_source)), dtype=np.int64)

    def symmetry_records(self, maps: np.ndarray | None = None) -> list[dict[str, Any]]:
        """The entries of ``symmetries.json`` (:func:`intrinsym.extract.records.records`),
        each with its ``coverage``, the share of the input vertices its row of ``maps``
        (default :meth:`symmetry_maps`) gives an image; a global symmetry's parts cut to
        the vertices its map gives an image (:func:`intrinsym.extract.records.cut_to_map`).
        Needs ``support`` and ``extraction``."""
        if self.support is None or self.extraction is None:
            raise ValueError("the result has no extraction")
        maps = self.symmetry_maps() if maps is None else maps
        listed = records.records(
            self.extraction.symmetries, self.source_point_vertex, self.target_point_vertex, self.support
        )
        for entry, row in zip(listed, maps, strict=True):
            entry["coverage"] = round(float(np.mean(row >= 0)), 6)
            if entry["kind"] == "global":
                records.cut_to_map(entry, row, one_mesh=self.info.mode == "detect")
        return listed

    def fitted_map(self, sym: Symmetry | None) -> np.ndarray:
        """(N_in,) int64: the vertex map of a symmetry of this result's samples
        (:func:`intrinsym.globalmap.vertex_maps.fitted_vertex_map` with the extraction's parameters),
        -1 off its parts and everywhere for None. Needs ``support`` and ``extraction``."""
        if self.support is None or self.extraction is None:
            raise ValueError("the result has no extraction")
        if sym is None:
            return np.full(len(self.support.vertex_source), -1, dtype=np.int64)
        return fitted_vertex_map(
            sym,
            self.support,
            self.edges,
            self.source_points,
            self.target_points,
            self.target_point_vertex,
            self.extraction.params,
        )

    def symmetry_mass(self) -> np.ndarray:
        """(N_in,) float32 in [0, 1]: per input vertex, the marginal mass within
        ``params.mass_radius`` of its image under :meth:`symmetry_map`
        (``symmetry_mass.npy``, :func:`intrinsym.globalmap.confidence.map_mass`): high where the
        marginals support the map, low where they do not; not a calibrated probability."""
        if self.support is None:
            raise ValueError("the result has no support")
        return map_mass(
            self.marginals,
            self.symmetry_map(),
            self.source_point_vertex,
            self.support,
            self.params.mass_radius,
        )

    def symmetry_score(self, mass: np.ndarray | None = None) -> np.ndarray:
        """(N_in,) float64 in [0, 1]: per input vertex, :meth:`symmetry_mass` (or
        ``mass``) weighed by how far the symmetry map and the extraction's own map agree
        on its image and, for a reflection, how far the map applied twice returns it
        (:func:`intrinsym.globalmap.confidence.score`); uncalibrated."""
        mass = self.symmetry_mass() if mass is None else mass
        if self.support is None or self.support.target_mesh_vertices is None or self.global_map is None:
            return np.asarray(mass, dtype=np.float64)
        images, image, scale = self.support.target_mesh_vertices, self.symmetry_map(), self.info.resolved.scale
        apart = disagreement(images, image, self.extraction_map(), scale)
        # a map onto another shape (a whole onto its part) has no round trip
        return score(mass, apart, round_trip(images, image, scale) if self.support.self_match else None)

    def symmetry_confidence(self, mass: np.ndarray | None = None) -> np.ndarray:
        """(N_in,) float32 in [0, 1]: per input vertex, the probability that its image
        under :meth:`symmetry_map` lies within 0.05 sqrt(area) of the true one (of either
        answer, for a match) (``symmetry_confidence.npy``): :meth:`symmetry_score` through
        :func:`intrinsym.globalmap.confidence.calibrated`, by the map's local distortion
        (:attr:`map_distortion`), or through one table of its own for a partial
        symmetry's map of a shape onto itself (:meth:`calibration_table`); for a part
        matched to its whole (and a whole to its part), every vertex the same: the share
        of the part's short distances the part's map keeps (``info.part_map``) through
        ``PART_CALIBRATION`` (0 when unknown); where no source sample's cell reaches (a
        connected component without samples, carried there), that of the nearest vertex
        a cell holds (:func:`intrinsym.globalmap.confidence.carried_confidence`); 0 where
        the map gives no image."""
        image = self.symmetry_map()
        if self.info.part:
            # a part's marginals do not rank its images: one score, its map's kept share
            kept = 0.0 if self.info.part_map is None else self.info.part_map.kept
            score = np.full(len(image), kept)
        else:
            score = self.symmetry_score(mass)
        # map_distortion is that of global_map: without it, the map scored is another
        local = self.map_distortion if self.global_map is not None else None
        conf = calibrated(score, local, table=self.calibration_table())
        if self.support is not None and self.support.source_mesh_vertices is not None:
            conf = carried_confidence(conf, self.support.vertex_source, self.support.source_mesh_vertices)
        return np.where(image >= 0, conf, 0.0).astype(np.float32)

    def calibration_table(self) -> tuple[float, ...] | None:
        """The one calibration table every vertex of :meth:`symmetry_map` takes, or None
        (the tables of ``CALIBRATION`` by local distortion): ``PART_CALIBRATION`` for a
        part matched to its whole (``info.part``), ``PARTIAL_CALIBRATION`` for a partial
        symmetry's map of a shape onto itself (no global map and the dominant symmetry
        partial, or the map ``info.self_map`` kept)."""
        if self.info.part:
            return PART_CALIBRATION
        sym = None if self.extraction is None else self.extraction.dominant_symmetry
        self_match = self.support is not None and self.support.self_match
        if self.info.self_map is not None or (
            self.global_map is None and self_match and sym is not None and sym.kind == "partial"
        ):
            return PARTIAL_CALIBRATION
        return None

    def global_confidence(self) -> float | None:
        """The expected share of vertices whose image lies within 0.05 sqrt(area) of the
        true one: the mean of :meth:`symmetry_confidence` over the input vertices (0 where
        the dominant symmetry gives none); None without a dominant symmetry."""
        if self.extraction is None or self.extraction.dominant_symmetry is None:
            return None
        return float(np.mean(self.symmetry_confidence()))

    def to_trimesh(self, color: str = "side", mesh: str | os.PathLike | None = None) -> Any:
        """The input as a ``trimesh.Trimesh`` (``PointCloud`` for a cloud), its vertices in
        the input's order, coloured by the global symmetry (:func:`intrinsym.result.export.to_trimesh`;
        ``color``: ``side``, ``partner`` or ``confidence``, :mod:`intrinsym.result.coloring`).
        ``mesh``: the input's path when it moved (default: the one in ``run.json``)."""
        from ..mesh.io import load
        from .export import to_trimesh

        shape = load(mesh if mesh is not None else self.info.input)
        conf = self.symmetry_confidence() if color == "confidence" else None
        return to_trimesh(shape, self.symmetry_map(), conf, color)

    def summary_line(self) -> str:
        """One line, cheap to make (no array is computed): mode, input, sizes, BP and the
        number of symmetries (the ``repr``)."""
        z, bp = self.info.sizes, self.info.bp
        found = "" if self.extraction is None else f", {len(self.extraction.symmetries)} symmetries"
        state = "converged" if bp.converged else "not converged"
        return (
            f"{self.info.mode} of {Path(self.info.input).name}: |Ps| = {z.source}, |Pt| = {z.target}, "
            f"BP {bp.iterations} iterations ({state}){found}"
        )

    def __repr__(self) -> str:
        return f"<intrinsym.Result {self.summary_line()}>"

    def _repr_html_(self) -> str:
        import html

        return f"<b>intrinsym.Result</b> {html.escape(self.summary_line())}"

    def run_json(self) -> dict[str, Any]:
        """``run.json``'s content: the parameters, :class:`RunInfo` and, with an extraction,
        its parameters (``extraction_params``)."""
        run = {"params": dataclasses.asdict(self.params), **self.info.to_dict()}
        if self.extraction is not None:
            run["extraction_params"] = dataclasses.asdict(self.extraction.params)
        return run

    def save(self, out_dir: str | os.PathLike, derived: Mapping[str, Writer] | None = None) -> Path:
        """Write ``out_dir/result.npz`` and ``out_dir/run.json``, and with an extraction
        ``symmetries.json`` and ``symmetry_map.npy`` (a match's also ``modes.json`` and
        ``mode_maps.npy``, :func:`intrinsym.result.modes.two_modes`), as one set
        (:func:`intrinsym.files.write_set`: the previous set stays whole until the new
        one replaces it; another process writing ``out_dir`` at the same time is refused
        with :class:`~intrinsym.errors.OutputError`).

        The files derived from the previous set (:attr:`DERIVED`) go with it, but those
        ``derived`` writes with the new set (``{"scores.json": write, ...}``, each called
        with the path to write); the folder's other files stay."""
        out = Path(out_dir)
        arrays = {name: getattr(self, name) for name in self.ARRAYS}
        if self.support is not None:
            arrays.update(self.support.to_arrays())
        if self.extraction is not None:
            arrays.update(self.extraction.to_arrays())
        if self.global_map is not None:
            arrays["global_map"] = np.asarray(self.global_map, dtype=np.int64)
        if self.pass_marginals is not None:
            arrays["pass_marginals"] = np.asarray(self.pass_marginals, dtype=np.float32)
        if self.map_distortion is not None:
            arrays["map_distortion"] = np.asarray(self.map_distortion, dtype=np.float32)
        if self.target_symmetry is not None:
            arrays["target_symmetry"] = np.asarray(self.target_symmetry, dtype=np.int64)
        if self.mode_marginals is not None:
            arrays["mode_marginals"] = np.asarray(self.mode_marginals, dtype=np.float32)
        run = self.run_json()

        def write_json(content: Any, indent: int | None = None) -> Writer:
            def write(path: Path) -> None:
                path.write_text(json.dumps(content, indent=indent))

            return write

        writers: dict[str, Writer] = {
            "result.npz": lambda path: save_npz(path, arrays),
            "run.json": write_json(run, indent=2),
        }
        if self.support is not None and self.extraction is not None:
            maps = self.symmetry_maps()
            listed = self.symmetry_records(maps)
            dominant = self.extraction.dominant_index
            vmap = maps[dominant].astype(np.int64) if dominant >= 0 else self.symmetry_map()
            writers["symmetries.json"] = write_json(listed)
            writers["symmetry_map.npy"] = lambda path: np.save(path, vmap)
            writers["symmetry_maps.npy"] = lambda path: np.save(path, maps.astype(np.int32))
            mass = self.symmetry_mass()
            conf = self.symmetry_confidence(mass)
            writers["symmetry_mass.npy"] = lambda path: np.save(path, mass)
            writers["symmetry_confidence.npy"] = lambda path: np.save(path, conf)
            if self.info.mode == "match":
                two = two_modes(self)
                writers["modes.json"] = write_json(two.as_dict(), indent=2)
                writers["mode_maps.npy"] = lambda path: np.save(path, two.maps)
        write_set(out, {**writers, **(derived or {})}, owned=(*self.FILES, *self.DERIVED))
        return out

    @classmethod
    def load(cls, out_dir: str | os.PathLike) -> Result:
        """Read a result folder written by :meth:`save`: it answers every method as the
        result saved did. Folders of the older format versions (1 to 3) hold no extraction
        (``extraction`` None); rerun it with :func:`intrinsym.pipeline.extract_result`.

        Raises
        ------
        ResultError
            A file missing, truncated or corrupt (one line naming it).
        """
        out = Path(out_dir)
        name = out / "run.json"
        try:
            run = json.loads(name.read_text())
            params = Params(**stored_params(run))
            info = RunInfo.from_dict(run)
            name = out / "result.npz"
            _check_arrays(name, npz_headers(name), info.sizes, params)
            with np.load(name) as z:

                def get(key: str) -> np.ndarray | None:
                    for k in (key, OLD_ARRAYS.get(key)):
                        if k is not None and k in z.files:
                            return z[k]
                    return None

                arrays = {key: get(key) for key in cls.ARRAYS}
                missing = [key for key, value in arrays.items() if value is None]
                if missing:
                    raise ResultError(f"{name}: lacks {', '.join(missing)}")
                support = Support.from_arrays(z) if Support.stored_in(z.files) else None
                extraction = (
                    Extraction.from_arrays(
                        z, ExtractParams(**run["extraction_params"]), info.sizes.source, info.sizes.target
                    )
                    if Extraction.stored_in(z.files)
                    else None
                )
                global_map, pass_marginals = get("global_map"), get("pass_marginals")
                map_distortion, target_symmetry = get("map_distortion"), get("target_symmetry")
                mode_marginals = get("mode_marginals")
        except _UNREADABLE as err:
            reason = "missing" if isinstance(err, FileNotFoundError) else f"{type(err).__name__}: {err}"
            raise ResultError(f"{name}: cannot read it ({reason}); run intrinsym detect again") from None
        return cls(
            **cast(dict[str, Any], arrays),
            params=params,
            info=info,
            support=support,
            extraction=extraction,
            global_map=global_map,
            pass_marginals=pass_marginals,
            map_distortion=map_distortion,
            target_symmetry=target_symmetry,
            mode_marginals=mode_marginals,
        )


def _shapes(sizes: Sizes) -> dict[str, tuple[int | str, ...]]:
    """The shape of every array ``result.npz`` holds (under its current and its version 1
    name), in the sizes of ``run.json``; a letter stands for a size it does not record,
    the same in every array: N and M the input vertices of the source and the target
    shape, P the BP passes after the first, K the symmetries and Q their sample pairs."""
    s, t, e, d = sizes.source, sizes.target, sizes.edges, sizes.target_distance_entries
    shapes: dict[str, tuple[int | str, ...]] = {
        "source_points": (s, 3),
        "target_points": (t, 3),
        "source_point_vertex": (s,),
        "target_point_vertex": (t,),
        "edges": (e, 2),
        "unary": (s, t),
        "marginals": (s, t),
        "pass_marginals": ("P", s, t),
        "global_map": ("N",),
        "map_distortion": ("N",),
        "target_symmetry": ("M",),
        "mode_marginals": (2, s, t),
        "edge_length": (e,),
        "vertex_source": ("N",),
        "vertex_target": ("M",),
        "target_distance_indptr": (t + 1,),
        "target_distance_index": (d,),
        "target_distance": (d,),
        "target_distance_radius": (),
        "self_match": (),
        "source_mesh_vertices": ("N", 3),
        "target_mesh_vertices": ("M", 3),
        "symmetry_source": ("Q",),
        "symmetry_target": ("Q",),
        "symmetry_size": ("K",),
        "symmetry_score": ("K",),
        "symmetry_consistency": ("K",),
        "symmetry_kind": ("K",),
        "global_index": (),
    }
    renamed = {**OLD_ARRAYS, **Support.OLD_KEYS}
    return shapes | {renamed[key]: shape for key, shape in shapes.items() if key in renamed}


def _check_arrays(name: Path, headers: Mapping[str, tuple[tuple[int, ...], np.dtype]], sizes: Sizes, p: Params) -> None:
    """Refuse a ``result.npz`` (``name``, its arrays' ``headers``) whose arrays have other
    shapes than ``run.json``'s ``sizes`` and parameters ``p`` give them
    (:class:`ResultError`), or more bytes than memory holds
    (:class:`~intrinsym.errors.ResourceError`), before any is read."""
    shapes, free = _shapes(sizes), dict[str, int]()
    for key, (shape, _) in headers.items():
        want = shapes.get(key)
        if want is None:
            continue
        fits = len(shape) == len(want)
        for have, size in zip(shape, want):
            fits &= have == (free.setdefault(size, have) if isinstance(size, str) else size)
        if not fits:
            text = ", ".join(str(free.get(size, size)) if isinstance(size, str) else str(size) for size in want)
            raise ResultError(
                f"{name}: its array {key} is {shape}, not ({text}) as run.json's sizes say; run intrinsym detect again"
            )
    passes = max(p.passes or 2, 1) - 1
    if free.get("P", 0) > passes:
        raise ResultError(f"{name}: holds {free['P']} further BP passes, more than the {passes} of run.json")
    nbytes = sum(math.prod(shape) * dtype.itemsize for shape, dtype in headers.values())
    resources.check_memory(nbytes, "reading its arrays", str(name))


def saved_global_confidence(out_dir: str | os.PathLike, has_global: bool) -> float | None:
    """The global confidence of a saved result: the mean of its ``symmetry_confidence.npy``;
    None without a global symmetry or without the file (results of earlier versions)."""
    path = Path(out_dir) / "symmetry_confidence.npy"
    return float(np.load(path).mean()) if has_global and path.is_file() else None
