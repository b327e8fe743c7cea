"""The batch's table (``summary.parquet`` and ``summary.csv``, one row per item) and its
report: an aggregate per class and a plot (``report.png``)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ...errors import InputError
from ...files import atomic_write
from .rows import COLUMNS

#: Statuses of the items that have a result.
FINISHED = ("done", "skipped")
#: Score columns of the report: (column, whether larger is better).
REPORT_SCORES = (
    ("global_score", True),
    ("global_confidence", True),
    ("mirror_hit", True),
    ("peak_recall", True),
    ("map_within_0.10", True),
    ("map_mean_error", False),
)


def table(rows: Sequence[dict[str, Any]]) -> pd.DataFrame:
    """The rows as a table, columns in :data:`~intrinsym.app.batching.rows.COLUMNS` order with the
    ``seconds_<stage>`` columns after ``seconds``."""
    frame = pd.DataFrame(list(rows))
    stages = [c for c in frame.columns if c.startswith("seconds_")]
    order = [c for c in COLUMNS if c != "seconds"]
    at = order.index("wall_seconds")
    order[at:at] = ["seconds", *stages]
    for column in order:
        if column not in frame.columns:
            frame[column] = None
    return frame[order]


def write(frame: pd.DataFrame, out: str | os.PathLike) -> None:
    """Write ``out/summary.parquet`` and ``out/summary.csv`` (each atomically)."""
    out = Path(out)
    atomic_write(out / "summary.parquet", lambda f: frame.to_parquet(f, index=False), binary=True)
    atomic_write(out / "summary.csv", lambda f: frame.to_csv(f, index=False))


def read(out: str | os.PathLike) -> pd.DataFrame:
    """``out/summary.parquet``, or an :class:`InputError` when there is none."""
    path = Path(out) / "summary.parquet"
    if not path.is_file():
        raise InputError(f"{out}: no summary.parquet (not a folder written by intrinsym batch)")
    return pd.read_parquet(path)


def previous_rows(out: str | os.PathLike) -> dict[tuple[str, str], dict[str, Any]]:
    """Rows of an earlier run's summary that finished, by (name, key); empty without one."""
    path = Path(out) / "summary.parquet"
    if not path.is_file():
        return {}
    try:
        frame = pd.read_parquet(path)
    except (OSError, ValueError):
        return {}
    finished = frame[frame["status"].isin(["done", "skipped"])]
    return {(r["name"], r["key"]): r for r in finished.to_dict("records")}


def aggregate(frame: pd.DataFrame) -> pd.DataFrame:
    """Per class (and "all"): items, failed, global symmetries found, mean and worst of
    every score column present, mean and largest seconds and peak memory."""

    def summarise(part: pd.DataFrame) -> dict[str, Any]:
        ok = part[part["status"].isin(FINISHED)]
        row: dict[str, Any] = {
            "items": len(part),
            "failed": int((part["status"] == "failed").sum()),
            "global found": float(ok["global_symmetry"].astype(float).mean()) if len(ok) else np.nan,
        }
        for column, larger_better in REPORT_SCORES:
            values = pd.to_numeric(ok[column], errors="coerce").dropna()
            if len(values):
                row[f"{column} mean"] = float(values.mean())
                row[f"{column} worst"] = float(values.min() if larger_better else values.max())
        seconds = pd.to_numeric(ok["seconds"], errors="coerce")
        memory = pd.to_numeric(ok["peak_memory_mb"], errors="coerce")
        row.update(
            {
                "seconds mean": float(seconds.mean()),
                "seconds max": float(seconds.max()),
                "peak MB max": float(memory.max()),
            }
        )
        return row

    groups = {str(name): summarise(part) for name, part in frame.groupby("class", sort=True)}
    groups["all"] = summarise(frame)
    return pd.DataFrame.from_dict(groups, orient="index")


def plot(frame: pd.DataFrame, path: str | os.PathLike) -> Path:
    """``report.png``: the distribution of the scores (left) and seconds against input
    vertices, per class (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = frame[frame["status"].isin(FINISHED)]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    shown = [
        c for c, _ in REPORT_SCORES if c != "map_mean_error" and pd.to_numeric(ok[c], errors="coerce").notna().any()
    ]
    for column in shown:
        left.hist(pd.to_numeric(ok[column], errors="coerce").dropna(), bins=20, range=(0, 1), alpha=0.5, label=column)
    left.set_xlabel("score")
    left.set_ylabel("items")
    left.set_title("score distribution")
    if shown:
        left.legend()
    for name, part in ok.groupby("class", sort=True):
        right.scatter(
            pd.to_numeric(part["vertices"], errors="coerce"),
            pd.to_numeric(part["seconds"], errors="coerce"),
            label=name,
        )
    right.set_xlabel("input vertices")
    right.set_ylabel("seconds (pipeline)")
    right.set_title("seconds against vertices")
    if ok["class"].nunique() <= 12:
        right.legend(fontsize="small")
    fig.tight_layout()
    out = Path(path)
    atomic_write(out, lambda f: fig.savefig(f, format="png", dpi=110), binary=True)
    plt.close(fig)
    return out
