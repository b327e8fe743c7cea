"""Batches: ``detect`` over many meshes (or ``match`` over many pairs) on Dask, one
output folder per item, a summary table, re-runs that skip what is done.

>>> import intrinsym
>>> summary = intrinsym.batch(["meshes/"], "out", n_source=100, n_target=1000)  # doctest: +SKIP
>>> summary[["name", "status", "global_score"]]  # doctest: +SKIP
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import ParameterError
from ...extras import require
from ...params import Params
from ...pipeline import resolve_params
from . import engine
from .engine import ClusterPlan, Counts, Transport
from .items import Item, collect, content_key
from .rows import base_row, finished_row
from .work import AfterSave

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ClusterPlan", "Counts", "Item", "batch", "collect", "content_key", "report"]

log = logging.getLogger("intrinsym")

#: Seconds between two rewrites of the summary while a batch runs.
SUMMARY_EVERY = 30.0


def batch(
    inputs: str | os.PathLike | Sequence[str | os.PathLike],
    out: str | os.PathLike,
    params: Params | None = None,
    *,
    n_source: int | None = None,
    n_target: int | None = None,
    seed: int | None = None,
    preset: str = "default",
    pairs: bool = False,
    group_by: str | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    host: str = engine.LOCAL_HOST,
    transport: Transport = "auto",
    force: bool = False,
    after_save: AfterSave | None = None,
    progress: Callable[[Counts], None] | None = None,
    message: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """Run ``detect`` on every mesh of ``inputs`` (``match`` on pairs) on a Dask cluster.

    Every item gets the folder ``out/NAME`` written by :meth:`Result.save` (with
    ``scores.json`` when a ground truth is known), whose ``run.json`` holds the item's
    content key; an item whose folder already holds a complete result with its key is
    skipped. A failing item becomes a failed row; the batch goes on.

    Parameters
    ----------
    inputs : path or sequence of paths
        Mesh files, folders, glob patterns and CSV manifests (see
        :func:`intrinsym.app.batching.items.collect`). A mesh ``STEM.off`` with ``STEM.sym.npy``,
        ``STEM.sym`` or its class's TOSCA map beside it is scored against it.
    out : path
        The batch's folder: the item folders, ``summary.parquet`` and ``summary.csv``.
    params : Params, optional
        Parameters of every item (default: the preset's); manifest columns override them.
    n_source, n_target, seed : int, optional
        Override the fields of the same names.
    preset : {"default", "paper"}
    pairs : bool
        ``match`` over the manifest's source/target rows, or all ordered pairs of distinct
        meshes within each group.
    group_by : str, optional
        Pairs: the manifest column that forms the groups.
    scheduler : str, optional
        Address of a running Dask scheduler (default ``$DASK_SCHEDULER_ADDRESS``, else a
        new local cluster sized by :func:`intrinsym.app.batching.engine.plan_cluster`).
    workers : int, optional
        Workers of the local cluster, 1 to the cores (default: from the cores and the memory).
    host : str
        Where the local cluster's scheduler, workers and dashboard listen (default
        127.0.0.1: this machine only; the dashboard has no authentication).
    transport : {"auto", "path", "bytes"}
        "path": the workers read the meshes and write the folders (a shared file system);
        "bytes": the client sends the meshes' bytes and writes the folders; "auto": path
        when every worker sees the output folder and the first input.
    force : bool
        Run every item again, even those with a complete result.
    after_save : callable, optional
        Called with each item's folder once it is written.
    progress : callable, optional
        Called with :class:`Counts` while the batch runs.
    message : callable, optional
        Called with a line on the cluster, the dashboard and the transport (default: the
        ``intrinsym`` logger).

    Returns
    -------
    pandas.DataFrame
        The summary, one row per item (also written to ``out``).

    Raises
    ------
    InputError, ParameterError
        Inputs that name no mesh, an unreadable manifest, an item name that is not a
        plain folder name, bad parameters, a scheduler that is malformed or does not
        answer (``out`` is then not created).
    KeyboardInterrupt
        After writing the summary of what finished (the rest as "interrupted").
    """
    require("batch", "intrinsym.batch")
    from . import summary

    say = message or log.info
    p = resolve_params(params, preset, n_source=n_source, n_target=n_target, seed=seed)
    paths = [str(inputs)] if isinstance(inputs, (str, os.PathLike)) else [str(i) for i in inputs]
    items = collect(paths, p, pairs=pairs, group_by=group_by)
    if transport not in ("auto", "path", "bytes"):
        raise ParameterError(f"transport must be auto, path or bytes, not {transport!r}")
    engine.check_workers(workers)
    engine.scheduler_address(scheduler)
    root = Path(out)
    earlier = summary.previous_rows(root)
    rows: dict[str, dict[str, Any]] = {}
    jobs: list[tuple[Item, str]] = []
    for item in items:
        key = content_key(item)
        found = None if force else finished_row(item, key, root / item.name)
        if found is None:
            jobs.append((item, key))
        else:
            old = earlier.get((item.name, key))
            rows[item.name] = {**old, "status": "skipped"} if old else found
    say(f"{len(items)} items: {len(jobs)} to run, {len(rows)} done before (skipped)")
    if jobs:
        _run(jobs, items, rows, root, scheduler, workers, host, transport, force, after_save, progress, say)
    root.mkdir(parents=True, exist_ok=True)
    frame = summary.table([rows[item.name] for item in items])
    summary.write(frame, root)
    return frame


def _run(
    jobs: list[tuple[Item, str]],
    items: list[Item],
    rows: dict[str, dict[str, Any]],
    root: Path,
    scheduler: str | None,
    workers: int | None,
    host: str,
    transport: Transport,
    force: bool,
    after_save: AfterSave | None,
    progress: Callable[[Counts], None] | None,
    say: Callable[[str], None],
) -> None:
    """Run the jobs on the scheduler, or a local cluster of so many workers listening on
    ``host``, filling ``rows`` (the summary is rewritten every ``SUMMARY_EVERY``
    seconds); on an interrupt write the summary with the items not finished as
    "interrupted" before re-raising. Creates ``root`` once the cluster answers."""
    from . import summary

    plan = engine.plan_cluster([item for item, _ in jobs], workers=workers)
    client, cluster = engine.connect(plan, scheduler, host)
    written = time.monotonic()
    try:
        root.mkdir(parents=True, exist_ok=True)
        say(engine.describe_cluster(client, cluster, plan))
        how = engine.choose_transport(client, transport, root, [item for item, _ in jobs])
        say(
            "inputs travel by path (workers read the meshes and write the folders)"
            if how == "path"
            else "inputs travel as bytes (the client sends the meshes and writes the folders)"
        )
        for outcome in engine.execute(client, jobs, how, root, not force, after_save, progress):
            rows[outcome.row["name"]] = outcome.row
            if time.monotonic() - written > SUMMARY_EVERY:
                summary.write(summary.table(_with_unfinished(items, rows, jobs, "pending")), root)
                written = time.monotonic()
    except KeyboardInterrupt:
        summary.write(summary.table(_with_unfinished(items, rows, jobs, "interrupted")), root)
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _with_unfinished(
    items: list[Item], rows: dict[str, dict[str, Any]], jobs: list[tuple[Item, str]], status: str
) -> list[dict]:
    """Every item's row, those not finished yet with ``status`` ("pending" while the
    batch runs, "interrupted" once it stopped)."""
    keys = {item.name: key for item, key in jobs}
    return [rows.get(item.name) or base_row(item, keys[item.name], status) for item in items]


def report(out: str | os.PathLike) -> tuple[pd.DataFrame, Path]:
    """The aggregate table of a batch's summary (per class: mean and worst score) and the
    plot ``out/report.png`` (score distribution; seconds against vertices)."""
    require("batch", "intrinsym.app.batching.report")
    require("viz", "intrinsym.app.batching.report")
    from . import summary

    frame = summary.read(out)
    return summary.aggregate(frame), summary.plot(frame, Path(out) / "report.png")
