"""Command line: a thin layer over :mod:`intrinsym.pipeline` and :mod:`intrinsym.evaluate`."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from . import __version__, evaluate, example_path, mesh, pipeline

D = pipeline.Params()

# (flag, Params field, type, help); defaults come from Params and the preset.
MODEL_OPTIONS = [
    ("--source", "n_source", int, f"number of source samples |Ps| (default {D.n_source}; paper Table 1: 111-479)"),
    ("--target", "n_target", int, f"number of target samples |Pt| (default {D.n_target}; paper: 6000-12722)"),
    ("--source-spacing", "source_spacing", float, "Poisson-disc radius of Ps in units of sqrt(area), instead of --source"),
    ("--target-spacing", "target_spacing", float, "Poisson-disc radius of Pt in units of sqrt(area), instead of --target"),
    ("--spin-bins", "spin_bins", int, f"spin image size in bins per side (default {D.spin_bins})"),
    ("--spin-radius", "spin_radius", float, f"spin image support radius in units of sqrt(area) (default {D.spin_radius})"),
    ("--spin-levels", "spin_levels", int, f"intensity levels for the NMI entropies, Eq. 2-4 (default {D.spin_levels})"),
    ("--spin-cloud", "spin_cloud", int, f"dense surface points the spin images are built from (default {D.spin_cloud})"),
    ("--gamma", "gamma", float, f"unary robustness gamma of Eq. 5 (default and paper: {D.gamma})"),
    ("--rho", "rho", float, f"pairwise truncation rho of Eq. 6 (default and paper: {D.rho})"),
    ("--tolerance", "tolerance", float, f"pairwise ring half-width delta in target spacings; sets lambda (default {D.tolerance})"),
    ("--lambda", "lam", float, "raw lambda of Eq. 6 in 1/(input length unit)^2; overrides --tolerance (paper: 1e6 in its units)"),
    ("--schedule", "schedule", str, f"BP message schedule: serial (paper) or flooding (default {D.schedule})"),
    ("--iterations", "iterations", int, f"maximum BP iterations T (default and paper: {D.iterations})"),
    ("--bp-tol", "bp_tol", float, f"stop BP when the largest message change is below this (default {D.bp_tol})"),
    ("--damping", "damping", float, f"message damping in [0, 1) (default {D.damping})"),
    ("--trivial-radius", "trivial_radius", float, f"radius of the removed trivial match, units of sqrt(area) (default {D.trivial_radius})"),
    ("--seed", "seed", int, f"random seed of sampling and BP orders (default {D.seed})"),
    ("--dtype", "dtype", str, f"message storage float32 or float64 (default {D.dtype})"),
]


def _add_model_options(p: argparse.ArgumentParser, self_match: bool) -> None:
    p.add_argument("-o", "--out", required=True, help="output directory (result.npz, run.json)")
    p.add_argument("--preset", choices=sorted(pipeline.PRESETS), default="default",
                   help="parameter preset; 'paper' sets rho 0.4, gamma 0.01, serial schedule, 100 iterations "
                        "and keeps the trivial match (default: default)")
    for flag, dest, typ, text in MODEL_OPTIONS:
        if dest == "trivial_radius" and not self_match:
            continue
        p.add_argument(flag, dest=dest, type=typ, default=None, help=text)
    if self_match:
        g = p.add_mutually_exclusive_group()
        g.add_argument("--remove-trivial", dest="remove_trivial", action="store_true", default=None,
                       help="put the unary at its floor near each source point (default, except with --preset paper)")
        g.add_argument("--keep-trivial", dest="remove_trivial", action="store_false",
                       help="keep the trivial (identity) match in the model, as the paper does")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    p.add_argument("--json", action="store_true", help="print the run summary as JSON")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="intrinsym",
        description="Partial intrinsic symmetries of 3D shapes: marginals of a correspondence MRF by loopy BP.",
    )
    parser.add_argument("--version", action="version", version=f"intrinsym {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    d = sub.add_parser("detect", help="match a shape to itself",
                       description="Marginals of where every source sample of MESH may map on MESH itself.")
    d.add_argument("mesh", nargs="?", help="mesh (.off .obj .ply .stl) or point cloud (.ply .xyz .npy)")
    d.add_argument("--example", action="store_true", help="use the shipped example mesh (spot, public domain)")
    _add_model_options(d, self_match=True)

    m = sub.add_parser("match", help="match shape A to shape B",
                       description="Marginals of where every source sample of A may map on B (two-shape mode).")
    m.add_argument("a", help="source shape")
    m.add_argument("b", help="target shape")
    _add_model_options(m, self_match=False)

    e = sub.add_parser("evaluate", help="score a saved result against a symmetry map",
                       description="Marginal scores (mirror hit, peak recall, decoy recall, breadth) of OUT.")
    e.add_argument("out", help="directory written by detect")
    e.add_argument("--symmetry-map", required=True, help="ground truth: TOSCA .sym, KIDS sym.txt or 0-based .npy")
    e.add_argument("--mesh", help="the mesh the result was computed on (default: the input named in run.json)")
    e.add_argument("--seed", type=int, default=0, help="seed of the decoy choice (default 0)")
    e.add_argument("--json", action="store_true", help="print the scores as JSON")
    return parser


def _overrides(args: argparse.Namespace) -> dict:
    names = [dest for _, dest, _, _ in MODEL_OPTIONS] + ["remove_trivial"]
    return {n: getattr(args, n) for n in names if getattr(args, n, None) is not None}


def _summary(result: pipeline.Result, out: Path) -> dict:
    info = result.info
    return {
        "out": str(out),
        "mode": info["mode"],
        "sizes": info["sizes"],
        "seconds": {k: round(v, 3) for k, v in info["seconds"].items()},
        "bp": {k: info["bp"][k] for k in ("iterations", "converged", "max_change")},
        "files": ["result.npz", "run.json"],
    }


def _print_summary(s: dict) -> None:
    z = s["sizes"]
    print(f"{s['mode']}: |Ps| = {z['source']}, |Pt| = {z['target']}, {z['edges']} edges (max degree {z['max_degree']})")
    print("seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in s["seconds"].items()))
    b = s["bp"]
    state = "converged" if b["converged"] else "not converged"
    print(f"bp: {b['iterations']} iterations, {state}, max message change {b['max_change']:.2e}")
    print(f"wrote {s['out']}/result.npz and run.json")


def _run(args: argparse.Namespace) -> int:
    if args.command in ("detect", "match"):
        log = None if args.quiet or args.json else (lambda line: print(line, file=sys.stderr))
        params = _overrides(args)
        if args.command == "detect":
            if args.example == (args.mesh is not None):
                raise pipeline.ParameterError("detect needs exactly one of MESH or --example")
            if args.example:
                args.mesh = example_path()
            result = pipeline.detect(args.mesh, preset=args.preset, log=log, **params)
        else:
            result = pipeline.match(args.a, args.b, preset=args.preset, log=log, **params)
        out = result.save(args.out)
        summary = _summary(result, out)
        if args.json:
            print(json.dumps(summary, indent=2))
        elif not args.quiet:
            _print_summary(summary)
        return 0

    out = Path(args.out)
    if not (out / "result.npz").is_file() or not (out / "run.json").is_file():
        raise mesh.InputError(f"{out}: not a result directory (result.npz and run.json missing)")
    result = pipeline.Result.load(out)
    shape = mesh.load(args.mesh or result.info["input"])
    sym = evaluate.load_symmetry_map(args.symmetry_map, len(shape.vertices))
    scores = evaluate.score_marginals(
        result.marginals, result.source_vertex, result.target_vertex, shape, sym, seed=args.seed
    )
    evaluate.save_scores(scores, out / "scores.json")
    if args.json:
        print(json.dumps(scores.as_dict(), indent=2))
    else:
        print(f"mirror hit {scores.mirror_hit:.3f}  peak recall {scores.peak_recall:.3f}  "
              f"decoy recall {scores.decoy_recall:.3f}  breadth {scores.breadth:.4f}  "
              f"({scores.n_scored} source points scored)")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``intrinsym`` command; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        return _run(args)
    except (mesh.InputError, pipeline.ParameterError) as err:
        print(f"intrinsym: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("intrinsym: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
