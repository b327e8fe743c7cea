"""Calibrate the per-vertex marginal mass into a confidence, and check it class by class.

Reads the per-shape rows that ``benchmarks/tosca.py`` caches (``--cache DIR``): each row
with a global map holds histograms of the symmetry map's per-vertex score
(``symmetry_score``: the marginal mass weighed by how far two global maps agree) and of
its marginal mass alone (``symmetry_mass``), :data:`tosca.MASS_BINS` equal-width bins,
with, per bin, how many vertices map within 0.05 of their true image; ``score_split``
holds the score's bins once per bin of the global map's local distortion
(``Result.map_distortion``, :data:`intrinsym.globalmap.confidence.DISTORTION_BINS`).
``--feature partial_score`` reads ``benchmarks/partial.py``'s cache instead: the score
of the SHREC'16 shapes whose dominant symmetry is partial, "within 0.05" of the true
partner (a vertex without one never is), the rows of
:data:`intrinsym.globalmap.confidence.PARTIAL_CALIBRATION`; ``--feature match_score``
reads ``benchmarks/shrec16_match.py``'s (``DIR/match``): the score of each SHREC'16
partial shape's map onto its null shape, "within 0.05" of the nearer of the true and
the mirror point; ``--feature part_kept`` the same pairs by the share of the part's short
distances its map keeps (``run.json``'s ``part_map``), the rows of
:data:`intrinsym.globalmap.confidence.PART_CALIBRATION`. From the
``--feature`` chosen (default ``score_split``, what the package calibrates) it

1. fits the calibration on every shape: the isotonic (non-decreasing) regression of "within
   0.05" on the bin centres, weighted by the vertex counts, one per group of bins; these
   values are the tables of :data:`intrinsym.globalmap.confidence.CALIBRATION` (the script says
   whether the package's copy is the fit, and prints the fit to paste when it is not);
2. checks it leaving one class out: for each class, the fit on the other classes is
   applied to that class's vertices; the table gives the expected calibration error (10
   equal-width confidence bins) of the raw mass and of the calibrated confidence, and the
   predicted against the measured share of vertices within 0.05 (the global confidence);
3. prints the pooled reliability table of the held-out confidences;
4. for a feature the package calibrates, says how the package's own table fits these rows
   (a table fitted on other maps, e.g. before a change of the code that makes them).

Every vertex of a mass bin takes the confidence of the bin's centre (the histogram holds
no finer mass). Command::

    python benchmarks/calibration.py --cache DIR [--tag TAG] [-o TABLE.md]
        [--feature score_split|score|mass|partial_score|match_score|part_kept]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import isotonic_regression

from intrinsym.globalmap import confidence

#: Equal-width confidence bins of the expected calibration error.
ECE_BINS = 10


def load_rows(cache: Path, tag: str | None, feature: str = "score") -> list[dict]:
    """The cached rows with a reliability histogram of ``feature`` (and the given tag),
    that histogram as the row's ``reliability``."""
    rows = []
    for path in sorted(cache.glob("*.json")):
        row = json.loads(path.read_text())
        histogram = (row.get("reliability") or {}).get(feature)
        if histogram and (tag is None or row.get("tag") == tag):
            rows.append({**row, "reliability": histogram})
    return rows


def histogram(rows: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """Summed vertex counts and counts within 0.05 per mass bin."""
    count = np.sum([r["reliability"]["count"] for r in rows], axis=0).astype(np.float64)
    within = np.sum([r["reliability"]["within_0.05"] for r in rows], axis=0).astype(np.float64)
    return count, within


def centres(n_bins: int) -> np.ndarray:
    return (np.arange(n_bins) + 0.5) / n_bins


def bin_centres(rows: list[dict]) -> np.ndarray:
    """The score at the centre of every bin of the rows' histograms (each group's bins in turn)."""
    histogram = rows[0]["reliability"]
    bins = histogram.get("bins", len(histogram["count"]))
    return np.tile(centres(bins), len(histogram["count"]) // bins)


def _isotonic(count: np.ndarray, within: np.ndarray) -> np.ndarray:
    has = count > 0
    values = np.empty(len(count))
    values[has] = isotonic_regression(within[has] / count[has], weights=count[has]).x
    return np.interp(centres(len(count)), centres(len(count))[has], values[has])


def fit(rows: list[dict]) -> np.ndarray:
    """Isotonic fit of the share within 0.05 per mass bin (empty bins take their
    neighbours'), one fit per group of bins (``score_split``: one per bin of the map's
    local distortion, in turn)."""
    count, within = histogram(rows)
    bins = rows[0]["reliability"].get("bins", len(count))
    return np.concatenate([_isotonic(count[g : g + bins], within[g : g + bins]) for g in range(0, len(count), bins)])


def ece(conf: np.ndarray, count: np.ndarray, within: np.ndarray) -> float:
    """Expected calibration error of a per-bin confidence (10 equal-width bins)."""
    which = np.minimum((conf * ECE_BINS).astype(np.int64), ECE_BINS - 1)
    total, err = count.sum(), 0.0
    for b in range(ECE_BINS):
        inside = which == b
        n = count[inside].sum()
        if n:
            err += n / total * abs(within[inside].sum() / n - (conf[inside] * count[inside]).sum() / n)
    return err


def global_confidences(rows: list[dict], table: np.ndarray) -> list[tuple[str, float, float]]:
    """Per row: its shape, its global confidence under ``table`` (the mean over its
    vertices) and its measured share within 0.05; a map that gives no scored vertex an
    image (nothing to be sure of) left out."""
    out = []
    for r in rows:
        c = np.asarray(r["reliability"]["count"], dtype=np.float64)
        w = np.asarray(r["reliability"]["within_0.05"], dtype=np.float64)
        if c.sum():
            out.append((r["shape"], float((table * c).sum() / c.sum()), float(w.sum() / c.sum())))
    return out


def leave_one_class_out(rows: list[dict]) -> tuple[list[dict], np.ndarray, np.ndarray, np.ndarray]:
    """Per class: ECE of the raw mass and of the held-out calibration, and the global
    confidence against the measured share; plus the pooled held-out bins."""
    classes = sorted({r["class"] for r in rows})
    out, pooled_conf, pooled_count, pooled_within = [], [], [], []
    for cls in classes:
        test = [r for r in rows if r["class"] == cls]
        train = [r for r in rows if r["class"] != cls]
        calib = fit(train)
        count, within = histogram(test)
        mass = bin_centres(test)
        out.append(
            {
                "class": cls,
                "shapes": len(test),
                "ece_mass": ece(mass, count, within),
                "ece_calibrated": ece(calib, count, within),
                "global": global_confidences(test, calib),
            }
        )
        pooled_conf.append(calib)
        pooled_count.append(count)
        pooled_within.append(within)
    return out, np.concatenate(pooled_conf), np.concatenate(pooled_count), np.concatenate(pooled_within)


def table_fit(rows: list[dict], table: np.ndarray) -> dict:
    """How a fixed table (the package's) fits the rows, none held out: the pooled ECE, each
    class's ECE, and the mean absolute difference between a shape's global confidence and
    its measured share within 0.05 (shapes whose map scores no vertex left out)."""
    count, within = histogram(rows)
    per_class = {}
    for cls in sorted({r["class"] for r in rows}):
        c, w = histogram([r for r in rows if r["class"] == cls])
        per_class[cls] = ece(table, c, w)
    gap = np.mean([abs(predicted - measured) for _, predicted, measured in global_confidences(rows, table)])
    return {"ece": ece(table, count, within), "per_class": per_class, "global_gap": float(gap)}


def markdown(rows: list[dict]) -> str:
    per_class, conf, count, within = leave_one_class_out(rows)
    lines = [
        "| held-out class | shapes | ECE uncalibrated | ECE calibrated | global confidence − measured, worst |",
        "|---|---|---|---|---|",
    ]
    for c in per_class:
        worst = max(c["global"], key=lambda s: abs(s[1] - s[2]))
        lines.append(
            f"| {c['class']} | {c['shapes']} | {c['ece_mass']:.3f} | {c['ece_calibrated']:.3f} | "
            f"{worst[1] - worst[2]:+.3f} ({worst[0]}: {worst[1]:.3f} vs {worst[2]:.3f}) |"
        )
    mass = np.tile(bin_centres(rows), len(per_class))
    lines.append(
        f"| **all, held out** | {len(rows)} | {ece(mass, count, within):.3f} | {ece(conf, count, within):.3f} | "
        f"mean abs {np.mean([abs(s[1] - s[2]) for c in per_class for s in c['global']]):.3f} |"
    )
    table = ["| confidence bin | share of vertices | mean confidence | within 0.05 |", "|---|---|---|---|"]
    which = np.minimum((conf * ECE_BINS).astype(np.int64), ECE_BINS - 1)
    for b in range(ECE_BINS):
        inside = which == b
        n = count[inside].sum()
        if n:
            table.append(
                f"| {b / ECE_BINS:.1f}-{(b + 1) / ECE_BINS:.1f} | {n / count.sum():.3f} | "
                f"{(conf[inside] * count[inside]).sum() / n:.3f} | {within[inside].sum() / n:.3f} |"
            )
    return "\n".join(lines) + "\n\nPooled held-out reliability:\n\n" + "\n".join(table) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cache", type=Path, required=True, help="benchmarks/tosca.py's cache folder")
    parser.add_argument("--tag", help="only rows with this tag")
    parser.add_argument(
        "--feature",
        choices=("score_split", "score", "mass", "partial_score", "match_score", "part_kept"),
        default="score_split",
        help="what is calibrated (score_split: the score, one table per bin of the map's local distortion; "
        "partial_score: the score of partial symmetries' maps, from benchmarks/partial.py's cache; "
        "match_score: the score of parts' maps onto their wholes, from benchmarks/shrec16_match.py's; "
        "part_kept: the share of a part's short distances its map keeps, from the same)",
    )
    parser.add_argument("-o", "--out", type=Path, help="also write the Markdown here")
    args = parser.parse_args(argv)
    rows = load_rows(args.cache, args.tag, args.feature)
    if len({r["class"] for r in rows}) < 2:
        print(f"calibration.py: need rows of at least two classes with a {args.feature} histogram in {args.cache}")
        return 1
    text = markdown(rows)
    values = fit(rows)
    # the features the package calibrates, with their tables; the others are diagnostics
    shipped_tables = {
        "score_split": ("CALIBRATION", confidence.CALIBRATION),
        "partial_score": ("PARTIAL_CALIBRATION", (confidence.PARTIAL_CALIBRATION,)),
        "part_kept": ("PART_CALIBRATION", (confidence.PART_CALIBRATION,)),
    }
    name, tables = shipped_tables.get(args.feature, (args.feature.upper(), ()))
    if tables:
        shipped = np.concatenate(tables)
        same = values.shape == shipped.shape and np.allclose(values, shipped, atol=5e-4)
        compared = f"{'equal to' if same else 'differs from'} intrinsym.globalmap.confidence.{name}"
        if shipped.shape == values.shape:
            held = table_fit(rows, shipped)
            classes = ", ".join(f"{c} {v:.3f}" for c, v in held["per_class"].items())
            text += (
                f"\nThe package's {name} on these rows (fitted elsewhere, none held out): pooled ECE "
                f"{held['ece']:.3f} ({classes}), global confidence − measured, mean abs {held['global_gap']:.3f}\n"
            )
    else:
        compared = "no table of the package"
    text += f"\nFit on all {len(rows)} shapes ({compared}):\n\n"
    groups = np.split(values, len(values) // rows[0]["reliability"].get("bins", len(values)))
    text += f"{name} = (\n" + "".join(f"    ({', '.join(f'{v:.3f}' for v in t)}),\n" for t in groups) + ")\n"
    print(text)
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
