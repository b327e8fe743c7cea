"""``intrinsym batch``: its own options (the parameter options are the ones of
``detect``) and what it prints: the cluster, a progress bar, the outcome, the report."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from ...errors import ParameterError
from ...extras import require
from ...params import make_params
from .. import text_tables
from . import batch, engine, report
from .engine import Counts
from .work import AfterSave

#: Failed items listed by name after a batch (the rest are in the summary).
SHOWN_FAILURES = 10


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``intrinsym batch`` besides ``detect``'s."""
    p.add_argument(
        "inputs",
        nargs="*",
        metavar="INPUT",
        help="mesh files, folders, glob patterns (quoted) or CSV manifests: column 'mesh' (pairs: 'source' "
        "and 'target'), optional 'symmetry_map', 'labels', 'target_symmetry' (pairs: the target's own "
        "symmetry map), 'class', 'name' and any parameter by its Python name (docs/parameters.md)",
    )
    p.add_argument(
        "--pairs",
        action="store_true",
        help="run match instead of detect: over a manifest's source/target rows, or over all ordered "
        "pairs of distinct meshes within each --group-by group (default: one group)",
    )
    p.add_argument("--group-by", metavar="COLUMN", help="--pairs: the manifest column whose values form the groups")
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler, e.g. tcp://host:8786 (default: $DASK_SCHEDULER_ADDRESS, else a "
        "local cluster sized from the cores and the memory)",
    )
    p.add_argument(
        "--workers", type=int, help="workers of the local cluster, 1 to the cores (default: from cores and memory)"
    )
    p.add_argument(
        "--host",
        default=engine.LOCAL_HOST,
        help="where the local cluster's scheduler, workers and dashboard listen (default: %(default)s, this "
        "machine only; the dashboard has no authentication, so choose another interface only on a trusted network)",
    )
    how = p.add_mutually_exclusive_group()
    how.add_argument(
        "--send-bytes",
        dest="transport",
        action="store_const",
        const="bytes",
        default="auto",
        help="send the meshes to the workers as bytes and write the results here (workers without "
        "this machine's files; default: by path when the workers see the output folder)",
    )
    how.add_argument(
        "--by-path",
        dest="transport",
        action="store_const",
        const="path",
        help="workers read the meshes and write the results themselves (a shared file system)",
    )
    p.add_argument("--force", action="store_true", help="run every item again, even those already done")
    p.add_argument(
        "--report",
        action="store_true",
        help="print the aggregate table of OUT/summary.parquet (mean and worst per class) and write "
        "OUT/report.png; without INPUTS, only that",
    )


class _Bar:
    """A rich progress bar of a batch: done / failed / running and the time left."""

    def __init__(self, console: Console) -> None:
        self.bar = Progress(
            TextColumn("batch"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[counts]}"),
            TimeElapsedColumn(),
            TextColumn("eta"),
            TimeRemainingColumn(),
            console=console,
            transient=True,
        )
        self.task = self.bar.add_task("batch", total=None, counts="starting the cluster")

    def __call__(self, counts: Counts) -> None:
        self.bar.update(
            self.task,
            total=counts.total,
            completed=counts.done + counts.failed,
            counts=f"done {counts.done}  failed {counts.failed}  running {counts.running}",
        )

    def __enter__(self) -> _Bar:
        self.bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.stop()


def _print_report(out: str, show: bool) -> dict[str, Any]:
    table, plot = report(out)
    if show:
        cells = [text_tables.format_column(list(table[column])) for column in table.columns]
        rows = [["class", *table.columns], *([str(name), *row] for name, row in zip(table.index, zip(*cells)))]
        console = Console()
        title = f"intrinsym batch report: {out} (plot: {plot})"
        for part in text_tables.fit_columns(rows, console.width):
            shown = Table(title=title)
            for column in part[0]:
                shown.add_column(column, justify="left" if column == "class" else "right")
            for row in part[1:]:
                shown.add_row(*row)
            console.print(shown)
            title = ""
    return {"report": json.loads(table.to_json(orient="index")), "plot": str(plot)}


def run(args: argparse.Namespace, overrides: dict[str, Any], after_save: AfterSave | None) -> int:
    """Run ``intrinsym batch``; exit code 0, or 1 when an item failed."""
    if not args.inputs and not args.report:
        raise ParameterError("batch needs INPUT... (or --report to report on OUT)")
    require("batch", "intrinsym batch")
    if args.report:
        require("viz", "intrinsym batch --report")
    engine.check_workers(args.workers, "--workers")
    quiet = args.quiet or args.json
    console = Console(stderr=True, quiet=quiet)
    output: dict[str, Any] = {"out": args.out}
    failed = 0
    if args.inputs:
        params = make_params(args.preset, **overrides)
        bar = _Bar(console) if not quiet and sys.stderr.isatty() else None
        with bar or contextlib.nullcontext():
            frame = batch(
                args.inputs,
                args.out,
                params,
                pairs=args.pairs,
                group_by=args.group_by,
                scheduler=args.scheduler,
                workers=args.workers,
                host=args.host,
                transport=args.transport,
                force=args.force,
                after_save=after_save,
                progress=bar,
                message=lambda line: console.print(line, highlight=False, soft_wrap=True),
            )
        counts = frame["status"].value_counts().to_dict()
        failed = int(counts.get("failed", 0))
        bad = frame[frame["status"] == "failed"]
        output.update(
            items=len(frame),
            **{status: int(counts.get(status, 0)) for status in ("done", "skipped", "failed")},
            failures=dict(zip(bad["name"], bad["error"])),
        )
        if not quiet:
            print(
                f"{len(frame)} items: {output['done']} done, {output['skipped']} skipped, {failed} failed; "
                f"wrote summary.parquet and summary.csv to {args.out}"
            )
            for name, error in list(output["failures"].items())[:SHOWN_FAILURES]:
                print(f"  failed {name}: {error}")
    if args.report:
        output.update(_print_report(args.out, not quiet))
    if args.json:
        print(json.dumps(output, indent=2))
    return 1 if failed else 0
