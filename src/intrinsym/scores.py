"""Score table: the marginal scores of the unary alone and after BP, per configuration.

Regenerates the table of issue 3 on shapes with a ground-truth symmetry map (TOSCA
layout: ``<dir>/<class><pose>.off`` with ``<dir>/<class>.sym``)::

    python -m intrinsym.scores --data ../shared/data/tosca_sym --config paper \\
        --config wks --config "wks*spin" -o scores.md

A configuration is a preset name ("paper", "default") or a unary name (``Params.unary``,
e.g. "wks*spin", on the default preset). "unary" scores the row-normalised unary,
i.e. the marginals of the same model without edges; "bp" scores the BP marginals.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from . import evaluate, mesh, pipeline
from .files import atomic_write

#: The posed TOSCA shapes of issue 3.
SHAPES = ("cat1", "dog1", "horse5", "michael1", "victoria1", "centaur1", "wolf1")
SCORES = ("mirror_hit", "peak_recall", "decoy_recall", "breadth")


def config_params(config: str) -> tuple[str, dict]:
    """(preset, overrides) of a configuration name: a preset, else a unary name."""
    if config in pipeline.PRESETS:
        return config, {}
    return "default", {"unary": config}


def score_shape(mesh_path: Path, sym_path: Path, config: str, seed: int = 0,
                log: Callable[[str], None] | None = None, **params) -> dict:
    """Run ``detect`` on one shape and score its unary and its BP marginals.

    Returns
    -------
    dict with "shape", "config", "unary" and "bp" (each a dict of the four scores and
    ``n_scored``), "iterations" (BP) and "seconds" (per stage).
    """
    preset, overrides = config_params(config)
    result = pipeline.detect(mesh_path, preset=preset, log=log, seed=seed, **{**overrides, **params})
    shape = mesh.load(mesh_path)
    sym = evaluate.load_symmetry_map(sym_path, len(shape.vertices))
    row = {"shape": mesh_path.stem, "config": config}
    for column, marginals in (("unary", result.unary), ("bp", result.marginals)):
        scores = evaluate.score_marginals(marginals, result.source_vertex, result.target_vertex, shape, sym, seed=seed)
        row[column] = scores.as_dict()
    row["iterations"] = result.info["bp"]["iterations"]
    row["seconds"] = {k: round(v, 2) for k, v in result.info["seconds"].items()}
    return row


def markdown(rows: list[dict]) -> str:
    """The rows as a Markdown table: shape x configuration x {unary, bp} scores."""
    head = ["shape", "config"] + [f"{c} {s}" for s in SCORES for c in ("unary", "bp")] + ["BP iterations"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["shape"], f"`{r['config']}`"]
        cells += [f"{r[c][s]:.3f}" for s in SCORES for c in ("unary", "bp")]
        cells.append(str(r["iterations"]))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _sym_path(data: Path, shape: str) -> Path:
    return data / (re.sub(r"\d+$", "", shape) + ".sym")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m intrinsym.scores``; returns the exit code."""
    parser = argparse.ArgumentParser(prog="python -m intrinsym.scores", description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, help="folder with <class><pose>.off meshes and <class>.sym maps")
    parser.add_argument("--shapes", default=",".join(SHAPES), help=f"comma-separated shapes (default {','.join(SHAPES)})")
    parser.add_argument("--config", action="append", help="preset or unary name; repeat (default: paper and default)")
    parser.add_argument("--source", type=int, help="|Ps| (default: the configuration's)")
    parser.add_argument("--target", type=int, help="|Pt| (default: the configuration's)")
    parser.add_argument("--iterations", type=int, help="maximum BP iterations (default: the configuration's)")
    parser.add_argument("--seed", type=int, default=0, help="seed of sampling, BP order and decoys (default 0)")
    parser.add_argument("-o", "--out", help="write the table here (.md) and the rows beside it (.json)")
    args = parser.parse_args(argv)
    params = {k: v for k, v in (("n_source", args.source), ("n_target", args.target),
                                ("iterations", args.iterations)) if v is not None}
    data = Path(args.data)
    rows = []
    try:
        for shape in args.shapes.split(","):
            for config in args.config or ["paper", "default"]:
                row = score_shape(data / f"{shape}.off", _sym_path(data, shape), config, args.seed, **params)
                print(json.dumps(row), file=sys.stderr)
                rows.append(row)
    except (mesh.InputError, pipeline.ParameterError) as err:
        print(f"intrinsym.scores: error: {err}", file=sys.stderr)
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
