"""The global map's geodesic trilateration, measured against the truth at several settings.

For every shape of ``tosca.py`` (or ``--shapes``), a default ``detect`` without the
refinement (``--refine-anchors 0``), saved under ``--saved DIR/<shape>`` and reused when
present; then its global map refined by :func:`intrinsym.globalmap.globalmap.refined_map` at each
number of anchors (``--anchors``) and tolerance in target spacings (``--tolerances``),
each scored as ``intrinsym evaluate`` scores it (within 0.05 / 0.10 of the true image,
mean error; geodesic, units of sqrt(area)). Prints one Markdown table: per shape, the map
before and at every setting, the share of vertices the default setting moved; then per
setting the means, the shapes at the targets and the largest loss. Command::

    OPENBLAS_NUM_THREADS=1 python benchmarks/refine.py --data DATA --saved DIR \\
        [--shapes michael3 cat ...] [--anchors 20 15 30] [--tolerances 2 1.5 3] [--exact-anchors]

``--exact-anchors`` anchors every source sample at its true image instead of its
marginal peak: an oracle, what the trilateration reaches with perfect anchors.

The first setting is the one whose moved share the table shows (the default: 20
anchors, 2 spacings). A shape whose run found no global symmetry is left out.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

import intrinsym
from _data import add_data_argument, data_folder, no_data
from intrinsym.evaluation import evaluate
from intrinsym.globalmap.globalmap import refined_map
from intrinsym.pipeline import extract_result, min_vertices, sample_pair
from intrinsym.surface import prepare
from tosca import cases, select


def _scores(vmap: np.ndarray, mesh: intrinsym.Shape, truth: np.ndarray) -> tuple[float, float, float]:
    s = evaluate.score_map(vmap, mesh, truth)
    return s.within(0.05), s.within(0.10), s.mean_error


def measure(case, saved: Path, settings: list[tuple[int, float]], exact: bool = False) -> dict | None:
    """One shape: scores before and at every setting, and the default setting's moved share
    (``exact``: the source samples anchored at their true images)."""
    mesh = intrinsym.load(case.mesh)
    truth = case.truth_map(mesh)
    folder = saved / case.name
    if (folder / "run.json").is_file():
        loaded = intrinsym.Result.load(folder)
        result = dataclasses.replace(loaded, extraction=extract_result(loaded))
    else:
        result = intrinsym.detect(mesh, intrinsym.make_params(refine_anchors=0))
        result.save(folder)
    start = result.symmetry_map()
    if (start < 0).all():
        return None
    p = result.params
    surf = prepare(mesh, min_vertices(p))
    ps, pt = sample_pair(surf, surf, p)
    spacing = result.info.resolved.target_spacing
    row: dict = {"shape": case.name, "before": _scores(start, mesh, truth)}
    targets, marginals = pt, result.marginals
    if exact:
        targets = surf.vertex_map[truth[result.source_point_vertex]]
        marginals = np.eye(len(ps), dtype=np.float32)
    for k, tol in settings:
        params = dataclasses.replace(p, refine_anchors=k)
        refined = refined_map(
            surf, ps, targets, result.source_point_vertex, marginals, start, result.edges, spacing, params, tol
        )
        row[(k, tol)] = _scores(refined, mesh, truth)
        row.setdefault("moved", float(np.mean(refined != start)))
    return row


def markdown(rows: list[dict], settings: list[tuple[int, float]]) -> str:
    """The per-shape table and a summary line per setting."""
    names = [f"{k} anchors, {tol:g} spacings" for k, tol in settings]
    out = [
        "| shape | before: within 0.05 / 0.10 / mean error | " + " | ".join(names) + " | moved (first setting) |",
        "|---|---|" + "---|" * len(settings) + "---|",
    ]
    for r in rows:
        cells = [f"{r[s][0]:.3f} / {r[s][1]:.3f} / {r[s][2]:.4f}" for s in settings]
        b = r["before"]
        head = f"| {r['shape']} | {b[0]:.3f} / {b[1]:.3f} / {b[2]:.4f} | "
        out.append(head + " | ".join(cells) + f" | {r['moved']:.2f} |")
    out.append("")
    before = np.array([r["before"] for r in rows])
    for s, name in zip(settings, names, strict=True):
        after = np.array([r[s] for r in rows])
        change = after - before
        worst = int(np.argmin(change[:, 0]))
        out.append(
            f"- {name}: mean within 0.05 {before[:, 0].mean():.3f} -> {after[:, 0].mean():.3f}, within 0.10 "
            f"{before[:, 1].mean():.3f} -> {after[:, 1].mean():.3f}, mean error {before[:, 2].mean():.4f} -> "
            f"{after[:, 2].mean():.4f}; shapes within 0.05 >= 0.90: {(before[:, 0] >= 0.9).sum()} -> "
            f"{(after[:, 0] >= 0.9).sum()}, within 0.10 >= 0.97: {(before[:, 1] >= 0.97).sum()} -> "
            f"{(after[:, 1] >= 0.97).sum()}; largest loss within 0.05 {change[worst, 0]:+.3f} "
            f"({rows[worst]['shape']}), within 0.10 {change[:, 1].min():+.3f}"
        )
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(parser)
    parser.add_argument("--saved", type=Path, required=True, help="detect results without the refinement")
    parser.add_argument("--shapes", nargs="+", metavar="NAME", help="shape or class names (default: all)")
    parser.add_argument("--anchors", nargs="+", type=int, default=[20, 15, 30])
    parser.add_argument("--tolerances", nargs="+", type=float, default=[2.0, 1.5, 3.0])
    parser.add_argument("--exact-anchors", action="store_true", help="anchor the samples at their true images")
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    if data is None:
        print(no_data("refine.py", args.data))
        return 0
    chosen = select(cases(data), args.shapes)
    first = (args.anchors[0], args.tolerances[0])
    settings = [first] + [(k, first[1]) for k in args.anchors[1:]] + [(first[0], t) for t in args.tolerances[1:]]
    rows = [r for r in (measure(c, args.saved, settings, args.exact_anchors) for c in chosen) if r is not None]
    print(markdown(rows, settings))
    return 0


if __name__ == "__main__":
    sys.exit(main())
