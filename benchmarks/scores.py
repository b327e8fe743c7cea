"""Score table: the marginal scores of the unary alone and after BP, per configuration.

Compares unary configurations on shapes with a ground-truth symmetry map (TOSCA
layout: ``<dir>/<class><pose>.off`` with ``<dir>/<class>.sym``)::

    python benchmarks/scores.py --data DIR --config paper \\
        --config wks --config "wks*spin" -o scores.md

The shapes are read from ``DIR/tosca_sym`` when it exists, else from ``DIR`` itself;
``DIR`` is ``--data`` or ``$INTRINSYM_DATA``. When shapes are asked for (the default
without ``--mirror``, or ``--shapes``) and there is no such folder, the script says so in
one line and exits 0.

A configuration is a preset name ("paper", "default") or a unary name (``Params.unary``,
e.g. "wks*spin", on the default preset). "unary" scores the row-normalised unary,
i.e. the marginals of the same model without edges; "bp" scores the BP marginals; "map"
the global map (``symmetry_map.npy``) within 0.05 and 0.10 of the true image.

``--mirror MESH`` (repeatable) adds shapes without a symmetry file, posed
mirror-symmetrically: their ground truth is their best reflection
(:func:`intrinsym.evaluation.evaluate.extrinsic_mirror`), and the row notes its median residual.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from _data import add_data_argument, data_folder, no_data
from intrinsym import pipeline
from intrinsym.errors import InputError, ParameterError
from intrinsym.evaluation import evaluate
from intrinsym.files import atomic_write
from intrinsym.mesh.io import load
from intrinsym.mesh.shape import surface_area
from intrinsym.params import PRESETS, make_params

#: The posed TOSCA shapes the unary configurations were compared on.
SHAPES = ("cat1", "dog1", "horse5", "michael1", "victoria1", "centaur1", "wolf1")
SCORES = ("mirror_hit", "peak_recall", "decoy_recall", "breadth")


def config_params(config: str) -> tuple[str, dict]:
    """(preset, overrides) of a configuration name: a preset, else a unary name."""
    if config in PRESETS:
        return config, {}
    return "default", {"unary": config}


def score_shape(mesh_path: Path, sym_path: Path | None, config: str, seed: int = 0, **params) -> dict:
    """Run ``detect`` on one shape and score its unary, its BP marginals and its global map.

    ``sym_path`` None: the ground truth is the shape's best reflection
    (:func:`intrinsym.evaluation.evaluate.extrinsic_mirror`).

    Returns
    -------
    dict with "shape", "config", "unary" and "bp" (each a dict of the four scores and
    ``n_scored``), "map" (within 0.05 and 0.10, mean error), "iterations" (BP),
    "seconds" (per stage) and, for a reflection, "mirror_residual" (its median, units
    of sqrt(area)).
    """
    preset, overrides = config_params(config)
    result = pipeline.detect(mesh_path, make_params(preset, seed=seed, **{**overrides, **params}))
    shape = load(mesh_path)
    row: dict = {"shape": mesh_path.stem, "config": config}
    if sym_path is None:
        sym, residual = evaluate.extrinsic_mirror(shape.vertices)
        row["mirror_residual"] = float(np.median(residual) / np.sqrt(surface_area(shape)))
    else:
        sym = evaluate.load_symmetry_map(sym_path, len(shape.vertices))
    for column, marginals in (("unary", result.unary), ("bp", result.marginals)):
        scores = evaluate.score_marginals(
            marginals, result.source_point_vertex, result.target_point_vertex, shape, sym, seed=seed
        )
        row[column] = scores.as_dict()
    found = evaluate.score_map(result.symmetry_map(), shape, sym)
    row["map"] = {"within_0.05": found.within(0.05), "within_0.10": found.within(0.10), "mean_error": found.mean_error}
    row["iterations"] = result.info.bp.iterations
    row["seconds"] = {k: round(v, 2) for k, v in result.info.seconds.items()}
    return row


def markdown(rows: list[dict]) -> str:
    """The rows as a Markdown table: shape x configuration x {unary, bp} scores."""
    head = (
        ["shape", "config"]
        + [f"{c} {s}" for s in SCORES for c in ("unary", "bp")]
        + ["BP iterations", "map within 0.05", "map within 0.10", "map mean error"]
    )
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        shape = r["shape"]
        if "mirror_residual" in r:
            shape += f" (reflection, residual {r['mirror_residual']:.4f})"
        cells = [shape, f"`{r['config']}`"]
        cells += [f"{r[c][s]:.3f}" for s in SCORES for c in ("unary", "bp")]
        cells.append(str(r["iterations"]))
        cells += [f"{r['map'][k]:.3f}" for k in ("within_0.05", "within_0.10", "mean_error")]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _sym_path(data: Path, shape: str) -> Path:
    return data / (re.sub(r"\d+$", "", shape) + ".sym")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python benchmarks/scores.py``; returns the exit code."""
    parser = argparse.ArgumentParser(prog="benchmarks/scores.py", description=__doc__.split("\n\n")[0])
    add_data_argument(
        parser, "research data folder (its tosca_sym/) or a folder of <class><pose>.off meshes with <class>.sym maps"
    )
    parser.add_argument("--shapes", help=f"comma-separated shapes (default {','.join(SHAPES)}, none with --mirror)")
    parser.add_argument(
        "--mirror",
        action="append",
        default=[],
        help="a mesh without a symmetry file, scored against its best reflection; repeat",
    )
    parser.add_argument("--config", action="append", help="preset or unary name; repeat (default: paper and default)")
    parser.add_argument("--source", type=int, help="|Ps| (default: the configuration's)")
    parser.add_argument("--target", type=int, help="|Pt| (default: the configuration's)")
    parser.add_argument("--iterations", type=int, help="maximum BP iterations (default: the configuration's)")
    parser.add_argument("--seed", type=int, default=0, help="seed of sampling, BP order and decoys (default 0)")
    parser.add_argument("-o", "--out", help="write the table here (.md) and the rows beside it (.json)")
    args = parser.parse_args(argv)
    params = {
        k: v
        for k, v in (("n_source", args.source), ("n_target", args.target), ("iterations", args.iterations))
        if v is not None
    }
    rows = []
    wanted = args.shapes if args.shapes is not None else "" if args.mirror else ",".join(SHAPES)
    shapes = [shape for shape in wanted.split(",") if shape]
    data = data_folder(args.data)
    if shapes and data is None:
        print(no_data("scores.py", args.data))
        return 0
    if data is not None and (data / "tosca_sym").is_dir():
        data = data / "tosca_sym"
    cases = [(data / f"{shape}.off", _sym_path(data, shape)) for shape in shapes]
    cases += [(Path(path), None) for path in args.mirror]
    try:
        for mesh_path, sym_path in cases:
            for config in args.config or ["paper", "default"]:
                row = score_shape(mesh_path, sym_path, config, args.seed, **params)
                print(json.dumps(row), file=sys.stderr)
                rows.append(row)
    except (InputError, ParameterError) as err:
        print(f"scores.py: error: {err}", file=sys.stderr)
        return 2
    table = markdown(rows)
    print(table, end="")
    if args.out:
        out = Path(args.out)
        atomic_write(out, lambda f: f.write(table))
        atomic_write(out.with_suffix(".json"), lambda f: json.dump(rows, f, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
