"""The global map's candidates and the global/partial decision, measured against the truth.

Per shape, one ``detect`` with the identity removed (``trivial_weight=0``: the first BP pass
of the default "auto", which decides on this pass's marginals), then from that run:

- the candidate global maps (the extraction's map, seeded ZoomOut's, the best spectral
  candidate), each with the marginal mass it keeps and its share of vertices within 0.05 /
  0.10 of the true image and mean error;
- which candidate each rule picks: now (ZoomOut unless it keeps ``MAP_MARGIN`` less mass
  than the extraction's), before (ZoomOut when it kept half of the symmetry's sample
  pairs), and "most mass";
- the per-vertex marginal mass of the chosen map against its errors (reliability table and
  expected calibration error over all shapes with a truth);
- the global/partial statistics of every shape, with and without a global symmetry: BP's
  argmax edge share (the rule of "auto"), its long-range agreement
  (:func:`long_range_agreement`), the edge share and kept mass of the extraction's
  global symmetry and of ZoomOut's map.

Shapes: the TOSCA poses, KIDS and the mirror-posed shapes of ``tosca.py``; generated ones
(``figure``, ``figure14``, ``figure_small``, ``star3``, ``star5``) at small size;
negatives without a global symmetry: ``partial`` (seeds 0 and 1, and ``partial_small``),
``partial_bent`` (one limb bent), ``bunny``, ``fandisk``. One JSON per shape in ``--cache``
(resumable); ``--saved DIR`` reuses result folders ``DIR/<shape>`` saved by an earlier
identity-removed run::

    OPENBLAS_NUM_THREADS=1 python benchmarks/global_map.py --data DATA --cache CACHE \\
        [--shapes cat3 figure partial ...] [-o table.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

import intrinsym
from _data import add_data_argument, data_folder, no_data
from intrinsym.evaluation import evaluate
from intrinsym.extract import _kernels as kernels
from intrinsym.extract.extract import consistency
from intrinsym.extract.support import SourceGraph
from intrinsym.extract.symmetry import Symmetry
from intrinsym.geodesics import geodesics
from intrinsym.globalmap.confidence import calibration, map_mass, mass_within, sample_images
from intrinsym.globalmap.globalmap import best_spectral, cell_mass, choose, zoomout_map
from intrinsym.mesh import generated as shapes
from intrinsym.mesh.shape import Shape, clean, surface_area
from intrinsym.pipeline import extract_result, min_vertices, sample_pair
from intrinsym.surface import prepare
from intrinsym.unary import unary
from tosca import cases

CANDIDATES = ("extraction", "zoomout", "spectral")
#: Generated shapes: (make, detect sizes, is a negative).
GENERATED = {
    "figure": (lambda: shapes.figure(10), dict(n_source=150, n_target=1500), False),
    "figure14": (lambda: shapes.figure(14), dict(n_source=200, n_target=2500), False),
    "figure_small": (
        lambda: shapes.figure(10),
        dict(n_source=60, n_target=600, eigenpairs=40, spin_cloud=10000, iterations=10),
        False,
    ),
    "star3": (lambda: shapes.star(3, 14), dict(n_source=150, n_target=1500), False),
    "star5": (lambda: shapes.star(5, 10), dict(n_source=150, n_target=1500), False),
    "partial": (lambda: shapes.partial(16), {}, True),
    "partial_s1": (lambda: shapes.partial(16), dict(seed=1), True),
    "partial_small": (lambda: shapes.partial(12), dict(n_source=150, n_target=1500), True),
    "partial_bent": (lambda: _bent(shapes.partial(16)), {}, True),
}


def _bent(g: shapes.GeneratedShape) -> shapes.GeneratedShape:
    """The partial shape with one limb bent by 0.9 rad: two identical limbs posed differently."""
    return dataclasses.replace(g, name="partial_bent", vertices=shapes.bend(g.vertices, np.pi / 2, 1.25, 0.9, 0.6))


NEGATIVE_MESHES = {"bunny": "static/stanford-bunny.obj", "fandisk": "static/fandisk.obj"}
#: The global/partial statistics tabulated, with their labels.
STATISTICS = {
    "argmax_share": "BP argmax edge share",
    "long_range": "long-range agreement of BP's argmax",
    "extraction_edges": "edge share of the extraction's map",
    "zoomout_edges": "edge share of ZoomOut's map",
    "extraction_mass": "mass kept by the extraction's map",
    "zoomout_mass": "mass kept by ZoomOut's map",
}
#: The rule before: ZoomOut's map when it keeps this share of the symmetry's sample pairs.
GUARD = 0.5


#: Landmark samples of the long-range agreement, and its tolerance (units of sqrt(area)).
LANDMARKS = 64
LONG_RANGE_TOLERANCE = 0.05


def long_range_agreement(graph, source: np.ndarray, image: np.ndarray, landmarks: int = LANDMARKS) -> float:
    """Share of landmark samples x (evenly spaced in the sample order) whose median over
    all samples y of |d(x, y) - d(image x, image y)| is below ``LONG_RANGE_TOLERANCE``:
    whether a self-map keeps long geodesic distances, not only the short edges BP's
    pairwise term asks it to keep. ``graph``: the working surface (unit area); ``source``,
    ``image``: working vertices of the samples and of their images."""
    pick = np.unique(np.linspace(0, len(source) - 1, min(landmarks, len(source))).round().astype(np.int64))
    before = geodesics.distances_from(graph, source[pick])[:, source]
    after = geodesics.distances_from(graph, image[pick])[:, image]
    with np.errstate(invalid="ignore"):
        distortion = np.abs(before - after)
    distortion[np.isinf(before) & np.isinf(after)] = 0.0
    return float(np.mean(np.median(distortion, axis=1) < LONG_RANGE_TOLERANCE))


def _guard_agreement(sym: Symmetry, vmap: np.ndarray, source_vertex: np.ndarray, support) -> float:
    """Share of the symmetry's pairs s -> t that the map sends within the target radius of t."""
    t = support.targets
    image = np.asarray(vmap)[np.asarray(source_vertex)[sym.source]]
    owner = np.where(image >= 0, np.asarray(support.vertex_target)[np.maximum(image, 0)], -1)
    kept = [
        b >= 0 and kernels.find(t.indptr, t.indices, t.dist, a, b, t.radius) <= t.radius
        for a, b in zip(sym.target, owner, strict=True)
    ]
    return float(np.mean(kept)) if kept else 1.0


def _shape(name: str, data: Path | None) -> tuple[Shape, list[np.ndarray], bool, dict]:
    """The mesh, its true symmetry maps (empty: none), whether it is a negative, detect sizes."""
    if name in GENERATED:
        make, sizes, negative = GENERATED[name]
        g = make()
        return Shape(g.vertices, g.faces), [] if negative else list(g.symmetries), negative, sizes
    if data is None:
        raise SystemExit(no_data("global_map.py", data))
    if name in NEGATIVE_MESHES:
        return intrinsym.load(data / NEGATIVE_MESHES[name]), [], True, {}
    found = [c for c in cases(data) if c.name == name]
    if not found:
        raise SystemExit(f"global_map.py: unknown shape {name}")
    case = found[0]
    mesh = intrinsym.load(case.mesh)
    return mesh, [case.truth_map(mesh)], False, {}


def _errors(vmap: np.ndarray, truths: list[np.ndarray], mesh: Shape) -> tuple[dict, np.ndarray]:
    """Scores of a map against the nearest of the true maps, and its per-vertex errors."""
    cleaned, cv = clean(mesh)
    graph = geodesics.surface_graph(cleaned.vertices / np.sqrt(surface_area(cleaned)), cleaned.faces)
    best: tuple[dict, np.ndarray] | None = None
    for truth in truths:
        scored = truth >= 0
        e = evaluate.map_errors(
            np.where(vmap[scored] >= 0, cv[np.maximum(vmap[scored], 0)], -1), cv[truth[scored]], graph
        )
        err = np.full(len(vmap), np.nan)
        err[scored] = e
        finite = e[np.isfinite(e)]
        scores = {
            "within_0.05": float(np.mean(e <= 0.05)),
            "within_0.10": float(np.mean(e <= 0.10)),
            "mean_error": float(finite.mean()) if len(finite) else float("nan"),
        }
        if best is None or scores["mean_error"] < best[0]["mean_error"]:
            best = (scores, err)
    assert best is not None
    return best


def measure(name: str, data: Path | None, saved: Path | None) -> tuple[dict, dict]:
    """One shape's row and per-vertex arrays (errors and mass of each candidate)."""
    mesh, truths, negative, sizes = _shape(name, data)
    folder = None if saved is None else saved / name
    t0 = time.perf_counter()
    if folder is not None and (folder / "run.json").is_file():
        result = intrinsym.Result.load(folder)
    else:
        params = dataclasses.replace(intrinsym.make_params(**sizes), trivial_weight=0.0)
        result = intrinsym.detect(mesh, params)
    p = result.params
    extraction = extract_result(result)
    result = dataclasses.replace(result, extraction=extraction)
    n_s = len(result.marginals)
    targets = result.support.targets
    graph = SourceGraph.from_edges(result.edges, result.support.edge_length, n_s)
    tolerance = max(p.d_error, result.info.resolved.target_spacing)
    row: dict = {"shape": name, "negative": negative, "seconds": time.perf_counter() - t0}
    argmax = result.marginals.argmax(axis=1)
    row["argmax_share"] = consistency(argmax, graph, targets, tolerance)
    surf = prepare(mesh, min_vertices(p))
    ps, pt = sample_pair(surf, surf, p)
    row["long_range"] = long_range_agreement(surf.graph, ps, pt[argmax])
    sym = extraction.global_symmetry
    row["global"] = sym is not None
    arrays: dict = {}
    if sym is None:
        return row, arrays
    row["coverage"] = len(sym.source) / n_s
    spectrum = unary.spectrum(surf, p.eigenpairs)
    source_vertex = result.source_point_vertex
    maps = {"extraction": result.extraction_map()}

    def images(vmap: np.ndarray) -> np.ndarray:
        return sample_images(vmap, source_vertex, result.support.vertex_target)

    judge = cell_mass(result.marginals, result.support)
    maps["zoomout"] = zoomout_map(
        surf, ps, pt, sym, spectrum[1], p, source_vertex, result.support.vertex_source, judge, maps["extraction"]
    )

    def mass_of(vmap: np.ndarray) -> float:
        return float(mass_within(result.marginals, images(vmap), targets, p.mass_radius).mean())

    found = best_spectral(surf, source_vertex, spectrum, mass_of, p)
    if found is not None:
        maps["spectral"] = found[0]
    row["guard"] = _guard_agreement(sym, maps["zoomout"], source_vertex, result.support)
    for key, vmap in maps.items():
        row[f"{key}_mass"] = mass_of(vmap)
        row[f"{key}_edges"] = consistency(images(vmap), graph, targets, tolerance)
        arrays[f"mass_{key}"] = map_mass(result.marginals, vmap, source_vertex, result.support, p.mass_radius)
        if truths:
            scores, err = _errors(vmap, truths, mesh)
            row.update({f"{key}_{k}": v for k, v in scores.items()})
            arrays[f"err_{key}"] = err
    row["rule_before"] = "zoomout" if row["guard"] >= GUARD else "extraction"
    row["rule_most_mass"] = max(("extraction", "zoomout"), key=lambda k: row[f"{k}_mass"])
    row["rule_now"] = choose({key: row[f"{key}_mass"] for key in maps}, p.fallback_mass)
    return row, arrays


def _cell(row: dict, key: str) -> str:
    if f"{key}_mass" not in row or f"{key}_within_0.05" not in row:
        return "-"
    return (
        f"{row[f'{key}_mass']:.3f} / {row[f'{key}_within_0.05']:.3f} / {row[f'{key}_within_0.10']:.3f} / "
        f"{row[f'{key}_mean_error']:.4f}"
    )


def markdown(rows: list[dict], arrays: dict[str, dict]) -> str:
    """The candidates table, the rules' means, the reliability table and the statistics."""
    out = [
        "| shape | extraction's map | seeded ZoomOut | best spectral candidate | before (guard) | most mass | now |",
        "|---|---|---|---|---|---|---|",
    ]
    scored = [r for r in rows if not r["negative"] and r["global"] and "extraction_within_0.05" in r]
    for r in scored:
        cells = " | ".join(_cell(r, k) for k in CANDIDATES)
        rules = f"{r['rule_before']} ({r['guard']:.2f}) | {r['rule_most_mass']} | {r['rule_now']}"
        out.append(f"| {r['shape']} | {cells} | {rules} |")
    out.append("")
    for rule, label in (("rule_before", "before (guard)"), ("rule_most_mass", "most mass"), ("rule_now", "now")):
        got = np.array([[r[f"{r[rule]}_{k}"] for k in ("within_0.05", "within_0.10", "mean_error")] for r in scored])
        if len(got):
            out.append(
                f"- {label}: mean within 0.05 {got[:, 0].mean():.3f}, within 0.10 {got[:, 1].mean():.3f}, "
                f"mean error {got[:, 2].mean():.4f}; worst within 0.05 {got[:, 0].min():.3f}, "
                f"within 0.10 {got[:, 1].min():.3f}"
            )
    masses, errors = [], []
    for r in scored:
        a = arrays[r["shape"]]
        err = a[f"err_{r['rule_now']}"]
        ok = np.isfinite(err)
        masses.append(a[f"mass_{r['rule_now']}"][ok])
        errors.append(err[ok])
    for threshold in (0.05, 0.10):
        if not masses:
            break
        per_shape = [calibration(m, e <= threshold)[0] for m, e in zip(masses, errors, strict=True)]
        ece, bins = calibration(np.concatenate(masses), np.concatenate(errors) <= threshold)
        out += [
            "",
            f"Per-vertex marginal mass of the chosen map against within {threshold:.2f}: ECE {ece:.3f} over all "
            "(per shape: " + ", ".join(f"{r['shape']} {e:.3f}" for r, e in zip(scored, per_shape, strict=True)) + ")",
            "",
            f"| mass | share of vertices | mean mass | within {threshold:.2f} |",
            "|---|---|---|---|",
        ]
        out += [
            f"| {b.low:.1f}-{b.high:.1f} | {b.share:.3f} | {b.confidence:.3f} | {b.accuracy:.3f} |"
            for b in bins
            if b.share > 0
        ]
    out += ["", "| statistic | with a global symmetry (sorted) | without | gap |", "|---|---|---|---|"]
    for stat, label in STATISTICS.items():
        pos = sorted(r[stat] for r in rows if not r["negative"] and stat in r)
        neg = sorted(r[stat] for r in rows if r["negative"] and stat in r)
        gap = f"{pos[0] - neg[-1]:+.3f}" if pos and neg else "-"
        out.append(f"| {label} | {', '.join(f'{v:.3f}' for v in pos)} | {', '.join(f'{v:.3f}' for v in neg)} | {gap} |")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(parser)
    parser.add_argument("--shapes", nargs="+", default=["figure", "figure14", "figure_small", "partial"])
    parser.add_argument("--cache", type=Path, required=True, help="one JSON + NPZ per shape (resumable)")
    parser.add_argument("--saved", type=Path, help="reuse identity-removed result folders DIR/<shape>")
    parser.add_argument("-o", "--output", type=Path, help="write the markdown here too")
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    args.cache.mkdir(parents=True, exist_ok=True)
    rows, arrays = [], {}
    for name in args.shapes:
        row_path, array_path = args.cache / f"{name}.json", args.cache / f"{name}.npz"
        if not row_path.is_file():
            row, arr = measure(name, data, args.saved)
            np.savez_compressed(array_path, **arr)
            row_path.write_text(json.dumps(row, indent=1))
            print(f"{name}: {time.strftime('%H:%M')} {json.dumps(row)}", file=sys.stderr, flush=True)
        rows.append(json.loads(row_path.read_text()))
        with np.load(array_path) as z:
            arrays[name] = dict(z)
    table = markdown(rows, arrays)
    print(table)
    if args.output:
        args.output.write_text(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
