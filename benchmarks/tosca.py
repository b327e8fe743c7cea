"""Default detection beside the spectral baseline on every shape with a known symmetry.

Runs the default :func:`intrinsym.detect` (seed 0) and the spectral baseline
(:func:`intrinsym.spectral.spectral.spectral_symmetry`, sign search then ZoomOut, as
``benchmarks/spectral.py`` runs it) on every mesh of the data folder that has a
ground-truth symmetry:

* ``tosca_sym/<class><pose>.off`` for every class with a ``tosca_sym/<class>.sym``
  map (all poses; gorilla has no map and is left out);
* ``kids_sym/0001.isometry.1.off`` with ``kids_sym/sym.txt`` (row ``kids``);
* the meshes posed nearly mirror-symmetrically that have no symmetry file, the SCAPE
  template (``scape``), ``homer``, ``cow`` and ``spot`` (the shipped example): their
  ground truth is their best reflection (:func:`intrinsym.evaluation.evaluate.extrinsic_mirror`),
  and the row records that reflection's median residual (units of sqrt(area)).

Per shape it records the marginal scores of the unary and of BP
(:func:`intrinsym.evaluation.evaluate.score_marginals`: mirror hit, peak recall, decoy recall,
breadth), the global symmetry map's fraction of vertices within 0.05 and 0.10 of the
true image and its mean error (:func:`intrinsym.evaluation.evaluate.score_map`, geodesic, units of
sqrt(area); what ``intrinsym evaluate`` reports), the same two shares of the surface area
(each vertex weighed by the area it stands for: a finely meshed hand holds more of the
vertices than of the area), whether a global symmetry was found,
the distortion of that map and of the true one (:func:`intrinsym.globalmap.distortion.map_distortion`:
the share of vertex pairs within 0.5 whose geodesic distance the map changes by more
than 0.05, which tells how near to an isometry the pose keeps its symmetry),
where the true symmetry keeps local distances (the vertices whose
:func:`intrinsym.globalmap.distortion.local_distortion` is at most ``LOCAL_ISOMETRY``: pairs within
0.1 changed by at most that on average) and both maps' scores there,
the global/partial decision and the statistics behind it (the share of source edges
BP's argmax keeps, the share of source samples it returns to when applied twice, and
whether the identity was kept as "no partner"), how the global map was chosen
(``run.json``'s ``global_map``: the marginal mass each candidate keeps) with the
extraction's map scored alone (``extraction_map`` in the cache), BP iterations,
seconds per stage and in total (the wall time of the ``detect`` call), and the
baseline's map scores and seconds (``spectral_symmetry`` alone). Command::

    OPENBLAS_NUM_THREADS=1 python benchmarks/tosca.py --data DATA [--cache DIR --tag TAG]
        [--shapes cat0 kids ...] [--jobs N] [--param NAME=VALUE ...] [--json] [--stages] [-o TABLE.md]

``DATA`` is the research data folder (holding ``tosca_sym/``, ``kids_sym/``, ``scape/``
and ``static/``); without ``--data`` the environment variable ``INTRINSYM_DATA`` names
it. The script skips (exit 0, a message) when neither is set or the folder is absent.

``--shapes`` takes shape names (``cat0``, ``kids``, ``scape``) or class names (``cat``:
all its poses). ``--cache DIR`` keeps one JSON file per shape (``DIR/<shape>.json``); a
shape whose file exists with the same ``--tag`` and package version is read back, not
recomputed, so an interrupted run resumes where it stopped. ``--param NAME=VALUE``
(repeatable) runs ``detect`` with that :class:`intrinsym.Params` field changed (``--param
rho=0.3``); the rows record it, a cached row counts only with the same changes, and the
table's last lines name them. ``--jobs N`` runs N shapes at
once in separate processes (each holds up to about 1.5 GB on the largest meshes).

Output: one Markdown table (shapes, then the mean and worst of every column over all
shapes, then per class), the sorted decision statistics and the shapes where the
global map within 0.10 falls more than 0.01 below the baseline's; ``--json`` prints the
rows as a JSON list instead. Worst means the minimum of a score where higher is better
and the maximum where lower is better (decoy recall, mean error, iterations, seconds).
Mean errors are averaged over the shapes with a global map; a shape without one counts
as worst.

On a machine whose cores are busy with other work, set ``OPENBLAS_NUM_THREADS=1``
(see ``benchmarks/spectral.py``).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import math
import os
import platform
import re
import sys
import time
import traceback
from collections.abc import Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

import numpy as np

import intrinsym
from intrinsym import params
from intrinsym.evaluation import evaluate
from intrinsym.extract.reflection import RETURN_RADIUS
from intrinsym.geodesics import geodesics
from intrinsym.globalmap import confidence, distortion
from intrinsym.spectral import spectral

#: Meshes without a symmetry file that are posed nearly mirror-symmetrically: name -> path.
REFLECTION = {
    "scape": "scape/mesh000.off",
    "homer": "static/homer.obj",
    "cow": "static/cow.obj",
    "spot": "static/spot.obj",
}
#: Class of the reflection-scored meshes in the per-class summary.
REFLECTION_CLASS = "reflection"
#: Marginal scores shown in the table (``score_marginals`` also gives breadth, kept in JSON).
MARGINAL = ("mirror_hit", "peak_recall", "decoy_recall")
#: The reflection statistic in the summary's words.
_REFLECTION = (
    f"share of source samples BP's argmax returns to within {RETURN_RADIUS} when applied twice "
    "and turns around (neighbours' order reversed)"
)
#: A vertex where the true symmetry changes the geodesic distances of the pairs around
#: it (within ``distortion.LOCAL_RADIUS``) by at most this on average (sqrt(area) units)
#: is one where an isometry-based method can be asked to find it: 1.8 times the largest
#: mean of a true symmetry over the vertices where the found maps are right (SCAPE's
#: reflection, 0.0056), below every mean of michael's symmetry file over the (finger)
#: vertices the found maps miss (0.011-0.018; docs/notes/2026-11-28-results-behind-the-defaults.md).
LOCAL_ISOMETRY = 0.01
#: Cache-format revision: a file with another one is recomputed.
CACHE_FORMAT = 8


# --------------------------------------------------------------------------- shapes


@dataclasses.dataclass(frozen=True)
class Case:
    """One benchmark shape: its mesh and ground truth (a map file, or None: reflection)."""

    name: str
    cls: str
    mesh: Path
    truth: Path | None

    def truth_map(self, mesh: intrinsym.Shape) -> np.ndarray:
        """(N,) int64: the true image of every vertex of ``mesh`` (the loaded ``self.mesh``)."""
        if self.truth is None:
            return evaluate.extrinsic_mirror(mesh.vertices)[0]
        return evaluate.load_symmetry_map(self.truth, len(mesh.vertices))


def _class_of(stem: str) -> str:
    return re.sub(r"\d+$", "", stem)


def _pose(stem: str) -> int:
    digits = re.search(r"(\d+)$", stem)
    return int(digits.group(1)) if digits else -1


def cases(data: Path) -> list[Case]:
    """Every shape of the data folder with ground truth, TOSCA by class and pose first."""
    out = []
    tosca = data / "tosca_sym"
    if tosca.is_dir():
        meshes = [p for p in tosca.glob("*.off") if (tosca / f"{_class_of(p.stem)}.sym").is_file()]
        for p in sorted(meshes, key=lambda p: (_class_of(p.stem), _pose(p.stem))):
            out.append(Case(p.stem, _class_of(p.stem), p, tosca / f"{_class_of(p.stem)}.sym"))
    kids = data / "kids_sym"
    if (kids / "0001.isometry.1.off").is_file() and (kids / "sym.txt").is_file():
        out.append(Case("kids", "kids", kids / "0001.isometry.1.off", kids / "sym.txt"))
    for name, rel in REFLECTION.items():
        if (data / rel).is_file():
            out.append(Case(name, REFLECTION_CLASS, data / rel, None))
    return out


def select(all_cases: list[Case], names: list[str] | None) -> list[Case]:
    """The cases named (shape or class names), in the benchmark's order."""
    if not names:
        return all_cases
    known = {c.name for c in all_cases} | {c.cls for c in all_cases}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise SystemExit(
            f"tosca.py: unknown shape(s) {', '.join(unknown)}; known: {', '.join(c.name for c in all_cases)}"
        )
    return [c for c in all_cases if c.name in names or c.cls in names]


# --------------------------------------------------------------------------- API adapters


def _shape_module():
    """The module with ``clean`` and ``surface_area`` (``intrinsym.mesh.shape``, else ``intrinsym.mesh``)."""
    for name in ("intrinsym.mesh.shape", "intrinsym.mesh"):
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        if hasattr(module, "clean") and hasattr(module, "surface_area"):
            return module
    raise ImportError("intrinsym has neither shape.clean nor mesh.clean")


def field(obj, *keys, default=None):
    """``obj[k1][k2]...`` on dicts, ``obj.k1.k2...`` on objects; ``default`` when missing."""
    for key in keys:
        if obj is None:
            return default
        obj = obj.get(key) if isinstance(obj, Mapping) else getattr(obj, key, None)
    return default if obj is None else obj


def decision(info) -> dict:
    """The global/partial decision of a run: its statistic, threshold and whether the
    identity was kept as the answer "no partner" (the shape judged partial).

    Reads ``info["identity"]`` (``isometry``, ``threshold``, ``weight`` > 0: identity
    kept) from ``run.json``'s dict or from an attribute-style info object; a record named
    ``decision`` with ``statistic`` / ``threshold`` / ``identity_kept`` is read alike.
    """
    record = field(info, "identity") or field(info, "decision")
    if record is None:
        return {"statistic": None, "threshold": None, "reflection": None, "identity_kept": None}
    statistic = field(record, "isometry", default=field(record, "statistic"))
    kept = field(record, "identity_kept", default=field(record, "kept"))
    if kept is None:
        weight = field(record, "weight")
        kept = None if weight is None else float(weight) > 0
    reflection = field(record, "reflection")
    return {
        "statistic": None if statistic is None else float(statistic),
        "threshold": field(record, "threshold"),
        "reflection": None if reflection is None else float(reflection),
        "reflection_threshold": field(record, "reflection_threshold"),
        "identity_kept": None if kept is None else bool(kept),
    }


#: Equal-width bins of the per-vertex score and mass in the reliability histograms.
MASS_BINS = 20


def reliability(result, shape, sym) -> dict | None:
    """Per bin of the symmetry map's per-vertex score (``symmetry_score``, the uncalibrated
    confidence) and of its marginal mass (``symmetry_mass``): how many vertices fall in it
    and how many of them map within 0.05 / 0.10 of the true image (graph geodesics, units
    of sqrt(area)); keyed ``score`` and ``mass``, each None on code without it. Keyed
    ``score_split``: the score's bins once per table of ``intrinsym.globalmap.confidence.CALIBRATION``
    (``groups``), each vertex in its table's, by the map's local distortion
    (``Result.map_distortion``, :func:`intrinsym.globalmap.confidence.distortion_group`)."""
    features = {}
    for key in ("score", "mass"):
        of = getattr(result, f"symmetry_{key}", None)
        features[key] = None if of is None else np.asarray(of(), dtype=np.float64)
    if features["mass"] is None:
        return None
    local = getattr(result, "map_distortion", None)
    if features["score"] is not None and local is not None:
        features["score_split"] = features["score"]
    vmap = np.asarray(result.symmetry_map(), dtype=np.int64)
    shapes = _shape_module()
    cleaned, vertex_map = shapes.clean(shape)
    graph = geodesics.surface_graph(cleaned.vertices / np.sqrt(shapes.surface_area(cleaned)), cleaned.faces)
    scored = (np.asarray(sym) >= 0) & (vmap >= 0)
    err = evaluate.map_errors(vertex_map[vmap[scored]], vertex_map[np.asarray(sym)[scored]], graph)
    out: dict = {}
    for key, value in features.items():
        if value is None:
            out[key] = None
            continue
        right = {"within_0.05": err < 0.05, "within_0.10": err < 0.10}
        if key == "score_split":  # each table's bins in turn
            group = confidence.distortion_group(local, len(vmap))[scored]
            out[key] = score_histogram(value[scored], right, group, len(confidence.CALIBRATION))
        else:
            out[key] = score_histogram(value[scored], right)
    return out


def score_histogram(
    value: np.ndarray, right: Mapping[str, np.ndarray], group: np.ndarray | None = None, groups: int = 1
) -> dict:
    """A reliability histogram of per-vertex values in [0, 1]: :data:`MASS_BINS` equal-width
    bins (once per group, each vertex in its ``group``'s), how many vertices fall in each
    (``count``) and, per key of ``right``, how many of them are right."""
    which = np.minimum((value * MASS_BINS).astype(np.int64), MASS_BINS - 1)
    if group is not None:
        which = which + MASS_BINS * group
    size = groups * MASS_BINS
    histogram = {"bins": MASS_BINS, "groups": groups, "count": np.bincount(which, minlength=size).tolist()}
    for key, ok in right.items():
        histogram[key] = np.bincount(which, weights=ok, minlength=size).astype(int).tolist()
    return histogram


def _sample_vertices(result) -> tuple[np.ndarray, np.ndarray]:
    """Input-mesh vertex of every source and target sample (either attribute name)."""
    out = []
    for side in ("source", "target"):
        for name in (f"{side}_point_vertex", f"{side}_vertex"):
            value = getattr(result, name, None)
            if value is not None and not callable(value):
                out.append(np.asarray(value))
                break
        else:
            raise AttributeError(f"result has no {side} sample vertices")
    return out[0], out[1]


def _params(result) -> dict:
    p = getattr(result, "params", None)
    if dataclasses.is_dataclass(p):
        return {k: v for k, v in dataclasses.asdict(p).items() if isinstance(v, (int, float, str, bool, type(None)))}
    return {}


# --------------------------------------------------------------------------- one shape


def _clean_floats(obj):
    """NaN / inf -> None, numpy scalars -> Python, recursively (strict JSON)."""
    if isinstance(obj, dict):
        return {k: _clean_floats(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean_floats(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def _map_row(scores) -> dict:
    """The summary numbers of ``MapScores.as_dict`` (not its curve)."""
    full = scores.as_dict()
    keys = ("within_0.05", "within_0.10", "area_within_0.05", "area_within_0.10", "mean_error", "coverage")
    return {key: full[key] for key in keys}


def _machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores"


def run_case(case: Case, tag: str | None, seed: int = 0, overrides: Mapping | None = None) -> dict:
    """Detect (the defaults, but ``overrides``: Params field -> value) and baseline on one
    shape; the JSON-ready row."""
    shapes = _shape_module()
    shape = intrinsym.load(case.mesh)
    n = len(shape.vertices)
    row: dict = {
        "shape": case.name,
        "class": case.cls,
        "mesh": f"{case.mesh.parent.name}/{case.mesh.name}",
        "vertices": n,
        "seed": seed,
    }
    if case.truth is None:
        sym, residual = evaluate.extrinsic_mirror(shape.vertices)
        row["truth"] = "reflection"
        row["mirror_residual"] = float(np.median(residual) / np.sqrt(shapes.surface_area(shape)))
    else:
        sym = evaluate.load_symmetry_map(case.truth, n)
        row["truth"] = f"{case.truth.parent.name}/{case.truth.name}"

    start = time.perf_counter()
    result = intrinsym.detect(case.mesh, params.make_params(**(overrides or {})), seed=seed)
    row["seconds_total"] = time.perf_counter() - start
    info = result.info
    source_vertex, target_vertex = _sample_vertices(result)
    for column, marginals in (("unary", result.unary), ("bp", result.marginals)):
        scores = evaluate.score_marginals(marginals, source_vertex, target_vertex, shape, sym, seed=seed)
        row[column] = scores.as_dict()
    vmap = np.asarray(result.symmetry_map())
    row["global_found"] = bool((vmap >= 0).any())
    row["map"] = _map_row(evaluate.score_map(vmap, shape, sym))
    row["map"]["distortion"] = distortion.map_distortion(vmap, shape, seed=seed).as_dict()
    row["truth_distortion"] = distortion.map_distortion(sym, shape, seed=seed).as_dict()
    # scored where the truth is locally isometric: elsewhere the truth is marked "none"
    isometric = distortion.local_distortion(sym, shape) <= LOCAL_ISOMETRY
    sym_isometric = np.where(isometric, sym, -1)
    row["isometric"] = {
        "share": float(isometric.mean()),
        "map": _map_row(evaluate.score_map(vmap, shape, sym_isometric)),
    }
    row["reliability"] = reliability(result, shape, sym) if row["global_found"] else None
    row["decision"] = decision(info)
    choice = field(info, "global_map")
    row["global_map"] = choice if choice is None or isinstance(choice, Mapping) else dataclasses.asdict(choice)
    if row["global_found"]:
        row["extraction_map"] = _map_row(evaluate.score_map(np.asarray(result.extraction_map()), shape, sym))
    row["bp_iterations"] = field(info, "bp", "iterations")
    row["bp_converged"] = field(info, "bp", "converged")
    seconds = field(info, "seconds", default={})
    row["seconds"] = dict(seconds) if isinstance(seconds, Mapping) else dict(vars(seconds))
    row["params"] = _params(result)
    del result

    cleaned, vertex_map = shapes.clean(shape)
    start = time.perf_counter()
    image = spectral.spectral_symmetry(cleaned.vertices, cleaned.faces)
    spectral_seconds = time.perf_counter() - start
    # back to input vertices: each cleaned vertex is represented by its first input vertex
    first = np.empty(len(cleaned.vertices), dtype=np.int64)
    first[vertex_map[::-1]] = np.arange(len(vertex_map))[::-1]
    spectral_map = first[image[vertex_map]]
    row["isometric"]["spectral"] = _map_row(evaluate.score_map(spectral_map, shape, sym_isometric))
    row["spectral"] = {
        **_map_row(evaluate.score_map(spectral_map, shape, sym)),
        "seconds": spectral_seconds,
    }
    row["version"] = intrinsym.__version__
    row["tag"] = tag
    row["overrides"] = dict(overrides or {})
    row["cache_format"] = CACHE_FORMAT
    row["machine"] = _machine()
    row["python"] = platform.python_version()
    return _clean_floats(row)


def _cached(cache: Path | None, case: Case, tag: str | None, overrides: Mapping) -> dict | None:
    if cache is None:
        return None
    path = cache / f"{case.name}.json"
    if not path.is_file():
        return None
    try:
        row = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if (row.get("tag"), row.get("version"), row.get("cache_format")) != (tag, intrinsym.__version__, CACHE_FORMAT):
        print(
            f"{case.name}: cache entry from tag {row.get('tag')!r} / version {row.get('version')!r}: recomputing",
            file=sys.stderr,
        )
        return None
    if (row.get("overrides") or {}) != overrides:
        print(f"{case.name}: cache entry of other parameters {row.get('overrides')}: recomputing", file=sys.stderr)
        return None
    return row


def _work(case: Case, tag: str | None, cache: Path | None, seed: int, overrides: Mapping) -> dict:
    """Worker: one shape, written to the cache (atomically) when there is one."""
    try:
        row = run_case(case, tag, seed, overrides)
    except Exception as err:  # noqa: BLE001 - one failing shape must not stop the benchmark
        traceback.print_exc()
        return {"shape": case.name, "class": case.cls, "error": f"{type(err).__name__}: {err}"}
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        tmp = cache / f".{case.name}.json.tmp{os.getpid()}"
        tmp.write_text(json.dumps(row, indent=1))
        os.replace(tmp, cache / f"{case.name}.json")
    return row


# --------------------------------------------------------------------------- table


def _get(row: dict, *keys):
    value = row
    for key in keys:
        if not isinstance(value, dict):
            return None
        value = value.get(key)
    return value


def _columns(stages: list[str]) -> list[tuple[str, tuple, bool, str]]:
    """(header, key path, higher is better, format) of every numeric column."""
    cols = []
    for score in MARGINAL:
        label = score.replace("_", " ")
        cols += [
            (f"{label} unary", ("unary", score), score != "decoy_recall", ".3f"),
            (f"{label} BP", ("bp", score), score != "decoy_recall", ".3f"),
        ]
    cols += [
        ("map ≤0.05", ("map", "within_0.05"), True, ".3f"),
        ("map ≤0.10", ("map", "within_0.10"), True, ".3f"),
        ("map mean error", ("map", "mean_error"), False, ".4f"),
        ("map ≤0.05 of the area", ("map", "area_within_0.05"), True, ".3f"),
        ("map ≤0.10 of the area", ("map", "area_within_0.10"), True, ".3f"),
        ("map distortion", ("map", "distortion", "above_0.05"), False, ".3f"),
        ("truth distortion", ("truth_distortion", "above_0.05"), False, ".3f"),
        ("truth locally isometric", ("isometric", "share"), True, ".3f"),
        ("map ≤0.05 there", ("isometric", "map", "within_0.05"), True, ".3f"),
        ("map ≤0.10 there", ("isometric", "map", "within_0.10"), True, ".3f"),
        ("global found", ("global_found",), True, "bool"),
        ("identity share", ("decision", "statistic"), True, ".3f"),
        ("reflection", ("decision", "reflection"), True, ".3f"),
        ("identity kept", ("decision", "identity_kept"), False, "bool"),
        ("BP it.", ("bp_iterations",), False, "d"),
        ("spectral ≤0.05", ("spectral", "within_0.05"), True, ".3f"),
        ("spectral ≤0.10", ("spectral", "within_0.10"), True, ".3f"),
        ("spectral mean error", ("spectral", "mean_error"), False, ".4f"),
        ("spectral ≤0.05 there", ("isometric", "spectral", "within_0.05"), True, ".3f"),
        ("≤0.10 ours − spectral", ("delta_0.10",), True, "+.3f"),
        ("s detect", ("seconds_total",), False, ".1f"),
        ("s BP", ("seconds", "bp"), False, ".1f"),
    ]
    cols += [(f"s {stage}", ("seconds", stage), False, ".1f") for stage in stages if stage != "bp"]
    cols.append(("s spectral", ("spectral", "seconds"), False, ".1f"))
    return cols


def _with_delta(row: dict) -> dict:
    ours, base = _get(row, "map", "within_0.10"), _get(row, "spectral", "within_0.10")
    return {**row, "delta_0.10": None if ours is None or base is None else ours - base}


def _fmt(value, fmt: str) -> str:
    if value is None:
        return "–"
    if fmt == "bool":
        return "yes" if value else "no"
    if fmt == "d":
        return str(round(value))
    text = format(value, fmt)
    return format(0.0, fmt) if text.strip("+-0.") == "" else text  # no "-0.000"


def _summary(rows: list[dict], cols) -> tuple[list[str], list[str]]:
    """Mean and worst cells of every column over the rows."""
    means, worsts = [], []
    for _, keys, higher, fmt in cols:
        values = [_get(r, *keys) for r in rows]
        if keys == ("map", "mean_error"):
            # a shape without a global map has no mean error: it is the worst
            missing = sum(v is None for v in values)
            finite = [v for v in values if v is not None]
            means.append(
                _fmt(float(np.mean(finite)), fmt) + (f" ({missing} none)" if missing else "") if finite else "–"
            )
            worsts.append("none" if missing else _fmt(max(finite), fmt) if finite else "–")
            continue
        finite = [float(v) for v in values if v is not None]
        if not finite:
            means.append("–")
            worsts.append("–")
            continue
        worst = min(finite) if higher else max(finite)
        if fmt == "bool":
            means.append(f"{np.mean(finite):.2f}")
            worsts.append(_fmt(worst, fmt))
        elif fmt == "d":
            means.append(f"{np.mean(finite):.1f}")
            worsts.append(_fmt(worst, fmt))
        else:
            means.append(_fmt(float(np.mean(finite)), fmt))
            worsts.append(_fmt(worst, fmt))
    return means, worsts


def markdown(rows: list[dict], show_stages: bool = False) -> str:
    """The table, the class summary and the findings as Markdown."""
    ok = [_with_delta(r) for r in rows if "error" not in r]
    stages = sorted({s for r in ok for s in r.get("seconds", {})}) if show_stages else []
    cols = _columns(stages)
    head = ["shape"] + [c[0] for c in cols]
    rule = "|" + "---|" * len(head)
    lines = ["| " + " | ".join(head) + " |", rule]
    for r in ok:
        name = r["shape"]
        if r.get("truth") == "reflection":
            name += f" (reflection, residual {r['mirror_residual']:.4f})"
        lines.append("| " + " | ".join([name] + [_fmt(_get(r, *c[1]), c[3]) for c in cols]) + " |")
    if ok:
        means, worsts = _summary(ok, cols)
        lines.append(f"| **mean ({len(ok)})** | " + " | ".join(means) + " |")
        lines.append("| **worst** | " + " | ".join(worsts) + " |")
    out = ["\n".join(lines)]

    classes = list(dict.fromkeys(r["class"] for r in ok))
    if len(classes) > 1:
        lines = ["| class | " + " | ".join(c[0] for c in cols) + " |", rule]
        for cls in classes:
            members = [r for r in ok if r["class"] == cls]
            means, worsts = _summary(members, cols)
            lines.append(f"| {cls} mean ({len(members)}) | " + " | ".join(means) + " |")
            lines.append(f"| {cls} worst | " + " | ".join(worsts) + " |")
        out.append("Per class:\n\n" + "\n".join(lines))

    for key, what in (("statistic", "share of source edges BP's argmax keeps"), ("reflection", _REFLECTION)):
        stats = sorted((_get(r, "decision", key), r["shape"]) for r in ok if _get(r, "decision", key) is not None)
        if stats:
            bound = "threshold" if key == "statistic" else "reflection_threshold"
            threshold = next((_get(r, "decision", bound) for r in ok if _get(r, "decision", bound)), None)
            out.append(
                f"Decision statistic ({what}"
                + (f"; threshold {threshold}" if threshold is not None else "")
                + "), sorted: "
                + ", ".join(f"{name} {value:.3f}" for value, name in stats)
                + "."
            )
    kept = [r["shape"] for r in ok if _get(r, "decision", "identity_kept")]
    out.append(f"Identity kept (judged partial): {', '.join(kept) if kept else 'none'}.")
    behind = [(r["shape"], r["delta_0.10"]) for r in ok if r["delta_0.10"] is not None and r["delta_0.10"] < -0.01]
    out.append(
        "Shapes more than 0.01 below the spectral baseline within 0.10: "
        + (", ".join(f"{name} ({d:+.3f})" for name, d in behind) if behind else "none")
        + "."
    )
    total = sum(r.get("seconds_total", 0.0) for r in ok)
    total_spectral = sum(_get(r, "spectral", "seconds") or 0.0 for r in ok)
    meta = sorted({(r.get("tag"), r.get("version"), r.get("machine")) for r in ok}, key=str)
    out.append(
        f"Total: detect {total:.0f} s, spectral baseline {total_spectral:.0f} s over {len(ok)} shapes; "
        + "; ".join(f"tag {t}, intrinsym {v}, {m}" for t, v, m in meta)
        + "."
    )
    changed = sorted({json.dumps(r.get("overrides") or {}, sort_keys=True) for r in ok})
    if changed != ["{}"]:
        out.append("Parameters other than the defaults: " + "; ".join(changed) + ".")
    failed = [r for r in rows if "error" in r]
    if failed:
        out.append("Failed: " + "; ".join(f"{r['shape']}: {r['error']}" for r in failed) + ".")
    return "\n\n".join(out) + "\n"


# --------------------------------------------------------------------------- main


def _overrides(texts: list[str]) -> dict:
    """``NAME=VALUE`` texts as Params field -> value (:meth:`intrinsym.params.Field.parse`)."""
    fields = {f.name: f for f in params.describe()}
    out = {}
    for text in texts:
        name, sep, value = text.partition("=")
        if not sep or name not in fields:
            raise intrinsym.ParameterError(f"{text!r} is not NAME=VALUE with NAME a Params field")
        out[name] = fields[name].parse(value)
    params.make_params(**out)  # checks the values together
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, help="research data folder (default: $INTRINSYM_DATA)")
    parser.add_argument("--shapes", nargs="+", metavar="NAME", help="shape or class names (default: all)")
    parser.add_argument("--jobs", type=int, default=1, help="shapes run at once (default 1)")
    parser.add_argument("--cache", type=Path, help="folder of per-shape JSON results, reused when present")
    parser.add_argument("--tag", help="code tag recorded in (and required of) the cached results")
    parser.add_argument("--seed", type=int, default=0, help="detect's seed (default 0)")
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="run detect with this Params field changed (repeatable; cached rows must have the same)",
    )
    parser.add_argument("--json", action="store_true", help="print the rows as a JSON list")
    parser.add_argument("--stages", action="store_true", help="a seconds column for every stage")
    parser.add_argument("-o", "--out", type=Path, help="also write the Markdown table here")
    args = parser.parse_args(argv)
    try:
        overrides = _overrides(args.param)
    except intrinsym.ParameterError as err:
        parser.error(f"--param {err}")
    data = args.data or (Path(os.environ["INTRINSYM_DATA"]) if os.environ.get("INTRINSYM_DATA") else None)
    if data is None or not data.is_dir():
        print(f"research data not available ({data or 'give --data DIR or set INTRINSYM_DATA'}): skipped")
        return 0
    todo = select(cases(data), args.shapes)
    if not todo:
        print(f"no shape with a symmetry map under {data}: skipped")
        return 0

    rows: dict[str, dict] = {}
    pending = []
    for case in todo:
        row = _cached(args.cache, case, args.tag, overrides)
        if row is not None:
            rows[case.name] = row
            print(f"{case.name}: cached", file=sys.stderr)
        else:
            pending.append(case)
    start = time.perf_counter()

    def done(case: Case, row: dict) -> None:
        rows[case.name] = row
        if "error" in row:
            print(f"{case.name}: FAILED {row['error']}", file=sys.stderr)
        else:
            print(
                f"{case.name}: map ≤0.10 {row['map']['within_0.10']:.3f} (spectral "
                f"{row['spectral']['within_0.10']:.3f}), detect {row['seconds_total']:.1f} s "
                f"[{len(rows)}/{len(todo)}, {time.perf_counter() - start:.0f} s]",
                file=sys.stderr,
            )
        sys.stderr.flush()

    if args.jobs <= 1:
        for case in pending:
            done(case, _work(case, args.tag, args.cache, args.seed, overrides))
    else:
        with ProcessPoolExecutor(args.jobs, mp_context=get_context("spawn")) as pool:
            futures = {pool.submit(_work, case, args.tag, args.cache, args.seed, overrides): case for case in pending}
            for future in as_completed(futures):
                done(futures[future], future.result())

    ordered = [rows[c.name] for c in todo]
    if args.json:
        print(json.dumps(ordered, indent=1))
    else:
        table = markdown(ordered, args.stages)
        print(table, end="")
        if args.out:
            args.out.write_text(table)
    return 1 if any("error" in r for r in ordered) else 0


if __name__ == "__main__":
    sys.exit(main())
