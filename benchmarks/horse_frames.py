"""Self-symmetry of Sumner's posed horse frames, and how intrinsically symmetric they are.

The frames of ``sumner_horse/`` of the data folder share the connectivity of the reference pose
``horse_ref``, which is posed mirror-symmetrically: its best reflection
(:func:`intrinsym.evaluation.evaluate.extrinsic_mirror`), carried through the shared vertex
indices, is every frame's ground-truth left/right map. For each mesh this prints

- how far that map is from an isometry of the mesh: the change of geodesic distance
  |d(x, y) - d(m(x), m(y))| over ``PAIRS`` random vertices x and every vertex y,
  median and 90th percentile (for comparison, the same of TOSCA's posed shapes with
  their symmetry files, when ``tosca_sym`` is present);
- the global map of the spectral baseline (:func:`intrinsym.spectral.spectral.spectral_symmetry`)
  and of ``intrinsym.detect`` at the defaults and with the trivial match removed
  (``trivial_weight=0``), scored as ``intrinsym evaluate`` scores (within 0.05 and 0.10
  of sqrt(area), geodesic, and the mean error)::

    python benchmarks/horse_frames.py [--data DIR] [--frames horse-01 horse-03]

The data folder is ``--data`` or ``$INTRINSYM_DATA``; without it (or its
``sumner_horse/``) the script says so in one line and exits 0.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

import intrinsym
from _data import add_data_argument, data_folder, no_data
from intrinsym.evaluation import evaluate
from intrinsym.geodesics import geodesics
from intrinsym.mesh.shape import Shape, surface_area
from intrinsym.spectral import spectral

#: Random vertices x of the geodesic-change measure.
PAIRS = 60
FRAMES = ("horse_ref", "horse-01", "horse-02", "horse-03", "horse-04", "horse-05")
TOSCA = ("cat1", "horse5", "victoria1", "michael2")


def geodesic_change(shape: Shape, sym: np.ndarray, n: int = PAIRS, seed: int = 0) -> tuple[float, float]:
    """Median and 90th percentile of |d(x, y) - d(sym[x], sym[y])| (units of sqrt(area))
    over ``n`` random vertices x and every vertex y."""
    vertices = np.asarray(shape.vertices) / np.sqrt(surface_area(shape))
    graph = geodesics.surface_graph(vertices, shape.faces)
    x = np.random.default_rng(seed).choice(len(vertices), n, replace=False)
    change = np.abs(geodesics.distances_from(graph, x) - geodesics.distances_from(graph, sym[x])[:, sym])
    return float(np.median(change)), float(np.quantile(change, 0.9))


def scored(predicted: np.ndarray, shape: Shape, sym: np.ndarray) -> str:
    if predicted.max() < 0:
        return "no global symmetry"
    s = evaluate.score_map(predicted, shape, sym)
    return f"{s.within(0.05):.3f} / {s.within(0.10):.3f} / {s.mean_error:.3f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(parser, "research data folder with sumner_horse/ (and tosca_sym/)")
    parser.add_argument("--frames", nargs="+", default=list(FRAMES), help="frames of sumner_horse to run")
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    horse = None if data is None else data / "sumner_horse"
    if horse is None or not horse.is_dir():
        print(no_data("horse_frames.py", args.data if horse is None else horse))
        return 0
    sym = evaluate.extrinsic_mirror(intrinsym.load(horse / "horse_ref.obj").vertices)[0]
    print(
        "| shape | geodesic change of the true map: median / p90 | spectral baseline: within 0.05 / 0.10 / mean "
        "| ours, defaults | ours, trivial_weight 0 |"
    )
    print("|---|---|---|---|---|")
    for name in args.frames:
        shape = intrinsym.load(horse / f"{name}.obj")
        median, p90 = geodesic_change(shape, sym)
        cells = [scored(spectral.spectral_symmetry(shape.vertices, shape.faces), shape, sym)]
        for weight in ("auto", 0.0):
            params = intrinsym.make_params(trivial_weight=weight)
            cells.append(scored(intrinsym.detect(shape, params).symmetry_map(), shape, sym))
        print(f"| {name} | {median:.4f} / {p90:.4f} | " + " | ".join(cells) + " |", flush=True)
    for name in TOSCA:
        path = data / "tosca_sym" / f"{name}.off"
        if path.is_file():
            shape = intrinsym.load(path)
            true = evaluate.load_symmetry_map(path.with_name(f"{name.rstrip('0123456789')}.sym"), len(shape.vertices))
            median, p90 = geodesic_change(shape, true)
            print(f"| TOSCA {name} | {median:.4f} / {p90:.4f} | | | |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
