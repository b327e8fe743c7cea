"""Command line: a thin layer over :mod:`intrinsym.pipeline` and :mod:`intrinsym.evaluation.evaluate`."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import functools
import json
import os
import re
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

import numpy as np
from rich.console import Console
from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

from .. import __version__, example_path, files, params, pipeline, resources
from ..errors import InputError, IntrinsymError, ParameterError
from ..evaluation import evaluate, partial_truth, symmetry_group
from ..extract import extract
from ..extract.records import part_mask, records
from ..extras import available, require
from ..mesh import generated as shapes
from ..mesh.io import load
from ..progress import BPIteration, ProgressEvent, next_stage
from ..result.result import Result, saved_global_confidence
from . import bench, cli_extra, text_tables, viewer, viz
from .batching import command as batch_command


def _add_output_commands(sub: argparse._SubParsersAction) -> None:
    r = sub.add_parser(
        "render",
        help="write the figures of a saved result",
        description="PNGs of OUT in OUT/figures: the marginal of one source sample (Eq. 9), the "
        "samples with the source graph (Fig. 1) and each extracted symmetry.",
    )
    r.add_argument("out", help="directory written by detect or match")
    r.add_argument(
        "--source-sample",
        type=int,
        help="source sample of the marginal figure (default: the one whose marginal best shows a symmetry)",
    )
    r.add_argument("--symmetries", type=int, default=6, help="figures for at most this many symmetries (default 6)")
    r.add_argument(
        "--dpi", type=int, default=viz.FigureParams.dpi, help=f"resolution of the PNGs (default {viz.FigureParams.dpi})"
    )
    v = sub.add_parser(
        "view",
        help="write an interactive HTML viewer of a saved result",
        description="One self-contained HTML file (no network needed): rotate, zoom, click the "
        "surface to see its marginal, toggle the extracted symmetries.",
    )
    v.add_argument("out", help="directory written by detect or match")
    v.add_argument("-o", "--html", help="output file (default: OUT/viewer.html)")
    for q in (r, v):
        q.add_argument("--mesh", help="the (target) mesh of the result (default: the input named in run.json)")
        q.add_argument(
            "--up",
            choices=sorted(viz.UP_FRAMES),
            default="y",
            help="world axis drawn upwards (default y; TOSCA and KIDS are z-up)",
        )
        q.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")


def build_parser(full: bool = False) -> argparse.ArgumentParser:
    """The ``intrinsym`` parser; ``full``: every model parameter in the help (``--help-all``)."""
    parser = cli_extra.Parser(
        prog="intrinsym",
        description="Partial intrinsic symmetries of 3D shapes: marginals of a correspondence MRF by loopy BP.",
    )
    parser.add_argument("--version", action="version", version=f"intrinsym {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    d = sub.add_parser(
        "detect",
        help="match a shape to itself",
        description="Marginals of where every source sample of MESH may map on MESH itself.",
    )
    d.add_argument("mesh", nargs="?", help="mesh (.off .obj .ply .stl) or point cloud (.ply .xyz .npy)")
    d.add_argument("--example", action="store_true", help="use the shipped example mesh (spot, public domain)")
    cli_extra.add_model_options(d, True, full, "output directory (result.npz, run.json, symmetry_map.npy, ...)")

    m = sub.add_parser(
        "match",
        help="match shape A to shape B",
        description="Marginals of where every source sample of A may map on B (two-shape mode).",
    )
    m.add_argument("a", help="source shape")
    m.add_argument("b", help="target shape")
    m.add_argument(
        "--target-symmetry",
        metavar="FILE",
        help="B's own symmetry map (a detect output folder of B, its symmetry_map.npy, or a TOSCA .sym): "
        "the second answer (mode_maps.npy) is it applied after the map",
    )
    cli_extra.add_model_options(m, False, full, "output directory (result.npz, run.json)")

    _add_output_commands(sub)
    cli_extra.add_export_commands(sub)

    bt = sub.add_parser(
        "batch",
        help="detect (or match) over many meshes on Dask",
        description="detect on every mesh of INPUT... (match on pairs with --pairs) on a local Dask cluster or "
        "a running scheduler: one folder per item in OUT, OUT/summary.parquet and summary.csv; a re-run skips "
        "the items already done. Exit code 1 when an item failed.",
    )
    cli_extra.add_model_options(
        bt, True, full, "output directory: one result folder per item, summary.parquet and summary.csv"
    )
    batch_command.add_arguments(bt)

    e = sub.add_parser(
        "evaluate",
        help="score a saved result against its ground truth (one or several true maps)",
        description="Scores of OUT against the ground truth (distances in sqrt(area) units): the marginals' (mirror "
        "hit, peak recall, decoy recall, breadth), the global map's (share within 0.05 / 0.10, mean error, "
        "distortion, the confidence's calibration) and, with several true maps, each found symmetry against its "
        "nearest one; written to OUT/scores.json and OUT/curve.png.",
    )
    e.add_argument("out", help="directory written by detect")
    e.add_argument(
        "--symmetry-map",
        required=True,
        action="append",
        help="ground truth: TOSCA .sym, KIDS sym.txt, 0-based .npy (-1: no partner, -2: not scored; shape (K, V): "
        "K true maps, a symmetry group), a SHREC'16 .baryc_gt_sym (with its .baryc_gt beside it) or another detect "
        "output folder (its symmetry_map.npy: how far two runs agree); repeat for several true maps: each found "
        "symmetry is scored against its nearest one. With -1 entries, or "
        "--reference, scores.json also holds the partial-symmetry scores (docs/format.md)",
    )
    e.add_argument(
        "--reference",
        help="the complete shape whose sqrt(area) is the unit of the partial-symmetry scores: a SHREC'16 "
        "truth's null shape (default: ../null/<class>.off beside it); otherwise default the mesh itself",
    )
    e.add_argument("--mesh", help="the mesh the result was computed on (default: the input named in run.json)")
    e.add_argument("--seed", type=int, default=0, help="seed of the decoy choice (default 0)")
    e.add_argument(
        "--labels",
        help="part labels, one integer per vertex (.npy or text; 0 = no part): "
        "adds the paper's segmentation score per part",
    )
    e.add_argument("--json", action="store_true", help="print the scores as JSON")

    q = sub.add_parser(
        "query",
        help="what is symmetric to one vertex of a saved result",
        description="Peak tracking and region growing (paper Sec. 5.1) from the source sample "
        "whose cell holds input vertex V, from OUT/result.npz without rerunning BP.",
    )
    q.add_argument("out", help="directory written by detect or match")
    q.add_argument("--vertex", type=int, required=True, help="0-based vertex of the (source) input mesh")
    q.add_argument("--peak-threshold", type=float, default=None, help="peak threshold t (default: as in run.json)")
    q.add_argument("--d-error", type=float, default=None, help="geodesic error bound (default: as in run.json)")
    q.add_argument("--json", action="store_true", help="print the symmetric parts as JSON")

    g = sub.add_parser(
        "generate",
        help="write a shape with exactly known symmetry",
        description="Write a generated shape as OFF with its ground truth beside it: STEM.sym.npy "
        "(principal symmetry map), STEM.maps.npy (all maps), STEM.labels.npy (parts). "
        "lantern writes two frames, FILE and STEM_b.off.",
    )
    g.add_argument("name", choices=shapes.NAMES, help="which shape")
    g.add_argument("-o", "--out", required=True, help="mesh file to write (.off)")
    g.add_argument("--arms", type=int, default=None, help="star: number of arms (default 5)")
    g.add_argument(
        "--resolution",
        type=int,
        default=None,
        help="star, lantern, figure, partial: grid cells per arm / per 45 degrees (default 12, 12, 10, 16)",
    )
    g.add_argument("--subdivisions", type=int, default=None, help="cuboctahedron: 1-to-4 subdivisions (default 3)")

    b = sub.add_parser(
        "bench",
        help="time the pipeline on a mesh",
        description="Seconds per stage, BP per iteration and to convergence, peak memory and the "
        "dense paper-style message time over ours, per mesh. The paper's Table 1 "
        "cases are benchmarks/table1.py of the source tree.",
    )
    b.add_argument("meshes", nargs="*", help="meshes to benchmark at --source / --target")
    b.add_argument("--small", action="store_true", help="one tiny case on the shipped example (a smoke test, seconds)")
    b.add_argument("--source", type=int, default=271, help="|Ps| (default 271, the paper's elephant)")
    b.add_argument("--target", type=int, default=12722, help="|Pt| (default 12722, the paper's elephant)")
    b.add_argument("--iterations", type=int, default=100, help="maximum BP iterations (default and paper: 100)")
    b.add_argument("--json", action="store_true", help="print the results as JSON")
    b.add_argument(
        "--profile",
        action="store_true",
        help="where the time goes: seconds per stage, per BP iteration and per descriptor step, in this process",
    )
    return parser


def _params(args: argparse.Namespace) -> params.Params:
    """The run's parameters; an invalid value is reported by its flag (``--source``, not ``n_source``)."""
    try:
        return params.make_params(args.preset, **_overrides(args))
    except ParameterError as err:
        text = str(err)
        for f in params.describe():
            text = re.sub(rf"(?<![-\w]){f.name}(?!\w)", f.flag, text)
        raise ParameterError(text) from None


def _overrides(args: argparse.Namespace) -> dict:
    return {f.name: getattr(args, f.name) for f in params.describe() if getattr(args, f.name, None) is not None}


def _summary(result: Result, out: Path) -> dict:
    info = result.info
    return {
        "out": str(out),
        "mode": info.mode,
        "sizes": dataclasses.asdict(info.sizes),
        "seconds": {k: round(v, 3) for k, v in info.seconds.items()},
        "bp": {k: getattr(info.bp, k) for k in ("backend", "iterations", "converged", "max_change")},
        "files": [f for f in Result.FILES if (out / f).is_file()],
        "global_confidence": saved_global_confidence(out, result.global_symmetry is not None),
        "identity": None if info.identity is None else dataclasses.asdict(info.identity),
        "self_map": None if info.self_map is None else dataclasses.asdict(info.self_map),
        "modes": _modes_summary(result, out),
    }


def _modes_summary(result: Result, out: Path) -> dict | None:
    """A match's ``modes.json`` and where its second answer came from (None without it)."""
    path = out / "modes.json"
    if not path.is_file():
        return None
    second = "target_symmetry" if result.target_symmetry is not None else "marginals"
    return {**json.loads(path.read_text()), "second_from": second}


def _print_summary(s: dict) -> None:
    z = s["sizes"]
    print(f"{s['mode']}: |Ps| = {z['source']}, |Pt| = {z['target']}, {z['edges']} edges (max degree {z['max_degree']})")
    print("seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in s["seconds"].items()))
    b = s["bp"]
    state = "converged" if b["converged"] else "not converged"
    print(
        f"bp: {b['iterations']} iterations on the {b['backend'].upper()}, {state}, "
        f"max message change {b['max_change']:.2e}"
    )
    if "symmetries" in s:
        print(f"symmetries: {s['symmetries']} found (symmetries.json)")
    if (i := s.get("identity") or {}).get("wider_radius") is not None:
        second = "none" if i["wider_distortion"] is None else f"{i['wider_distortion']:.4f}"
        print(
            f"global symmetry by the reflection test alone: BP again at trivial radius {i['wider_radius']:.3g}, "
            f"{'its' if i['wider_kept'] else 'the first'} map kept (mean local distortion {second}, first "
            f"{i['distortion']:.4f})"
        )
    if (sm := s.get("self_map")) is not None:
        shares = ", ".join(f"{name} {share:.2f}" for name, share in sm["mapped"].items())
        why = (
            "no global symmetry"
            if sm.get("trivial_global") is None
            else f"the global map is the trivial match ({sm['trivial_global']:.2f} of its vertices stay put)"
        )
        print(f"{why}: the partial symmetry map is {sm['source']} (vertices mapped: {shares})")
    if (m := s.get("modes")) is not None:
        source = "the target's symmetry" if m["second_from"] == "target_symmetry" else "the marginals"
        state = "both answers stand" if m["both"] else "one answer"
        print(
            f"two answers (mode_maps.npy, the second from {source}): confidence "
            f"{m['confidence'][0]:.2f} / {m['confidence'][1]:.2f}, {state}"
        )
    if s.get("global_confidence") is not None:
        print(
            f"global symmetry: {s['global_confidence']:.2f} of the vertices expected within 0.05 sqrt(area) of their "
            "true image "
            "(symmetry_confidence.npy)"
        )
    print(f"wrote {', '.join(s['files'])} to {s['out']}")
    if s.get("figures"):
        print(f"figures: {', '.join(s['figures'])} in {s['out']}/figures")


class _Progress:
    """Stage progress on a terminal: finished stages stay as lines, a spinner shows the rest."""

    def __init__(self, console: Console | None = None) -> None:
        self.bar = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            TimeElapsedColumn(),
            console=console or Console(stderr=True),
            transient=True,
        )
        self.task = self.bar.add_task("loading", total=None)

    def __call__(self, event: ProgressEvent) -> None:
        if isinstance(event, BPIteration):
            self.bar.update(
                self.task,
                description=f"bp iteration {event.iteration}: max message change "
                f"{event.max_change:.3g} (at most {event.max_iterations})",
            )
        else:
            self.bar.console.print(f"[green]done[/] {event.stage}: {event.seconds:.2f} s", highlight=False)
            self.bar.update(self.task, description=next_stage(event.stage))

    def __enter__(self) -> _Progress:
        self.bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.stop()


def _result_dir(path: str) -> Path:
    """A directory written by ``Result.save``, or a one-line input error."""
    out = Path(path)
    if not (out / "result.npz").is_file() or not (out / "run.json").is_file():
        raise InputError(f"{out}: not a result directory (result.npz and run.json missing)")
    return out


def _render_or_view(args: argparse.Namespace) -> int:
    out = _result_dir(args.out)
    if args.command == "render":
        require("viz", "intrinsym render")
        files.check_output_dir(out / "figures")
    else:
        files.check_output_file(args.html if args.html is not None else out / "viewer.html")
    if args.command == "render":
        paths = viz.render(
            out,
            args.source_sample,
            viz.FigureParams(up=args.up, dpi=args.dpi),
            args.mesh,
            max_symmetries=args.symmetries,
        )
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
        frames = (
            [(made[0], out), (made[1], out.with_name(f"{out.stem}_b{out.suffix}"))]
            if isinstance(made, tuple)
            else [(made, out)]
        )
        written = [f for frame, path in frames for f in shapes.save(frame, path)]
    except (TypeError, ValueError) as err:
        text = str(err).splitlines()[0]
        raise ParameterError(re.sub(r"^(arms|resolution|subdivisions)\b", r"--\1", text)) from None
    except OSError as err:
        raise InputError(f"{args.out}: cannot write ({err.strerror})") from None
    print("wrote " + ", ".join(map(str, written)))
    return 0


def _bench(args: argparse.Namespace) -> int:
    for path in args.meshes:
        if not Path(path).is_file():
            raise InputError(f"{path}: no such file")
    if args.small == bool(args.meshes):
        raise ParameterError("bench needs MESH... or --small")
    if args.profile:
        for case in bench.SMALL if args.small else [bench.Case(Path(p).stem, p, 0, 0) for p in args.meshes]:
            sizes = (case.n_source, case.n_target) if args.small else (args.source, args.target)
            p = params.Params(n_source=sizes[0], n_target=sizes[1], iterations=args.iterations)
            prof = bench.profile(case.mesh, p)
            print(json.dumps(dataclasses.asdict(prof), indent=2) if args.json else "\n".join(bench.profile_lines(prof)))
        return 0
    cases = (
        list(bench.SMALL)
        if args.small
        else [bench.Case(Path(p).stem, str(Path(p).resolve()), args.source, args.target) for p in args.meshes]
    )
    console = Console(stderr=True, quiet=args.json or not sys.stderr.isatty())
    with console.status("bench") as status:
        results = bench.run(
            cases, args.iterations, log=lambda name, line: status.update(f"[bold]{name}[/bold]: {line}")
        )
    if args.json:
        print(json.dumps([dataclasses.asdict(r) for r in results], indent=2))
        return 0
    console = Console()
    title = "intrinsym bench (seconds; paper: 100 iterations, GTX280 / 2.66 GHz CPU)"
    for part in text_tables.fit_columns(bench.table(results), console.width):
        table = Table(title=title)
        for col in part[0]:
            table.add_column(col, justify="right")
        for row in part[1:]:
            table.add_row(*row)
        console.print(table)
        title = ""
    return 0


def _map_file(path: str) -> Path:
    """A symmetry map's file: ``path``, or the ``symmetry_map.npy`` of a detect output folder."""
    if not Path(path).is_dir():
        return Path(path)
    file = Path(path) / "symmetry_map.npy"
    if not file.is_file():
        raise InputError(f"{path}: a folder without symmetry_map.npy (give a detect output folder or a map file)")
    return file


def _target_symmetry(path: str, n_vertices: int) -> np.ndarray:
    """``--target-symmetry``: the map in a detect output folder or a map file, (N,) int64
    with -1 where a vertex has no image."""
    file = _map_file(path)
    vmap = evaluate.load_symmetry_map(file, n_vertices, allow_missing=True)
    if vmap.min() < -1:
        raise InputError(f"{file}: a symmetry map marks no vertex 'not scored' (-2)")
    return vmap


def _run(args: argparse.Namespace) -> int:
    if getattr(args, "figures", False):
        require("viz", f"intrinsym {args.command} --figures")
    if args.command == "batch":
        render = functools.partial(viz.render, params=viz.FigureParams(up=args.up)) if args.figures else None
        return batch_command.run(args, _overrides(args), render)
    if args.command == "bench":
        return _bench(args)
    if args.command == "generate":
        return _generate(args)
    if args.command in ("render", "view"):
        return _render_or_view(args)
    if args.command in ("export", "show"):
        return cli_extra.run_export(args)
    if args.command in ("detect", "match"):
        p = _params(args)
        if args.command == "detect" and args.example == (args.mesh is not None):
            raise ParameterError("detect needs exactly one of MESH or --example")
        with files.output_lock(args.out):
            inputs = [load(args.mesh or example_path())] if args.command == "detect" else [load(args.a), load(args.b)]
            target_symmetry = (
                _target_symmetry(args.target_symmetry, len(inputs[1].vertices))
                if args.command == "match" and args.target_symmetry
                else None
            )
            estimate = resources.check_run(
                max(len(s.vertices) for s in inputs), p, str(inputs[0].path), args.command == "detect"
            )
            if estimate.seconds > 60 and not args.quiet:
                print(f"intrinsym: this run takes {estimate.describe()}", file=sys.stderr)
            show = not (args.quiet or args.json) and sys.stderr.isatty()
            progress = _Progress() if show else None
            with resources.disk_room(args.out, estimate.disk), progress or contextlib.nullcontext():
                if args.command == "detect":
                    result = pipeline.detect(inputs[0], p, progress=progress)
                else:
                    result = pipeline.match(inputs[0], inputs[1], p, progress=progress, target_symmetry=target_symmetry)
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
    result = Result.load(out)
    if args.command == "query":
        return _query(args, result, out)
    shape = load(args.mesh or result.info.input)
    has_map = (out / "symmetry_map.npy").is_file()
    if args.labels and not has_map:
        raise InputError(f"{out}: no symmetry_map.npy to segment (rerun intrinsym detect)")
    n = len(shape.vertices)
    found = evaluate.load_symmetry_map(out / "symmetry_map.npy", n, allow_missing=True) if has_map else None
    truths = symmetry_group.load_truths([_map_file(path) for path in args.symmetry_map], shape, args.reference)
    nearest, group = symmetry_group.group_report(truths, found, viz.load_symmetries(out), shape)
    truth = truths[nearest]
    sym = truth.partner
    conf_path = out / "symmetry_confidence.npy"
    report, maps = evaluate.evaluation_report(
        result.marginals,
        result.source_point_vertex,
        result.target_point_vertex,
        found,
        shape,
        sym,
        labels=evaluate.load_labels(args.labels, n) if args.labels else None,
        seed=args.seed,
        confidence=evaluate.load_confidence(conf_path, n) if has_map and conf_path.is_file() else None,
    )
    curve = maps is not None and available("viz")
    if maps is not None and curve:
        evaluate.plot_curve(maps, out / "curve.png")
    elif maps is not None:
        print("intrinsym: no curve.png: it needs the [viz] extra: pip install 'intrinsym[viz]'", file=sys.stderr)
    report["group"] = group
    shrec = any(Path(path).suffix == ".baryc_gt_sym" for path in args.symmetry_map)
    if found is not None and (args.reference or shrec or np.any(sym < 0)):
        report["partial"] = partial_truth.partial_report(found, shape, truth, _best_parts(out, n))
    evaluate.save_scores(report, out / "scores.json")
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(
            f"mirror hit {report['mirror_hit']:.3f}  peak recall {report['peak_recall']:.3f}  "
            f"decoy recall {report['decoy_recall']:.3f}  breadth {report['breadth']:.4f}  "
            f"(fractions; {report['n_scored']} source points scored)"
        )
        if "map" in report:
            m = report["map"]
            print(
                f"global map (shares of the vertices): within 0.05 sqrt(area) {m['within_0.05']:.3f}  within 0.10 "
                f"{m['within_0.10']:.3f}  (of the area {m['area_within_0.05']:.3f} / {m['area_within_0.10']:.3f})  "
                f"mean error {m['mean_error']:.4f} sqrt(area)  coverage {m['coverage']:.3f}"
                + ("  (curve.png)" if curve else "")
            )
            for label, value in m["segmentation"].items():
                print(f"segmentation part {label}: {100 * value:.1f}%")
            if "confidence" in report:
                c = report["confidence"]
                print(
                    f"confidence (symmetry_confidence.npy): expected calibration error "
                    f"{c['expected_calibration_error']:.3f}, mean {c['confidence']:.3f} against "
                    f"{c['within']:.3f} measured within {c['threshold']} sqrt(area)"
                )
        if "partial" in report:
            q = report["partial"]
            print(
                f"partial symmetry (units of sqrt(area) {q['unit']:.4g}): balanced {q['balanced']:.3f}  "
                f"partnered within 0.05 {q['partnered_within_005']:.3f} / 0.10 {q['partnered_within_010']:.3f} "
                f"({q['n_partnered']} vertices)  unpartnered left unmapped {q['unpartnered_unmapped']:.3f} "
                f"({q['n_unpartnered']} vertices)  IoU of the best symmetry's parts {q['iou']}"
            )
        for line in symmetry_group.group_lines(group):
            print(line)
        distortion = report["truth_distortion"]
        line = f"distortion (share of the pairs within {distortion['radius']} sqrt(area) changed by more than 0.05): "
        if "map" in report:
            line += f"global map {report['map']['distortion']['above_0.05']:.3f}, "
        print(line + f"ground truth {distortion['above_0.05']:.3f}")
    return 0


def _best_parts(out: Path, n: int) -> np.ndarray | None:
    """(n,) bool: the input vertices of the best-ranked symmetry's two parts; None without one."""
    found = viz.load_symmetries(out)
    return part_mask(found[0], n) if found else None


def _query(args: argparse.Namespace, result: Result, out: Path) -> int:
    """Print every symmetric part pair of the source sample holding --vertex."""
    if result.support is None:
        raise InputError(f"{out}: result.npz holds no extraction data (rerun intrinsym detect)")
    cells = result.support.vertex_source
    if not 0 <= args.vertex < len(cells):
        raise ParameterError(f"--vertex must lie in [0, {len(cells) - 1}]")
    sample = int(cells[args.vertex])
    if sample < 0:
        raise ParameterError(f"vertex {args.vertex} lies in no source sample's cell")
    p = dataclasses.replace(
        result.params,
        **{k: v for k, v in (("peak_threshold", args.peak_threshold), ("d_error", args.d_error)) if v is not None},
    )
    found = extract.query_from_support(
        result.marginals,
        result.edges,
        result.support,
        result.source_points,
        result.target_points,
        sample,
        dataclasses.replace(result, params=p).extraction_params(),
        unary=result.unary,
        passes=result.passes,
    )
    listed = records(found, result.source_point_vertex, result.target_point_vertex, result.support)
    for record, sym in zip(listed, found):
        record["image_vertex"] = int(result.target_point_vertex[sym.target[np.searchsorted(sym.source, sample)]])
    if args.json:
        print(json.dumps({"vertex": args.vertex, "source_sample": sample, "symmetries": listed}))
        return 0
    print(f"vertex {args.vertex} (source sample {sample}): {len(listed)} symmetric part(s)")
    for r in listed:
        print(
            f"  {r['kind']:8s} -> vertex {r['image_vertex']:6d}  score {r['score']:.3f}  "
            f"consistency {r['consistency']:.2f}  {len(r['pairs'])} samples, "
            f"{len(r['source_vertex_index'])} -> {len(r['target_vertex_index'])} vertices"
        )
    return 0


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is, so that it unwinds as on Ctrl-C (temporary
    files removed, the progress display stopped)."""


#: Seconds after which a signal that arrived inside Numba or llvmlite is sent again.
RESEND_SECONDS = 0.1
#: Modules whose Python code runs under C callers that drop or mangle an exception raised in
#: it: llvmlite's ctypes callbacks (Numba compiling its kernels, on a first run) and Numba's
#: own, which its C dispatcher calls (unpickling a cached kernel, typing the arguments).
UNINTERRUPTIBLE = ("llvmlite", "numba")
#: What each handled signal raises where it lands.
RAISES: dict[int, type[KeyboardInterrupt]] = {signal.SIGTERM: Terminated, signal.SIGINT: KeyboardInterrupt}


def _interrupt(signum: int, frame: FrameType | None) -> None:
    """Raise the signal's exception (:data:`RAISES`) in the frame the signal interrupted,
    unless that frame runs inside Numba or llvmlite (:data:`UNINTERRUPTIBLE`). An exception
    cannot leave llvmlite's ctypes callbacks: it is dropped there and the process later dies
    of a segmentation fault. Numba's C dispatcher turns one raised in the Python code it
    calls into a ``SystemError`` traceback. There the signal is sent again a moment later,
    until it lands outside: a running kernel has no Python frame, so it lands when the
    kernel returns."""
    while frame is not None:
        if str(frame.f_globals.get("__name__", "")).split(".")[0] in UNINTERRUPTIBLE:
            resend = threading.Timer(RESEND_SECONDS, os.kill, (os.getpid(), signum))
            resend.daemon = True  # a run that ends first is not signalled after it
            resend.start()
            return
        frame = frame.f_back
    raise RAISES[signum]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``intrinsym`` command; returns the exit code (2 for a user
    error, 130 on Ctrl-C, 143 on SIGTERM)."""
    args = cli_extra.parse(build_parser, argv)
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, _interrupt)}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not where Ctrl-C is ignored
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, _interrupt)
    try:
        return _run(args)
    except IntrinsymError as err:
        print(f"intrinsym: error: {err}", file=sys.stderr)
        return 2
    except MemoryError as err:  # beyond the estimate that resources.check_run refuses up front
        print(f"intrinsym: error: out of memory ({err or 'MemoryError'})", file=sys.stderr)
        return 2
    except Terminated:
        print("intrinsym: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("intrinsym: interrupted", file=sys.stderr)
        return 130
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


if __name__ == "__main__":
    sys.exit(main())
