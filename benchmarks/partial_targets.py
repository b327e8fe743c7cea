"""The partial-symmetry issue's targets on the SHREC'16 shapes, from ``partial.py``'s cache.

For every target the issue sets (defaults, seed 0, all 125 shapes): the value measured,
by how much it falls short, the kinds and classes that miss it and how many shapes do.
Then one row per shape that misses a per-shape target (balanced 0.60; on the holes,
0.90 of the partnered vertices within 0.10; the best-ranked symmetry's IoU 0.80) with
its scores, the map ``detect`` kept and, given ``unary_partner.py``'s rows for the
default unary (``--unary``), where that unary put the partner: the measurements that
explain the miss, and their medians over the shapes that miss and those that meet the
balanced 0.60. Commands::

    OPENBLAS_NUM_THREADS=1 python benchmarks/partial.py --data DATA --cache C --tag TAG --jobs 2
    OPENBLAS_NUM_THREADS=1 python benchmarks/unary_partner.py --data DATA --shapes cuts holes
        --terms 'wks*spin' --json U.json
    python benchmarks/partial_targets.py --data DATA --cache C --tag TAG [--unary U.json ...] [-o OUT.md]

``--param`` selects cached rows run with those ``Params`` fields, as in ``partial.py``.
Every shape needs its three cached rows (intrinsym, none, pyfm); a missing one, or a
``--unary`` file that cannot be read, is one line naming it, exit 2. Seconds are
``partial.py``'s: ``detect`` within the process, as many shapes at a time as its
``--jobs``, not the whole command.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import intrinsym
import partial
from _data import add_data_argument
from tosca import _overrides

#: The methods whose cached rows the targets need.
METHODS = ("intrinsym", "none", "pyfm")
#: Measures of ``unary_partner.py`` shown beside a shape that misses.
UNARY = ("partner at floor", "argmax ≤0.05", "BP argmax ≤0.05")


@dataclass(frozen=True)
class Target:
    """One target of the issue.

    Attributes
    ----------
    name : str
        As the tables word it.
    key : str
        The row's score (``partial.py``'s cached key).
    bound : float
        The value to reach: at least (at most for ``most``).
    scope : str
        "mean": the mean over the shapes; "each": every shape; "share": at least
        ``share`` of the shapes.
    kinds : tuple of str
        The kinds of shape it applies to.
    share : float
        For ``scope="share"``: the share of shapes that must meet ``bound``.
    most : bool
        The bound is a largest value (seconds).
    """

    name: str
    key: str
    bound: float
    scope: str
    kinds: tuple[str, ...] = ("cuts", "holes")
    share: float = 1.0
    most: bool = False

    def meets(self, value: float) -> bool:
        return value <= self.bound if self.most else value >= self.bound

    def short(self, value: float) -> float:
        """How far ``value`` lies from the bound, on the wrong side (0 when it meets it)."""
        return 0.0 if self.meets(value) else abs(value - self.bound)


TARGETS = (
    Target("balanced, mean", "balanced", 0.85, "mean"),
    Target("balanced, every shape", "balanced", 0.60, "each"),
    Target("partnered within 0.10, mean", "partnered_within_010", 0.90, "mean"),
    Target("unpartnered left unmapped, mean", "unpartnered_unmapped", 0.85, "mean"),
    Target("holes: partnered within 0.10, every shape", "partnered_within_010", 0.90, "each", kinds=("holes",)),
    Target("IoU best 0.80 on 90 % of the shapes", "iou", 0.80, "share", share=0.90),
    Target("seconds per shape", "seconds", 5.0, "each", most=True),
)
#: The columns of the targets' table.
HEADER = ("target", "measured", "short by", "kinds and classes short", "shapes short (per class)")
#: The per-shape targets a shape is listed for, with their short labels.
LISTED = {"balanced": TARGETS[1], "holes ≤0.10": TARGETS[4], "IoU": TARGETS[5]}


class MissingRows(Exception):
    """A cached row or the unary file the report needs is absent or unreadable."""


def load_rows(cache: Path, names: Sequence[Path], tag: str | None, overrides: Mapping) -> dict[tuple[str, str], dict]:
    """Every shape's cached row per method in :data:`METHODS`; raises :class:`MissingRows`
    naming the first one absent (or cached under another tag or other parameters)."""
    rows = {}
    for path in names:
        for method in METHODS:
            row = partial._cached(cache, path, method, partial._key(method, tag, overrides))
            if row is None:
                raise MissingRows(f"{partial._cache_file(cache, path, method)}: no row of tag {tag!r} (run partial.py)")
            rows[path.stem, method] = row
    return rows


def load_unary(paths: Sequence[Path]) -> dict[str, dict]:
    """``unary_partner.py``'s JSON rows of the default unary (``wks*spin``), by shape, from
    one or more files (two runs over the cuts and the holes, say)."""
    out = {}
    for path in paths:
        try:
            rows = json.loads(path.read_text())
            out |= {r["shape"]: r for r in rows if r["term"] == "wks*spin"}
        except (OSError, ValueError, TypeError, KeyError) as err:
            raise MissingRows(f"{path}: not unary_partner.py's --json rows ({err})") from None
    return out


def _values(
    rows: Mapping[tuple[str, str], dict], names: Sequence[str], key: str, method: str = "intrinsym"
) -> np.ndarray:
    return np.array([partial._value(rows[n, method], key) for n in names])


def _shapes(count: int) -> str:
    return f"{count} shape" if count == 1 else f"{count} shapes"


def _by_class(names: Sequence[str]) -> str:
    counts = Counter(partial._group(n)[1] for n in names)
    return ", ".join(f"{c} {k}" for c, k in sorted(counts.items()))


def summary(target: Target, values: np.ndarray) -> float:
    """What ``target`` judges of a set of shapes' ``values``: their mean ("mean"), the
    share that meets the bound ("share") or the worst ("each")."""
    if target.scope == "mean":
        return float(values.mean())
    if target.scope == "share":
        return float(np.mean([target.meets(v) for v in values]))
    return float(values.max() if target.most else values.min())


def summary_meets(target: Target, value: float) -> bool:
    return value >= target.share if target.scope == "share" else target.meets(value)


def target_row(target: Target, rows: Mapping[tuple[str, str], dict], names: Sequence[str]) -> dict[str, str]:
    """One target's cells: measured, short by, the kinds and classes that miss it (with
    what :func:`summary` gives of them) and the shapes that miss it, counted per class."""
    names = [n for n in names if partial._group(n)[0] in target.kinds]
    values = _values(rows, names, target.key)
    names = [n for n, v in zip(names, values, strict=True) if np.isfinite(v)]  # a shape without the score
    values = values[np.isfinite(values)]
    missing = [n for n, v in zip(names, values, strict=True) if not target.meets(v)]
    if not len(values):
        return dict.fromkeys(HEADER, "–") | {HEADER[0]: _label(target), HEADER[1]: "no shape scored"}
    if target.scope == "mean":
        text = f"{values.mean():.3f} over {len(values)} shapes"
        short = f"{target.short(float(values.mean())):.3f}"
    elif target.scope == "share":
        needed = int(np.ceil(target.share * len(values)))
        met = len(values) - len(missing)
        text = f"{met} of {len(values)} ({met / len(values):.0%})"
        short = _shapes(needed - met)
    elif target.most:
        text = f"median {np.median(values):.1f}, {values.min():.1f}-{values.max():.1f}"
        short = f"up to {values.max() / target.bound:.1f}x"
    else:
        text = f"{len(missing)} of {len(values)} short, lowest {values.min():.3f}"
        short = f"up to {target.short(float(values.min())):.3f}"
    groups = partial.kinds_and_classes(names)
    if len(target.kinds) == 1:  # the one kind's group is all the shapes: the classes alone
        del groups[target.kinds[0]]
    worse = []
    for group, members in groups.items():
        value = summary(target, _values(rows, members, target.key))
        if not summary_meets(target, value):
            worse.append(f"{group} {_format(target, value)}")
    cells = (
        _label(target),
        text,
        short if not summary_meets(target, summary(target, values)) else "met",
        ", ".join(worse) or "none",
        f"{len(missing)}: {_by_class(missing)}" if missing else "none",
    )
    return dict(zip(HEADER, cells, strict=True))


def _format(target: Target, value: float) -> str:
    """What :func:`summary` gives, as the table shows it."""
    return f"{value:.0%}" if target.scope == "share" else f"{value:.1f}" if target.most else f"{value:.3f}"


def _label(target: Target) -> str:
    return f"{target.name} ({'≤' if target.most else '≥'} {target.bound:g})"


def baseline_row(rows: Mapping[tuple[str, str], dict], names: Sequence[str]) -> dict[str, str]:
    """The target "ahead of both baselines on the mean balanced score, per class and kind"."""
    behind, margins = [], []
    for group, members in partial.kinds_and_classes(names).items():
        ours = float(np.mean(_values(rows, members, "balanced")))
        best = max(float(np.mean(_values(rows, members, "balanced", m))) for m in ("none", "pyfm"))
        margins.append((ours - best, group))
        if ours <= best:
            behind.append(f"{group} {ours:.3f} against {best:.3f}")
    margin, group = min(margins)
    cells = (
        "ahead of none and pyFM on the mean balanced score, every kind and class",
        f"ahead on {len(margins) - len(behind)} of {len(margins)}; least margin {margin:.3f} ({group})",
        "met" if not behind else f"{len(behind)} groups",
        "; ".join(behind) or "none",
        "–",
    )
    return dict(zip(HEADER, cells, strict=True))


def kept_map(row: Mapping) -> str:
    """The map ``detect`` kept: global, the partial candidate its self-map record names, or
    nothing (no candidate counted)."""
    self_map = row.get("self_map")
    if self_map is None:
        return "global"
    trivial = "" if self_map.get("trivial_global") is None else ", global was trivial"
    source = "nothing" if self_map["source"] == "none" else f"partial: {self_map['source']}"
    return source + trivial


def shape_rows(rows: Mapping[tuple[str, str], dict], names: Sequence[str], unary: Mapping[str, dict]) -> list[dict]:
    """A row per shape that misses a per-shape target of :data:`LISTED`."""
    out = []
    for n in names:
        row = rows[n, "intrinsym"]
        applies = [label for label, t in LISTED.items() if partial._group(n)[0] in t.kinds]
        misses = [label for label in applies if not LISTED[label].meets(partial._value(row, LISTED[label].key))]
        if not misses:
            continue
        cells = {"shape": n, "misses": ", ".join(misses)}
        for key, label in (
            ("balanced", "balanced"),
            ("partnered_within_005", "partnered ≤0.05"),
            ("partnered_within_010", "≤0.10"),
            ("unpartnered_unmapped", "unpartnered unmapped"),
            ("iou", "IoU"),
        ):
            value = partial._value(row, key)
            cells[label] = "–" if np.isnan(value) else f"{value:.3f}"
        cells["map kept"] = kept_map(row)
        for key in UNARY if unary else ():
            cells[f"unary: {key}"] = f"{unary[n][key]:.2f}" if n in unary else "–"
        out.append(cells)
    return out


def explained(rows: Mapping[tuple[str, str], dict], names: Sequence[str], unary: Mapping[str, dict]) -> list[str]:
    """Medians of the unary's measures over the shapes below the balanced 0.60 and over
    those at or above it, one line each."""
    target = LISTED["balanced"]
    low = [n for n in names if n in unary and not target.meets(partial._value(rows[n, "intrinsym"], target.key))]
    high = [n for n in names if n in unary and target.meets(partial._value(rows[n, "intrinsym"], target.key))]
    lines = []
    for key in UNARY:
        medians = [f"{np.median([unary[n][key] for n in group]):.2f}" if group else "–" for group in (low, high)]
        lines.append(
            f"- {key}: median {medians[0]} over the {_shapes(len(low))} below balanced 0.60, "
            f"{medians[1]} over the {_shapes(len(high))} at or above"
        )
    return lines


def _table(cells: Sequence[Mapping[str, str]]) -> list[str]:
    if not cells:
        return ["(none)"]
    head = list(cells[0])
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + [
        "| " + " | ".join(c[h] for h in head) + " |" for c in cells
    ]


def report(rows: Mapping[tuple[str, str], dict], names: Sequence[str], unary: Mapping[str, dict]) -> str:
    """The Markdown report: the targets, then the shapes that miss a per-shape one."""
    targets = [target_row(t, rows, names) for t in TARGETS] + [baseline_row(rows, names)]
    lines = ["## Targets", "", *_table(targets), "", "## Shapes that miss a per-shape target", ""]
    lines += _table(shape_rows(rows, names, unary))
    if unary:
        lines += ["", *explained(rows, names, unary)]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(parser)
    parser.add_argument("--cache", type=Path, required=True, help="partial.py's --cache folder")
    parser.add_argument("--tag", help="partial.py's --tag of the rows")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="a Params field changed")
    parser.add_argument("--unary", type=Path, nargs="+", metavar="FILE", help="unary_partner.py's --json rows")
    parser.add_argument("-o", "--out", type=Path, help="also write the report here")
    args = parser.parse_args(argv)
    try:
        overrides = _overrides(args.param)
    except intrinsym.ParameterError as err:
        parser.error(f"--param {err}")
    data = partial.partial_data(args.data, "partial_targets.py")
    if data is None:
        return 0
    found = partial.shapes(data)
    try:
        rows = load_rows(args.cache, found, args.tag, overrides)
        unary = load_unary(args.unary or [])
    except MissingRows as err:
        print(f"partial_targets.py: {err}", file=sys.stderr)
        return 2
    text = report(rows, [p.stem for p in found], unary)
    print(text, end="")
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
