"""Robustness to the defects of real scans, on posed TOSCA shapes with ground truth.

Each shape is perturbed (noise along the normal, quadric decimation, a remeshing,
holes, a point cloud, a split into two components), detected with the default
parameters, and scored on the clean mesh: the perturbed shape's global map is carried
back by nearest vertices (each clean vertex -> nearest perturbed vertex -> its image ->
nearest clean vertex) and scored against the clean ground truth (share within 0.10
sqrt(area) of the true image); the marginals are scored on the perturbed shape against
the ground truth carried to it the same way (mirror hit, peak recall).

    python benchmarks/robustness.py --data DIR [--shapes cat1 michael1] [--only noise_1 ...]
        [--cache FOLDER] [--markdown FILE]

Decimation uses fast-simplification (quadric error metric) when installed, else
trimesh's. Rows are cached per (shape, perturbation) in ``--cache`` as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).parent))

import intrinsym  # noqa: E402
from _data import add_data_argument, data_folder, no_data  # noqa: E402
from intrinsym.evaluation import evaluate  # noqa: E402
from intrinsym.mesh.shape import Shape, vertex_normals  # noqa: E402

Mesh = tuple[np.ndarray, np.ndarray | None]


def _decimate(v: np.ndarray, f: np.ndarray, n_vertices: int) -> Mesh:
    """Quadric decimation to about ``n_vertices`` vertices."""
    reduction = float(np.clip(1.0 - 2.0 * n_vertices / len(f), 0.0, 0.99))
    try:
        import fast_simplification

        out_v, out_f = fast_simplification.simplify(v.astype(np.float32), f.astype(np.int32), reduction)
        return np.asarray(out_v, dtype=np.float64), np.asarray(out_f, dtype=np.int64)
    except ImportError:
        import trimesh

        mesh = trimesh.Trimesh(v, f, process=False).simplify_quadric_decimation(face_count=2 * n_vertices)
        return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _noise(percent: float) -> Callable[[np.ndarray, np.ndarray, np.random.Generator], Mesh]:
    def apply(v: np.ndarray, f: np.ndarray, rng: np.random.Generator) -> Mesh:
        diagonal = float(np.linalg.norm(np.ptp(v, axis=0)))
        normals = vertex_normals(Shape(v, f, ""))
        return v + normals * rng.normal(0.0, percent / 100 * diagonal, len(v))[:, None], f

    return apply


def _remesh(v: np.ndarray, f: np.ndarray, rng: np.random.Generator) -> Mesh:
    """A different triangulation of the same surface at the same resolution: midpoint
    subdivision, then quadric decimation back to the vertex count."""
    import trimesh

    edge = float(np.mean(trimesh.Trimesh(v, f, process=False).edges_unique_length))
    sv, sf = trimesh.remesh.subdivide_to_size(v, f, max_edge=edge / 2)
    return _decimate(np.asarray(sv), np.asarray(sf), len(v))


def _holes(v: np.ndarray, f: np.ndarray, rng: np.random.Generator, count: int = 5, share: float = 0.1) -> Mesh:
    """``count`` balls of faces removed, about ``share`` of the faces in all."""
    centroids = v[f].mean(axis=1)
    tree = cKDTree(centroids)
    keep = np.ones(len(f), dtype=bool)
    for centre in rng.choice(len(f), count, replace=False):
        keep[tree.query(centroids[centre], k=int(share * len(f) / count))[1]] = False
    return _compact(v, f[keep])


def _compact(v: np.ndarray, f: np.ndarray) -> Mesh:
    used = np.unique(f)
    index = np.full(len(v), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    return v[used], index[f]


def _cloud(v: np.ndarray, f: np.ndarray, rng: np.random.Generator, n: int = 10000) -> Mesh:
    """``n`` area-uniform points of the surface, no faces."""
    areas = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    tri = rng.choice(len(f), n, p=areas / areas.sum())
    a, b = rng.random((2, n))
    swap = a + b > 1
    a[swap], b[swap] = 1 - a[swap], 1 - b[swap]
    t = v[f[tri]]
    return t[:, 0] + a[:, None] * (t[:, 1] - t[:, 0]) + b[:, None] * (t[:, 2] - t[:, 0]), None


def _split(v: np.ndarray, f: np.ndarray, rng: np.random.Generator) -> Mesh:
    """Two components: the faces within a slab across the middle of the longest axis removed."""
    axis = int(np.argmax(np.ptp(v, axis=0)))
    c = v[f].mean(axis=1)[:, axis]
    middle, width = float(np.median(v[:, axis])), 0.02 * float(np.ptp(v[:, axis]))
    kept = f[np.abs(c - middle) > width]
    return _compact(v, kept)


def _wound(v: np.ndarray, f: np.ndarray, rng: np.random.Generator, share: float = 0.5) -> Mesh:
    """Half the faces, drawn at random, wound the other way (an inconsistently oriented export)."""
    turn = rng.random(len(f)) < share
    out = f.copy()
    out[turn] = out[turn][:, ::-1]
    return v, out


PERTURBATIONS: dict[str, tuple[str, Callable[..., Mesh] | None]] = {
    "clean": ("clean", None),
    "noise_0.1": ("normal noise 0.1 % of the diagonal", _noise(0.1)),
    "noise_0.3": ("normal noise 0.3 %", _noise(0.3)),
    "noise_1": ("normal noise 1 %", _noise(1.0)),
    "noise_2": ("normal noise 2 %", _noise(2.0)),
    "decimate_5000": ("decimated to 5,000 vertices", lambda v, f, rng: _decimate(v, f, 5000)),
    "decimate_2000": ("decimated to 2,000 vertices", lambda v, f, rng: _decimate(v, f, 2000)),
    "remesh": ("remeshed (subdivided, decimated back)", _remesh),
    "holes": ("five holes (about 10 % of the faces)", _holes),
    "cloud": ("point cloud of 10,000 points", _cloud),
    "split": ("split into two components", _split),
    "wound": ("half the faces wound the other way", _wound),
}


def run_case(mesh_path: Path, truth_path: Path, name: str, seed: int = 0) -> dict:
    """Detect on one perturbation of one shape; the JSON-ready row."""
    shape = intrinsym.load(mesh_path)
    v, f = shape.vertices, shape.faces
    sym = evaluate.load_symmetry_map(truth_path, len(v))
    perturb = PERTURBATIONS[name][1]
    pv, pf = (v, f) if perturb is None else perturb(v, f, np.random.default_rng(seed))
    to_p = cKDTree(pv).query(v)[1]  # clean vertex -> nearest perturbed vertex
    to_clean = cKDTree(v).query(pv)[1]  # perturbed vertex -> nearest clean vertex
    start = time.perf_counter()
    row: dict = {"shape": mesh_path.stem, "perturbation": name, "vertices": len(pv)}
    try:
        result = intrinsym.detect(Shape(pv, pf, str(mesh_path)), seed=seed)
    except intrinsym.IntrinsymError as err:
        row["error"] = str(err)
        return row
    row["seconds"] = time.perf_counter() - start
    image = np.asarray(result.symmetry_map())
    carried = np.where(image[to_p] >= 0, to_clean[np.maximum(image[to_p], 0)], -1)
    row["within_0.10"] = float(evaluate.score_map(carried, shape, sym).as_dict()["within_0.10"])
    truth_p = np.where(sym[to_clean] >= 0, to_p[np.maximum(sym[to_clean], 0)], -1)
    if pf is not None:
        marginals = evaluate.score_marginals(
            result.marginals,
            result.source_point_vertex,
            result.target_point_vertex,
            Shape(pv, pf, ""),
            truth_p,
            seed=seed,
        )
        row["mirror_hit"], row["peak_recall"] = float(marginals.mirror_hit), float(marginals.peak_recall)
    return row


def markdown(rows: list[dict], shapes: list[str]) -> str:
    lines = [
        "| perturbation | " + " | ".join(shapes) + " |",
        "|---|" + "---|" * len(shapes),
    ]
    for name, (label, _) in PERTURBATIONS.items():
        cells = []
        for s in shapes:
            row = next((r for r in rows if r["shape"] == s and r["perturbation"] == name), None)
            if row is None:
                cells.append("not run")
            elif "error" in row:
                cells.append(f"error: {row['error']}")
            else:
                extra = f" (mirror hit {row['mirror_hit']:.2f})" if "mirror_hit" in row else ""
                cells.append(f"{row['within_0.10']:.3f}{extra}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(parser)
    parser.add_argument("--shapes", nargs="+", default=["cat1", "michael1"])
    parser.add_argument("--only", nargs="+", choices=sorted(PERTURBATIONS), help="perturbations to run (default all)")
    parser.add_argument(
        "--cache", help="folder of cached rows, reused when present (they are not keyed by the code: one per version)"
    )
    parser.add_argument("--markdown", help="also write the table to this file")
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    if data is None:
        print(no_data("robustness", args.data))
        return 0
    cache = None if args.cache is None else Path(args.cache)
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.only or list(PERTURBATIONS):
        for shape in args.shapes:
            mesh = data / "tosca_sym" / f"{shape}.off"
            truth = data / "tosca_sym" / f"{shape.rstrip('0123456789')}.sym"
            file = None if cache is None else cache / f"{shape}_{name}.json"
            if file is not None and file.is_file():
                rows.append(json.loads(file.read_text()))
                continue
            row = run_case(mesh, truth, name)
            if file is not None:
                file.write_text(json.dumps(row, indent=2))
            rows.append(row)
            print(json.dumps(row), flush=True)
    table = markdown(rows, args.shapes)
    print(table)
    if args.markdown:
        Path(args.markdown).write_text(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
