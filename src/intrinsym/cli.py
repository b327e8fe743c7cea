"""Command line: a thin layer over :mod:`intrinsym.pipeline` and :mod:`intrinsym.evaluate`."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

from . import __version__, bench, evaluate, example_path, extract, mesh, pipeline, shapes, viewer, viz

D = pipeline.Params()


def _weight(text: str) -> float | str:
    """--trivial-weight: 'auto' or a number (its range is checked by Params)."""
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or a number, got {text!r}") from None


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
    ("--schedule", "schedule", str, f"BP message schedule: colour (serial, independent updates batched), serial (paper), residual (colour, a node sends only while its inputs change) or flooding (default {D.schedule})"),
    ("--iterations", "iterations", int, f"maximum BP iterations T (default and paper: {D.iterations})"),
    ("--bp-tol", "bp_tol", float, f"stop BP when the largest message change is below this (default {D.bp_tol})"),
    ("--damping", "damping", float, f"message damping in [0, 1) (default {D.damping})"),
    ("--backend", "backend", str, f"where BP runs: auto (GPU if CuPy sees one, unless --schedule residual or --dtype float64), cpu or gpu (default {D.backend})"),
    ("--trivial-radius", "trivial_radius", float, f"radius of the trivial match, units of sqrt(area) (default {D.trivial_radius})"),
    ("--trivial-weight", "trivial_weight", _weight,
     "the trivial match's largest unary as a fraction of the row's largest elsewhere, in [0, 1); 0 removes it, "
     "0.7 keeps it as the answer 'no partner' on shapes whose symmetries are only partial; auto: 0, unless BP's "
     f"argmax keeps fewer than --isometry-threshold of the source edges, then {pipeline.NO_PARTNER_WEIGHT} "
     f"(default {D.trivial_weight})"),
    ("--isometry-threshold", "isometry_threshold", float,
     "share of source edges whose length BP's argmax keeps within --d-error or one target spacing below which "
     f"--trivial-weight auto keeps the identity (default {D.isometry_threshold})"),
    ("--passes", "passes", int, "BP passes; each further pass removes the earlier passes' argmax from the unary "
                                "and finds another mode (default: 1 for detect, 2 for match)"),
    ("--pass-radius", "pass_radius", float, f"radius about each argmax that a further pass removes, units of "
                                            f"sqrt(area) (default {D.pass_radius})"),
    ("--seed", "seed", int, f"random seed of sampling and BP orders (default {D.seed})"),
    ("--dtype", "dtype", str, f"message storage float32 or float64 (default {D.dtype})"),
    ("--unary", "unary", str, f"unary descriptor terms {'/'.join(pipeline.UNARY_TERMS)} joined by '*' "
                              f"(default {D.unary}; paper: spin)"),
    ("--potential", "potential", str, f"similarity-to-potential map: calibrated or paper (Eq. 5; spin only) "
                                      f"(default {D.potential})"),
    ("--eigenpairs", "eigenpairs", int, f"Laplace-Beltrami eigenpairs of wks/hks (default {D.eigenpairs})"),
    ("--energies", "energies", int, f"WKS energies / HKS times (default {D.energies})"),
    ("--calibration", "calibration", str, f"how each calibrated width is measured: offset (descriptor distance to "
                                          f"the targets nearest a point on the surface), descriptor (to the "
                                          f"--calibration-k nearest targets in descriptor space), both (the larger) or local "
                                          f"(both, raised per source sample to its own offset spread) "
                                          f"(default {D.calibration})"),
    ("--calibration-k", "calibration_k", int, f"nearest targets in descriptor space of the descriptor rule "
                                              f"(default {D.calibration_k})"),
    ("--unary-floor", "unary_floor", float, f"smallest calibrated unary potential (default {D.unary_floor})"),
    ("--peak-threshold", "peak_threshold", float,
     f"extraction: peak threshold t on the max-normalised marginal (default {D.peak_threshold}; paper 0.5-0.75)"),
    ("--d-error", "d_error", float,
     f"extraction: geodesic error bound of the region growing, units of sqrt(area) (default {D.d_error}; "
     "paper 0.001-0.15)"),
    ("--vertex-fit", "vertex_fit", float,
     f"extraction: largest relative residual of the local linear fits that extend the global map to every "
     f"input vertex; 0 gives each vertex its sample's image (default {D.vertex_fit}, off; 0.5 measured on the generated figure)"),
]


def _add_model_options(p: argparse.ArgumentParser, self_match: bool) -> None:
    p.add_argument("-o", "--out", required=True, help="output directory (result.npz, run.json)")
    p.add_argument("--preset", choices=sorted(pipeline.PRESETS), default="default",
                   help="parameter preset; 'paper' sets rho 0.4, gamma 0.01, serial schedule, 100 iterations "
                        "and keeps the trivial match (default: default)")
    for flag, dest, typ, text in MODEL_OPTIONS:
        if dest in ("trivial_radius", "trivial_weight", "isometry_threshold") and not self_match:
            continue
        p.add_argument(flag, dest=dest, type=typ, default=None, help=text)
    if self_match:
        g = p.add_mutually_exclusive_group()
        g.add_argument("--remove-trivial", dest="remove_trivial", action="store_true", default=None,
                       help="weaken the trivial match to --trivial-weight (default, except with --preset paper)")
        g.add_argument("--keep-trivial", dest="remove_trivial", action="store_false",
                       help="keep the trivial (identity) match in the model, as the paper does")
        p.add_argument("--report-identity", dest="report_identity", action="store_true", default=None,
                       help="extraction: also list the identity symmetries (kind 'identity') in symmetries.json; "
                            "they arise where the trivial match stays in the model (--keep-trivial)")
    p.add_argument("--unary-seeds", dest="unary_seeds", action=argparse.BooleanOptionalAction, default=None,
                   help="extraction: also grow symmetries from the unary's peaks (default on; off with --preset paper)")
    if self_match:
        p.add_argument("--zoomout", dest="zoomout", action=argparse.BooleanOptionalAction, default=None,
                       help="global map (symmetry_map.npy): the global symmetry's sample pairs refined by ZoomOut "
                            "in the Laplace-Beltrami eigenfunctions (default on; off with --preset paper)")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    p.add_argument("--json", action="store_true", help="print the run summary as JSON")
    p.add_argument("--figures", action="store_true", help="also write the PNGs of 'intrinsym render' to OUT/figures")
    p.add_argument("--up", choices=sorted(viz.UP_FRAMES), default="y",
                   help="figures: world axis drawn upwards (default y; TOSCA and KIDS are z-up)")


def _add_output_commands(sub: argparse._SubParsersAction) -> None:
    r = sub.add_parser("render", help="write the figures of a saved result",
                       description="PNGs of OUT in OUT/figures: the marginal of one source sample (Eq. 9), the "
                                   "samples with the source graph (Fig. 1) and each extracted symmetry.")
    r.add_argument("out", help="directory written by detect or match")
    r.add_argument("--source-sample", type=int, help="source sample of the marginal figure "
                                                     "(default: the one whose marginal best shows a symmetry)")
    r.add_argument("--symmetries", type=int, default=6, help="figures for at most this many symmetries (default 6)")
    r.add_argument("--dpi", type=int, default=viz.FigureParams.dpi,
                   help=f"resolution of the PNGs (default {viz.FigureParams.dpi})")
    v = sub.add_parser("view", help="write an interactive HTML viewer of a saved result",
                       description="One self-contained HTML file (no network needed): rotate, zoom, click the "
                                   "surface to see its marginal, toggle the extracted symmetries.")
    v.add_argument("out", help="directory written by detect or match")
    v.add_argument("-o", "--html", help="output file (default: OUT/viewer.html)")
    for q in (r, v):
        q.add_argument("--mesh", help="the (target) mesh of the result (default: the input named in run.json)")
        q.add_argument("--up", choices=sorted(viz.UP_FRAMES), default="y",
                       help="world axis drawn upwards (default y; TOSCA and KIDS are z-up)")
        q.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")


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

    _add_output_commands(sub)

    e = sub.add_parser("evaluate", help="score a saved result against a symmetry map",
                       description="Marginal scores (mirror hit, peak recall, decoy recall, breadth) of OUT.")
    e.add_argument("out", help="directory written by detect")
    e.add_argument("--symmetry-map", required=True,
                   help="ground truth: TOSCA .sym, KIDS sym.txt or 0-based .npy (-1: no image, as in a partial "
                        "symmetry; such vertices are not scored)")
    e.add_argument("--mesh", help="the mesh the result was computed on (default: the input named in run.json)")
    e.add_argument("--seed", type=int, default=0, help="seed of the decoy choice (default 0)")
    e.add_argument("--labels", help="part labels, one integer per vertex (.npy or text; 0 = no part): "
                                    "adds the paper's segmentation score per part")
    e.add_argument("--json", action="store_true", help="print the scores as JSON")

    q = sub.add_parser("query", help="what is symmetric to one vertex of a saved result",
                       description="Peak tracking and region growing (paper Sec. 5.1) from the source sample "
                                   "whose cell holds input vertex V, from OUT/result.npz without rerunning BP.")
    q.add_argument("out", help="directory written by detect or match")
    q.add_argument("--vertex", type=int, required=True, help="0-based vertex of the (source) input mesh")
    q.add_argument("--peak-threshold", type=float, default=None, help="peak threshold t (default: as in run.json)")
    q.add_argument("--d-error", type=float, default=None, help="geodesic error bound (default: as in run.json)")
    q.add_argument("--json", action="store_true", help="print the symmetric parts as JSON")

    g = sub.add_parser("generate", help="write a shape with exactly known symmetry",
                       description="Write a generated shape as OFF with its ground truth beside it: STEM.sym.npy "
                                   "(principal symmetry map), STEM.maps.npy (all maps), STEM.labels.npy (parts). "
                                   "lantern writes two frames, FILE and STEM_b.off.")
    g.add_argument("name", choices=shapes.NAMES, help="which shape")
    g.add_argument("-o", "--out", required=True, help="mesh file to write (.off)")
    g.add_argument("--arms", type=int, default=None, help="star: number of arms (default 5)")
    g.add_argument("--resolution", type=int, default=None,
                   help="star, lantern, figure, partial: grid cells per arm / per 45 degrees "
                        "(default 12, 12, 10, 16)")
    g.add_argument("--subdivisions", type=int, default=None, help="cuboctahedron: 1-to-4 subdivisions (default 3)")

    b = sub.add_parser("bench", help="time the pipeline on the paper's Table 1 cases",
                       description="Seconds per stage, BP per iteration and to convergence, peak memory and the "
                                   "dense paper-style message time over ours, per case.")
    b.add_argument("meshes", nargs="*", help="extra meshes to benchmark at --source/--target")
    b.add_argument("--cases", default=None,
                   help="comma-separated Table 1 cases (default: all; 'none' for only MESHES): "
                        + ", ".join(c.name for c in bench.TABLE1))
    b.add_argument("--small", action="store_true", help="one tiny case (a smoke test, seconds)")
    b.add_argument("--source", type=int, default=271, help="|Ps| of the extra meshes (default 271)")
    b.add_argument("--target", type=int, default=12722, help="|Pt| of the extra meshes (default 12722)")
    b.add_argument("--iterations", type=int, default=100, help="maximum BP iterations (default and paper: 100)")
    b.add_argument("--data", default=None, help="folder of the cases' meshes (default: $INTRINSYM_DATA or ../shared/data)")
    b.add_argument("--json", action="store_true", help="print the results as JSON")
    return parser


def _overrides(args: argparse.Namespace) -> dict:
    names = [dest for _, dest, _, _ in MODEL_OPTIONS] + ["remove_trivial", "report_identity", "unary_seeds", "zoomout"]
    return {n: getattr(args, n) for n in names if getattr(args, n, None) is not None}


def _summary(result: pipeline.Result, out: Path) -> dict:
    info = result.info
    return {
        "out": str(out),
        "mode": info["mode"],
        "sizes": info["sizes"],
        "seconds": {k: round(v, 3) for k, v in info["seconds"].items()},
        "bp": {k: info["bp"][k] for k in ("backend", "iterations", "converged", "max_change")},
        "files": ["result.npz", "run.json"] + (["symmetries.json", "symmetry_map.npy"] if result.extraction else []),
    }


def _print_summary(s: dict) -> None:
    z = s["sizes"]
    print(f"{s['mode']}: |Ps| = {z['source']}, |Pt| = {z['target']}, {z['edges']} edges (max degree {z['max_degree']})")
    print("seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in s["seconds"].items()))
    b = s["bp"]
    state = "converged" if b["converged"] else "not converged"
    print(f"bp: {b['iterations']} iterations on the {b['backend'].upper()}, {state}, "
          f"max message change {b['max_change']:.2e}")
    if "symmetries" in s:
        print(f"symmetries: {s['symmetries']} found (symmetries.json)")
    print(f"wrote {', '.join(s['files'])} to {s['out']}")
    if s.get("figures"):
        print(f"figures: {', '.join(s['figures'])} in {s['out']}/figures")


BP_LINE = "bp iteration"
"""Prefix of the pipeline's per-iteration log lines (a transient progress line here)."""


class _Progress:
    """Stage progress on a terminal: finished stages stay as lines, a spinner shows the rest."""

    def __init__(self, iterations: int, console: Console | None = None) -> None:
        self.bar = Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                            console=console or Console(stderr=True), transient=True)
        self.task = self.bar.add_task("loading", total=None)
        self.iterations = iterations

    def __call__(self, line: str) -> None:
        if line.startswith(BP_LINE):
            self.bar.update(self.task, description=f"{line} (at most {self.iterations})")
        else:
            self.bar.console.print(f"[green]done[/] {line}", highlight=False)
            self.bar.update(self.task, description="running the next stage")

    def __enter__(self) -> _Progress:
        self.bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.stop()


def _result_dir(path: str) -> Path:
    """A directory written by ``Result.save``, or a one-line input error."""
    out = Path(path)
    if not (out / "result.npz").is_file() or not (out / "run.json").is_file():
        raise mesh.InputError(f"{out}: not a result directory (result.npz and run.json missing)")
    return out


def _render_or_view(args: argparse.Namespace) -> int:
    out = _result_dir(args.out)
    if args.command == "render":
        paths = viz.render(out, args.source_sample, viz.FigureParams(up=args.up, dpi=args.dpi), args.mesh,
                           max_symmetries=args.symmetries)
    else:
        paths = [viewer.write(out, args.html, args.mesh, args.up)]
    if not args.quiet:
        for path in paths:
            print(f"wrote {path}")
    return 0


def _generate(args: argparse.Namespace) -> int:
    """Write a generated shape (two frames for the lantern) and its ground truth."""
    options = {k: getattr(args, k) for k in ("arms", "resolution", "subdivisions") if getattr(args, k) is not None}
    try:
        made = shapes.generate(args.name, **options)
        out = Path(args.out)
        frames = [(made[0], out), (made[1], out.with_name(f"{out.stem}_b{out.suffix}"))] if isinstance(
            made, tuple) else [(made, out)]
        written = [f for frame, path in frames for f in shapes.save(frame, path)]
    except (TypeError, ValueError) as err:
        raise pipeline.ParameterError(str(err).splitlines()[0]) from None
    except OSError as err:
        raise mesh.InputError(f"{args.out}: cannot write ({err.strerror})") from None
    print("wrote " + ", ".join(map(str, written)))
    return 0


def _bench(args: argparse.Namespace) -> int:
    for path in args.meshes:
        if not Path(path).is_file():
            raise mesh.InputError(f"{path}: no such file")
    if args.small:
        cases = list(bench.SMALL)
    elif args.cases in (None, "all"):
        cases = list(bench.TABLE1) if not args.meshes or args.cases else []
    else:
        names = {c.name: c for c in bench.TABLE1}
        wanted = [n.strip() for n in args.cases.split(",") if n.strip() and n.strip() != "none"]
        unknown = [n for n in wanted if n not in names]
        if unknown:
            raise pipeline.ParameterError(f"unknown bench case(s): {', '.join(unknown)}")
        cases = [names[n] for n in wanted]
    cases += [bench.Case(Path(p).stem, str(Path(p).resolve()), args.source, args.target) for p in args.meshes]
    data = Path(args.data) if args.data else bench.default_data_dir()
    console = Console(stderr=True, quiet=args.json or not sys.stderr.isatty())
    with console.status("bench") as status:
        results = bench.run(cases, data, args.iterations,
                            log=lambda name, line: status.update(f"[bold]{name}[/bold]: {line}"))
    if args.json:
        print(json.dumps([dataclasses.asdict(r) for r in results], indent=2))
        return 0
    table = Table(title="intrinsym bench (seconds; paper: 100 iterations, GTX280 / 2.66 GHz CPU)")
    rows = bench.table(results)
    for col in rows[0]:
        table.add_column(col, justify="right")
    for row in rows[1:]:
        table.add_row(*row)
    Console().print(table)
    return 0


def _run(args: argparse.Namespace) -> int:
    if args.command == "bench":
        return _bench(args)
    if args.command == "generate":
        return _generate(args)
    if args.command in ("render", "view"):
        return _render_or_view(args)
    if args.command in ("detect", "match"):
        params = _overrides(args)
        show = not (args.quiet or args.json) and sys.stderr.isatty()
        progress = _Progress(pipeline.make_params(args.preset, **params).iterations) if show else None
        if args.command == "detect" and args.example == (args.mesh is not None):
            raise pipeline.ParameterError("detect needs exactly one of MESH or --example")
        with progress or contextlib.nullcontext():
            if args.command == "detect":
                result = pipeline.detect(args.mesh or example_path(), preset=args.preset, log=progress, **params)
            else:
                result = pipeline.match(args.a, args.b, preset=args.preset, log=progress, **params)
            out = result.save(args.out)
            figures = viz.render(out, params=viz.FigureParams(up=args.up)) if args.figures else []
        summary = _summary(result, out)
        summary["symmetries"] = len(viz.load_symmetries(out))
        summary["figures"] = [path.name for path in figures]
        if args.json:
            print(json.dumps(summary, indent=2))
        elif not args.quiet:
            _print_summary(summary)
        return 0

    out = _result_dir(args.out)
    result = pipeline.Result.load(out)
    if args.command == "query":
        return _query(args, result, out)
    shape = mesh.load(args.mesh or result.info["input"])
    sym = evaluate.load_symmetry_map(args.symmetry_map, len(shape.vertices), allow_missing=True)
    scores = evaluate.score_marginals(
        result.marginals, result.source_vertex, result.target_vertex, shape, sym, seed=args.seed
    )
    report = scores.as_dict()
    if (out / "symmetry_map.npy").is_file():
        maps = _map_scores(args, out, shape, sym)
        report["map"] = maps.as_dict()
        evaluate.plot_curve(maps, out / "curve.png")
    elif args.labels:
        raise mesh.InputError(f"{out}: no symmetry_map.npy to segment (rerun intrinsym detect)")
    evaluate.save_scores(report, out / "scores.json")
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(f"mirror hit {scores.mirror_hit:.3f}  peak recall {scores.peak_recall:.3f}  "
              f"decoy recall {scores.decoy_recall:.3f}  breadth {scores.breadth:.4f}  "
              f"({scores.n_scored} source points scored)")
        if "map" in report:
            m = report["map"]
            print(f"global map: within 0.05 {m['within_0.05']:.3f}  within 0.10 {m['within_0.10']:.3f}  "
                  f"mean error {m['mean_error']:.4f}  coverage {m['coverage']:.3f}  (curve.png)")
            for label, value in m["segmentation"].items():
                print(f"segmentation part {label}: {100 * value:.1f}%")
    return 0


def _map_scores(args: argparse.Namespace, out: Path, shape: mesh.Shape, sym) -> evaluate.MapScores:
    """Scores of OUT/symmetry_map.npy (with --labels, per part)."""
    n = len(shape.vertices)
    predicted = evaluate.load_symmetry_map(out / "symmetry_map.npy", n, allow_missing=True)
    labels = evaluate.load_labels(args.labels, n) if args.labels else None
    return evaluate.score_map(predicted, shape, sym, labels=labels)


def _query(args: argparse.Namespace, result: pipeline.Result, out: Path) -> int:
    """Print every symmetric part pair of the source sample holding --vertex."""
    if result.support is None:
        raise mesh.InputError(f"{out}: result.npz holds no extraction data (rerun intrinsym detect)")
    cells = result.support.vertex_source
    if not 0 <= args.vertex < len(cells):
        raise pipeline.ParameterError(f"--vertex must lie in [0, {len(cells) - 1}]")
    sample = int(cells[args.vertex])
    if sample < 0:
        raise pipeline.ParameterError(f"vertex {args.vertex} lies in no source sample's cell")
    p = dataclasses.replace(result.params, **{k: v for k, v in (("peak_threshold", args.peak_threshold),
                                                                ("d_error", args.d_error)) if v is not None})
    found = extract.from_result(result.marginals, result.edges, result.support, result.source_points,
                                result.target_points, dataclasses.replace(result, params=p).extraction_params(),
                                source=sample, unary=result.unary, passes=result.passes)
    listed = extract.records(found, result.source_vertex, result.target_vertex, result.support)
    for record, sym in zip(listed, found):
        record["image_vertex"] = int(result.target_vertex[sym.target[np.searchsorted(sym.source, sample)]])
    if args.json:
        print(json.dumps({"vertex": args.vertex, "source_sample": sample, "symmetries": listed}))
        return 0
    print(f"vertex {args.vertex} (source sample {sample}): {len(listed)} symmetric part(s)")
    for r in listed:
        print(f"  {r['kind']:8s} -> vertex {r['image_vertex']:6d}  score {r['score']:.3f}  "
              f"consistency {r['consistency']:.2f}  {len(r['pairs'])} samples, "
              f"{len(r['source_vertices'])} -> {len(r['target_vertices'])} vertices")
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
