"""The spectral baseline's global map on the TOSCA / KIDS table of docs/results.md.

Runs :func:`intrinsym.spectral.spectral.spectral_symmetry` (sign search over Laplace-Beltrami
eigenfunctions, then ZoomOut) on every shape of the "Default settings on TOSCA and KIDS"
table of docs/results.md and scores its map exactly as that table scores ours
(:func:`intrinsym.evaluation.evaluate.score_map`, what ``intrinsym evaluate`` runs: fraction of
vertices whose image lies within 0.05 and 0.10 of sqrt(area) of the true mirror image,
geodesic, and the mean error)::

    python benchmarks/spectral.py [--data DIR] [--shapes cat1 kids] [--json]

Prints a markdown table (``--json``: one JSON object per shape instead). ``seconds`` is
the wall time of ``spectral_symmetry`` alone (eigenpairs included, loading and scoring
not). The data folder is ``--data`` or ``$INTRINSYM_DATA``; without it the script says
so in one line and exits 0.

On a machine whose cores are busy with other work, OpenBLAS threads waiting on each
other slow the eigensolver and ZoomOut's small matrix products down (measured back to
back on the 2-core development machine while other jobs ran: michael1 25.8 s with the
default threads, 14.8 s with one; wolf0 4.9 s and 1.6 s), so the numbers of docs/results.md were
taken with ``OPENBLAS_NUM_THREADS=1``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from _data import add_data_argument, data_folder, no_data
from intrinsym.evaluation import evaluate
from intrinsym.mesh.io import load
from intrinsym.mesh.shape import clean
from intrinsym.spectral import spectral

#: Shape name -> (mesh, ground-truth map) relative to the data folder, in the table's order.
SHAPES = {
    **{
        name: (f"tosca_sym/{name}.off", f"tosca_sym/{name.rstrip('0123456789')}.sym")
        for name in (
            "cat1",
            "dog1",
            "horse5",
            "michael1",
            "victoria1",
            "centaur1",
            "wolf1",
            "michael2",
            "cat0",
            "dog0",
            "horse0",
            "victoria0",
            "centaur0",
            "wolf0",
        )
    },
    "kids": ("kids_sym/0001.isometry.1.off", "kids_sym/sym.txt"),
}


def run(data: Path, name: str) -> dict:
    """Map one shape with the baseline and score it; a JSON-ready dict."""
    mesh_path, sym_path = SHAPES[name]
    shape = load(data / mesh_path)
    cleaned, vertex_map = clean(shape)
    start = time.perf_counter()
    image = spectral.spectral_symmetry(cleaned.vertices, cleaned.faces)
    seconds = time.perf_counter() - start
    # back to input vertices: each cleaned vertex is represented by its first input vertex
    first = np.empty(len(cleaned.vertices), dtype=np.int64)
    first[vertex_map[::-1]] = np.arange(len(vertex_map))[::-1]
    sym = evaluate.load_symmetry_map(data / sym_path, len(shape.vertices))
    scores = evaluate.score_map(first[image[vertex_map]], shape, sym)
    return {
        "shape": name,
        "within_0.05": scores.within(0.05),
        "within_0.10": scores.within(0.10),
        "mean_error": scores.mean_error,
        "seconds": seconds,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(parser)
    parser.add_argument("--shapes", nargs="+", choices=list(SHAPES), default=list(SHAPES))
    parser.add_argument("--json", action="store_true", help="one JSON object per shape")
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    if data is None:
        print(no_data("spectral.py", args.data))
        return 0
    if not args.json:
        print("| shape | map within 0.05 | map within 0.10 | map mean error | seconds |")
        print("|---|---|---|---|---|")
    for name in args.shapes:
        row = run(data, name)
        if args.json:
            print(json.dumps(row))
        else:
            print(
                f"| {name} | {row['within_0.05']:.3f} | {row['within_0.10']:.3f} "
                f"| {row['mean_error']:.4f} | {row['seconds']:.1f} |"
            )
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
