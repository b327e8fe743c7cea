"""Where the global map misses, is the true symmetry an isometry? Per shape, from saved maps.

For every shape of ``tosca.py`` (or ``--shapes``), a default ``detect`` saved under
``--saved DIR/<shape>`` (run and saved when absent); then the local distortion of its
global map and of the true symmetry (:func:`intrinsym.globalmap.distortion.local_distortion`: per
vertex, the mean change of the geodesic distances to the vertices within 0.1), averaged
over the vertices the map misses by more than 0.05 ("misses") and over the others
("hits"). Where the truth changes the distances around the misses several times more than
the map does, the misses are the truth's, not the map's: no isometry-based method can be
asked to find it there. Prints one Markdown table. Command::

    OPENBLAS_NUM_THREADS=1 python benchmarks/local_isometry.py --data DATA --saved DIR [--shapes michael ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import intrinsym
from _data import add_data_argument, data_folder, no_data
from intrinsym.evaluation import evaluate
from intrinsym.geodesics import geodesics
from intrinsym.globalmap import distortion
from tosca import cases, select


def measure(case, saved: Path) -> dict | None:
    """One shape's miss share and the mean local distortion of map and truth at the
    misses and the hits; None without a global map."""
    mesh = intrinsym.load(case.mesh)
    truth = case.truth_map(mesh)
    folder = saved / case.name
    if not (folder / "symmetry_map.npy").is_file():
        intrinsym.detect(mesh).save(folder)
    found = np.load(folder / "symmetry_map.npy")
    if (found < 0).all():
        return None
    unit = geodesics.unit_area_graph(mesh)
    _, vmap, graph = unit
    miss = evaluate.map_errors(vmap[found], vmap[truth], graph) > 0.05
    row: dict = {"shape": case.name, "miss": float(miss.mean())}
    for name, m in (("map", found), ("truth", truth)):
        local = distortion.local_distortion(m, mesh, unit=unit)
        for where, sel in (("misses", miss), ("hits", ~miss)):
            row[name, where] = float(np.nanmean(local[sel])) if sel.any() else float("nan")
    return row


def markdown(rows: list[dict]) -> str:
    """One table row per shape: miss share, then map and truth at the misses and hits."""
    out = [
        "| shape | misses (> 0.05) | map at the misses | truth at the misses | map at the hits | truth at the hits |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        cells = [f"{r[name, where]:.4f}" for where in ("misses", "hits") for name in ("map", "truth")]
        out.append(f"| {r['shape']} | {r['miss']:.3f} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(parser)
    parser.add_argument("--saved", type=Path, required=True, help="folder of saved detect results, one per shape")
    parser.add_argument("--shapes", nargs="+", metavar="NAME", help="shape or class names (default: all)")
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    if data is None:
        print(no_data("local_isometry.py", args.data))
        return 0
    chosen = select(cases(data), args.shapes)
    rows = [r for r in (measure(c, args.saved) for c in chosen) if r is not None]
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
