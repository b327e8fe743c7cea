"""Two runs of a SHREC'16 benchmark side by side, shape by shape, against the seed's spread.

On the partial shapes one shape's outcome is a draw: the default ``detect`` at seed 1
moves 76 of the 125 shapes by more than 0.01 (balanced, by 0.090 on average) and the mean
by 0.018 (docs/limitations.md). A change earns its place only beyond that. This script
reads the per-shape caches that ``benchmarks/partial.py`` and ``benchmarks/shrec16_match.py``
write (one JSON row per shape and method; the match's under ``CACHE/match``) and prints, per
kind (cuts / holes) and over the shapes both runs hold: the mean of a score before and
after, how many shapes gain or lose more than ``--within``, the mean absolute change,
and the largest moves. ``--spread A B`` adds the same row for two runs that differ only
in the seed (e.g. ``--param seed=1``), and the ratio of the change in the mean to the
seed's. Command::

    python benchmarks/compare.py BEFORE AFTER [--metric NAME] [--method intrinsym]
        [--within 0.01] [--spread SEED0 SEED1] [--shapes cuts holes_dog ...]

``--metric`` defaults to ``balanced`` for ``partial.py``'s caches and ``within_010`` for
``shrec16_match.py``'s (whichever the results hold). Exit code 2 with one line on a folder
without results, a metric the results lack, or no shape in common.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: The score compared when ``--metric`` is not given: the first the results hold.
DEFAULT_METRICS = ("balanced", "within_010")
KINDS = ("cuts", "holes")


class CompareError(Exception):
    """A folder, metric or selection the comparison cannot use (one line, exit 2)."""


@dataclass(frozen=True)
class Change:
    """One score over the same shapes in two runs.

    Attributes
    ----------
    shapes : (N,) str
    before, after : (N,) float64
        The score per shape (NaN where a run recorded none).
    within : float
        A shape gains or loses when its score moves by more than this.
    """

    shapes: np.ndarray
    before: np.ndarray
    after: np.ndarray
    within: float

    @property
    def delta(self) -> np.ndarray:
        return self.after - self.before

    @property
    def better(self) -> int:
        return int(np.sum(self.delta > self.within))

    @property
    def worse(self) -> int:
        return int(np.sum(self.delta < -self.within))

    @property
    def scored(self) -> np.ndarray:
        """The changes of the shapes both runs scored."""
        return self.delta[np.isfinite(self.delta)]

    @property
    def mean_change(self) -> float:
        """Change in the mean, over the shapes both runs scored."""
        return float(np.mean(self.scored)) if len(self.scored) else float("nan")

    @property
    def mean_abs_change(self) -> float:
        return float(np.mean(np.abs(self.scored))) if len(self.scored) else float("nan")

    def subset(self, keep: np.ndarray) -> Change:
        return Change(self.shapes[keep], self.before[keep], self.after[keep], self.within)


def load_results(folder: Path, method: str) -> dict[str, dict]:
    """Per shape, the cached result of ``method`` in ``folder`` (or in its ``match``
    subfolder, where ``shrec16_match.py`` writes), keyed by the rows' own ``shape``.

    Raises
    ------
    CompareError
        The folder holds no such results, or a file that is not one.
    """
    if not folder.is_dir():
        raise CompareError(f"{folder}: not a folder")
    for where in (folder, folder / "match"):
        rows = {}
        for f in sorted(where.glob("*.json")):
            try:
                row = json.loads(f.read_text())
            except (OSError, ValueError) as error:
                raise CompareError(f"{f}: not a readable result ({error})") from None
            if row.get("method") == method:
                rows[row["shape"]] = row
        if rows:
            return rows
    raise CompareError(f"{folder}: no results of {method}")


def pick_metric(rows: dict[str, dict], metric: str | None) -> str:
    """``metric``, or the first of :data:`DEFAULT_METRICS` the results hold."""
    first = next(iter(rows.values()))
    if metric is None:
        for name in DEFAULT_METRICS:
            if name in first:
                return name
        raise CompareError(f"none of {', '.join(DEFAULT_METRICS)} in the results; give --metric")
    if metric not in first:
        raise CompareError(f"--metric {metric}: not in the results")
    return metric


def compare(
    before: dict[str, dict], after: dict[str, dict], metric: str, within: float, shapes: list[str] | None = None
) -> Change:
    """The score ``metric`` of the shapes both runs hold (and whose names start with one
    of ``shapes``), sorted by name."""
    common = sorted(set(before) & set(after))
    if shapes:
        common = [s for s in common if any(s.startswith(prefix) for prefix in shapes)]
    if not common:
        raise CompareError("no shape in both runs" + (" among --shapes" if shapes else ""))

    def score(row: dict) -> float:
        value = row.get(metric)
        return float("nan") if value is None else float(value)

    return Change(
        np.array(common),
        np.array([score(before[s]) for s in common]),
        np.array([score(after[s]) for s in common]),
        within,
    )


def _row(label: str, change: Change) -> str:
    return (
        f"| {label} ({len(change.shapes)}) | {np.nanmean(change.before):.3f} | {np.nanmean(change.after):.3f} "
        f"| {change.mean_change:+.3f} | {change.better} | {change.worse} | {change.mean_abs_change:.3f} |"
    )


def markdown(change: Change, metric: str, spread: Change | None = None, moves: int = 3) -> str:
    """The comparison table per kind and overall, the seed's row, and the largest moves."""
    lines = [
        f"| {metric} | before | after | change of the mean | better by > {change.within:g} | worse | mean abs change |",
        "|---|---|---|---|---|---|---|",
    ]
    for kind in KINDS:
        keep = np.char.startswith(change.shapes.astype(str), kind)
        if keep.any() and not keep.all():
            lines.append(_row(kind, change.subset(keep)))
    lines.append(_row("**all**", change))
    if spread is not None:
        lines.append(_row("seed only", spread))
    order = np.argsort(np.nan_to_num(change.delta, nan=0.0), kind="stable")
    lines.append("")
    for title, picks in (("down", order[:moves]), ("up", order[::-1][:moves])):
        moved = [
            f"{change.shapes[i]} {change.before[i]:.3f} -> {change.after[i]:.3f}"
            for i in picks
            if abs(np.nan_to_num(change.delta[i])) > change.within
        ]
        lines.append(f"Largest moves {title}: " + ("; ".join(moved) if moved else "none"))
    if spread is not None:
        seed = abs(spread.mean_change)
        ratio = abs(change.mean_change) / seed if seed > 0 else float("inf")
        lines.append(
            f"The change of the mean is {ratio:.1f} times the seed's ({change.mean_change:+.3f} against "
            f"{spread.mean_change:+.3f}); shapes moved by more than {change.within:g}: "
            f"{change.better + change.worse} against the seed's {spread.better + spread.worse}."
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path, help="cache folder of the first run")
    parser.add_argument("after", type=Path, help="cache folder of the second run")
    parser.add_argument("--metric", help=f"score compared (default: the first of {', '.join(DEFAULT_METRICS)} held)")
    parser.add_argument("--method", default="intrinsym", help="the method's results (default intrinsym)")
    parser.add_argument("--within", type=float, default=0.01, help="a shape moves when its score changes by more")
    parser.add_argument(
        "--spread", nargs=2, type=Path, metavar=("SEED_A", "SEED_B"), help="two runs that differ only in the seed"
    )
    parser.add_argument("--shapes", nargs="+", metavar="NAME", help="shape names or prefixes (default: all)")
    args = parser.parse_args(argv)
    try:
        if args.within < 0:
            raise CompareError(f"--within {args.within}: must be at least 0")
        before, after = load_results(args.before, args.method), load_results(args.after, args.method)
        metric = pick_metric(before, args.metric)
        pick_metric(after, metric)
        change = compare(before, after, metric, args.within, args.shapes)
        spread = None
        if args.spread:
            seeds = [load_results(folder, args.method) for folder in args.spread]
            spread = compare(seeds[0], seeds[1], metric, args.within, args.shapes)
    except CompareError as error:
        print(f"compare.py: {error}", file=sys.stderr)
        return 2
    print(markdown(change, metric, spread))
    return 0


if __name__ == "__main__":
    sys.exit(main())
