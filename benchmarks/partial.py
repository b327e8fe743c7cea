"""Partial symmetry on the SHREC'16 cuts and holes, beside "no partner anywhere" and pyFM.

Runs the default :func:`intrinsym.detect` (seed 0) on every partial shape of
``shrec16_partial/{cuts,holes}`` and scores its ``symmetry_map`` with the protocol of
:mod:`intrinsym.evaluation.partial_truth` (distances in units of sqrt(area) of the null shape):
the partnered share within 0.05 and 0.10, the unpartnered share left unmapped, their
balance (mean of the first and the third) and the IoU of the best-ranked symmetry's
parts with the truth's partnered vertices; two diagnostics: where the map gives an
unpartnered vertex an image, the share of those images that are unpartnered themselves,
and (cached, not tabulated) ``map_kept``, the share of the shape's short distances the
map keeps (what a part's match calibrates its confidence on), and ``self_map`` with
``self_map_seconds``, which partial symmetry map ``detect`` kept without a global
symmetry (``run.json``'s record) and what it cost. Beside it, two baselines: "no partner
anywhere" (every vertex -1) and the peer a user would pick, pyFM's orientation-reversing
self-map (PyPI ``pyfmaps``: WKS, ``fit(w_orient=1, orient_reversing=True)``, ZoomOut
20 -> 100), which maps every vertex. Command::

    OPENBLAS_NUM_THREADS=1 python benchmarks/partial.py --data DATA [--cache DIR --tag TAG]
        [--shapes cuts_cat holes ...] [--jobs N] [--param NAME=VALUE ...] [--no-pyfm] [--cached] [-o TABLE.md]

``DATA`` holds ``shrec16_partial/`` (default ``$INTRINSYM_DATA``; skipped, exit 0, when
absent). ``--cached`` computes nothing and tabulates the shapes already in the cache.
``--shapes`` takes shape names (``cuts_cat_shape_1``) or prefixes (``cuts``,
``holes_dog``). ``--cache DIR`` keeps one JSON file per shape and method
(``DIR/<shape>.<method>.json``), reused when its tag, version and parameters match, so
an interrupted run resumes; pyFM's rows are kept across tags. ``--jobs N`` runs N shapes
at once in separate processes.

Output: one Markdown table, a row per shape, then the mean and worst rows per kind
(cuts / holes), per class and over all shapes.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

import numpy as np

import intrinsym
from _data import add_data_argument, data_folder, no_data
from intrinsym.evaluation import partial_truth
from intrinsym.extract import records
from intrinsym.globalmap import confidence, distortion, part_map
from tosca import _clean_floats, _machine, _overrides, score_histogram

#: Cache-format revision: a file with another one is recomputed.
CACHE_FORMAT = 1
#: Scores of a row, with their table headers and the methods that have them (None: all).
SCORES = (
    ("balanced", "balanced", None),
    ("partnered_within_005", "partnered ≤0.05", None),
    ("partnered_within_010", "partnered ≤0.10", None),
    ("unpartnered_unmapped", "unpartnered unmapped", None),
    ("unpartnered_onto_unpartnered", "mapped unpartnered onto unpartnered", ("intrinsym",)),
    ("iou", "IoU best", ("intrinsym", "pyfm")),
)


def shapes(data: Path) -> list[Path]:
    """Every partial shape under ``data/shrec16_partial``, cuts then holes, by class and number."""

    def key(p: Path) -> tuple:
        kind, cls, _, k = p.stem.split("_")
        return kind, cls, int(k)

    return sorted((data / "shrec16_partial").glob("*/*_shape_*.off"), key=key)


def partial_data(data: Path | None, script: str) -> Path | None:
    """The research data folder (``--data``, else ``$INTRINSYM_DATA``) when it holds
    ``shrec16_partial/``; else None, after printing ``script``'s skip line."""
    found = data_folder(data)
    if found is None or not (found / "shrec16_partial").is_dir():
        print(no_data(script, data))
        return None
    return found


def select(found: list[Path], names: list[str] | None) -> list[Path]:
    """The shapes named (exactly, or by a prefix of their name)."""
    if not names:
        return found
    return [p for p in found if any(p.stem == n or p.stem.startswith(n + "_") for n in names)]


def pyfm_map(shape: intrinsym.Shape) -> np.ndarray:
    """(N,) int64: pyFM's orientation-reversing self-map of ``shape`` (WKS, ZoomOut 20 -> 100)."""
    from pyFM.functional import FunctionalMapping
    from pyFM.mesh import TriMesh

    mesh = TriMesh(np.asarray(shape.vertices), np.asarray(shape.faces))
    model = FunctionalMapping(mesh, mesh)
    model.preprocess(n_descr=100, descr_type="WKS", subsample_step=5, k_process=100, verbose=False)
    model.fit(K=(20, 20), w_descr=1.0, w_lap=1e-2, w_dcomm=1e-1, w_orient=1.0, orient_reversing=True, verbose=False)
    model.zoomout_refine(nit=16, step=5, verbose=False)
    return np.asarray(model.get_p2p(), dtype=np.int64)


def best_parts(result: intrinsym.Result, n: int) -> np.ndarray | None:
    """(n,) bool: the input vertices of the best-ranked symmetry's two parts; None without one."""
    if result.extraction is None or result.support is None or not result.extraction.symmetries:
        return None
    return records.part_mask(result.symmetry_records()[0], n)


def run(path: Path, method: str, overrides: Mapping) -> dict:
    """One shape scored under ``method`` ("intrinsym", "none" or "pyfm")."""
    shape, truth = partial_truth.load_shrec16(path)
    row: dict = {"shape": path.stem, "class": _group(path.stem)[1], "method": method, "vertices": len(shape.vertices)}
    row["partnered_share"] = float(truth.partnered.mean())
    start = time.perf_counter()
    iou, result = float("nan"), None
    if method == "none":
        vmap = np.full(len(shape.vertices), -1, dtype=np.int64)
    elif method == "pyfm":
        vmap = pyfm_map(shape)
        iou = partial_truth.part_iou(np.ones(len(vmap), dtype=bool), truth)
    else:
        result = intrinsym.detect(shape, intrinsym.make_params(**overrides))
        vmap = result.symmetry_map()
    row["seconds"] = time.perf_counter() - start
    scores = partial_truth.score_partial(vmap, shape, truth)
    if result is not None:
        parts = best_parts(result, len(vmap))
        iou = 0.0 if parts is None else partial_truth.part_iou(parts, truth)
        row["coverage"] = float((vmap >= 0).mean())
        scored, right = _right(vmap, truth, scores)  # right: partnered, within 0.05 of the partner
        row["confidence"] = confidence_row(result.symmetry_confidence()[scored], right)
        row["reliability"] = reliability(result, vmap, truth, scores)
        # what a part's match calibrates its confidence on (part_map.PART_MAP_RADIUS / _CHANGE),
        # recorded to see whether it also tells a right self-map from a wrong one
        kept = distortion.map_distortion(vmap, shape, part_map.PART_MAP_RADIUS).above(part_map.PART_MAP_CHANGE)
        row["map_kept"] = 1.0 - kept if np.isfinite(kept) else None
        # which partial symmetry map detect kept without a global symmetry, and its cost
        row["self_map"] = None if result.info.self_map is None else dataclasses.asdict(result.info.self_map)
        row["self_map_seconds"] = result.info.seconds.get("self map")
    # where the unpartnered vertices the map gives an image are sent: onto the unpartnered
    # remains themselves (a self-map of what has no partner) or onto the partnered rest
    sent = vmap[truth.unpartnered & (vmap >= 0)]
    row["unpartnered_onto_unpartnered"] = float(truth.unpartnered[sent].mean()) if len(sent) else None
    row.update(scores.as_dict(), iou=iou)
    return row


def _right(vmap: np.ndarray, truth: partial_truth.PartialTruth, scores: partial_truth.PartialMapScores) -> tuple:
    """The scored vertices with an image, and whether each image is right: the vertex is
    partnered and its image within 0.05 of the partner (a vertex without a partner has no
    right image)."""
    errors = np.full(len(vmap), np.inf)
    errors[truth.partnered] = scores.errors
    scored = (vmap >= 0) & (truth.partner != partial_truth.NOT_SCORED)
    return scored, errors[scored] <= 0.05


def reliability(
    result: intrinsym.Result,
    vmap: np.ndarray,
    truth: partial_truth.PartialTruth,
    scores: partial_truth.PartialMapScores,
) -> dict | None:
    """Per bin of the symmetry map's per-vertex score (``symmetry_score``), how many
    scored vertices with an image fall in it and how many of those are right
    (:func:`_right`), the histogram ``benchmarks/calibration.py`` fits, as
    ``benchmarks/tosca.py`` records it, keyed by the dominant symmetry's kind
    (``partial_score``: a partial symmetry's map, ``score``: a global one); None
    without a dominant symmetry."""
    sym = None if result.extraction is None else result.extraction.dominant_symmetry
    if sym is None:
        return None
    scored, right = _right(vmap, truth, scores)
    histogram = score_histogram(result.symmetry_score()[scored], {"within_0.05": right})
    return {"score" if sym.kind == "global" else "partial_score": histogram}


def confidence_row(conf: np.ndarray, right: np.ndarray) -> dict:
    """A confidence's calibration over the vertices it is given: ECE, mean and count;
    ``right`` says which of their images are right."""
    if not len(conf):
        return {"ece": None, "mean": None, "n": 0}
    ece, _ = confidence.calibration(conf, right)
    return {"ece": ece, "mean": float(conf.mean()), "n": int(len(conf))}


def _cache_file(cache: Path, path: Path, method: str) -> Path:
    return cache / f"{path.stem}.{method}.json"


def _key(method: str, tag: str | None, overrides: Mapping) -> dict:
    if method in ("none", "pyfm"):  # the baselines: no code of ours, no tag
        return {"method": method, "cache_format": CACHE_FORMAT}
    return {
        "method": method,
        "tag": tag,
        "version": intrinsym.__version__,
        "overrides": dict(overrides),
        "cache_format": CACHE_FORMAT,
    }


def _cached(cache: Path | None, path: Path, method: str, key: dict) -> dict | None:
    if cache is None or not _cache_file(cache, path, method).is_file():
        return None
    row = json.loads(_cache_file(cache, path, method).read_text())
    return row if all(row.get(k) == v for k, v in key.items()) else None


#: One shape under one method with the Params overrides: its row.
Runner = Callable[[Path, str, Mapping], dict]


def _work(path: Path, method: str, cache: Path | None, key: dict, overrides: Mapping, runner: Runner) -> dict:
    """Worker: one shape and method, written to the cache (atomically) when there is one."""
    try:
        row = {**runner(path, method, overrides), **key, "machine": _machine()}
    except Exception as err:  # a failed shape is a row, not the end of the run
        row = {"shape": path.stem, "method": method, "error": f"{type(err).__name__}: {err}"}
        traceback.print_exc()
    row = _clean_floats(row)
    if cache is not None and "error" not in row:
        cache.mkdir(parents=True, exist_ok=True)
        tmp = cache / f".{path.stem}.{method}.tmp{os.getpid()}"
        tmp.write_text(json.dumps(row, indent=1))
        os.replace(tmp, _cache_file(cache, path, method))
    return row


def _group(stem: str) -> tuple[str, str]:
    kind, cls, _, _ = stem.split("_")
    return kind, cls


def kinds_and_classes(names: Sequence[str]) -> dict[str, list[str]]:
    """The shapes named per kind (cuts, holes), then per class, in the order found."""
    groups: dict[str, list[str]] = {}
    for index in (0, 1):
        for n in names:
            groups.setdefault(_group(n)[index], []).append(n)
    return groups


def _value(row: dict | None, key: str) -> float:
    value = None if row is None else row.get(key)
    return float("nan") if value is None else float(value)


def markdown(rows: dict[tuple[str, str], dict], names: list[str], methods: list[str]) -> str:
    """The table: a row per shape, then mean and worst per kind, per class and overall."""
    head = ["shape", "partnered share"]
    columns = [(key, m) for key, _, have in SCORES for m in methods if have is None or m in have]
    labels = {key: label for key, label, _ in SCORES}
    head += [f"{labels[key]} ({m})" for key, m in columns]
    head += ["seconds (intrinsym)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def cells(name_rows: list[str], agg) -> list[str]:
        out = [f"{agg(np.array([_value(rows.get((n, 'intrinsym')), 'partnered_share') for n in name_rows])):.3f}"]
        for key, m in columns:
            values = np.array([_value(rows.get((n, m)), key) for n in name_rows])
            out.append("–" if np.all(np.isnan(values)) else f"{agg(values):.3f}")
        seconds = np.array([_value(rows.get((n, "intrinsym")), "seconds") for n in name_rows])
        out.append(f"{np.nanmax(seconds) if agg is np.nanmin else np.nanmean(seconds):.1f}")
        return out

    for n in names:
        lines.append("| " + " | ".join([n, *cells([n], np.nanmean)]) + " |")
    groups = kinds_and_classes(names)
    groups["all"] = list(names)
    for g, members in groups.items():
        if len(members) > 1:
            lines.append("| " + " | ".join([f"**mean {g}** ({len(members)})", *cells(members, np.nanmean)]) + " |")
            lines.append("| " + " | ".join([f"worst {g}", *cells(members, np.nanmin)]) + " |")
    return "\n".join(lines) + "\n"


def run_script(
    argv: list[str] | None,
    doc: str,
    methods: list[str],
    runner: Runner,
    table: Callable[[dict[tuple[str, str], dict], list[str], list[str]], str],
    status: str,
    cache_folder: str | None = None,
    optional: Mapping[str, str] | None = None,
) -> int:
    """The command line of a SHREC'16 script (this one's, ``shrec16_match.py``'s): the
    options, the cache, the runs (``runner`` per shape and method, pyFM's after
    ``methods`` unless ``--no-pyfm``), the progress lines (the row's ``status`` score)
    and the table; exit 1 when a run failed. ``cache_folder``: a subfolder of ``--cache``
    for this script's files; ``optional``: further methods, each run when its flag
    (``--NAME``, the value its help) is given."""
    script = Path(str(sys.modules[runner.__module__].__file__)).name
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    add_data_argument(parser)
    parser.add_argument("--shapes", nargs="+", metavar="NAME", help="shape names or prefixes (default: all)")
    parser.add_argument("--jobs", type=int, default=1, help="shapes run at once (default 1)")
    parser.add_argument("--cache", type=Path, help="folder of per-shape JSON results, reused when present")
    parser.add_argument("--tag", help="code tag recorded in (and required of) the cached results")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="a Params field changed")
    parser.add_argument("--no-pyfm", action="store_true", help="leave out the pyFM baseline")
    parser.add_argument("--cached", action="store_true", help="compute nothing: the table of the cached shapes")
    parser.add_argument("-o", "--out", type=Path, help="also write the Markdown table here")
    for name, text in (optional or {}).items():
        parser.add_argument(f"--{name}", action="store_true", help=text)
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    try:
        overrides = _overrides(args.param)
    except intrinsym.ParameterError as err:
        parser.error(f"--param {err}")
    data = partial_data(args.data, script)
    if data is None:
        return 0
    cache = args.cache / cache_folder if args.cache is not None and cache_folder else args.cache
    todo = select(shapes(data), args.shapes)
    methods = methods + [name for name in optional or {} if getattr(args, name)] + ([] if args.no_pyfm else ["pyfm"])
    rows: dict[tuple[str, str], dict] = {}
    pending = []
    for path in todo:
        for method in methods:
            key = _key(method, args.tag, overrides)
            row = _cached(cache, path, method, key)
            if row is not None:
                rows[path.stem, method] = row
            else:
                pending.append((path, method, key))
    if args.cached:
        done_shapes = {name for name, method in rows if method == "intrinsym"}
        todo, pending = [p for p in todo if p.stem in done_shapes], []
    start = time.perf_counter()

    def done(row: dict) -> None:
        rows[row["shape"], row["method"]] = row
        line = row.get("error") or f"{status} {_value(row, status):.3f}, {_value(row, 'seconds'):.1f} s"
        print(f"{row['shape']} {row['method']}: {line} [{time.perf_counter() - start:.0f} s]", file=sys.stderr)

    if args.jobs == 1:
        for path, method, key in pending:
            done(_work(path, method, cache, key, overrides, runner))
    else:
        with ProcessPoolExecutor(args.jobs, mp_context=get_context("spawn")) as pool:
            futures = [pool.submit(_work, path, method, cache, key, overrides, runner) for path, method, key in pending]
            for future in as_completed(futures):
                done(future.result())
    text = table(rows, [p.stem for p in todo], methods)
    print(text, end="")
    if args.out:
        args.out.write_text(text)
    return 1 if any("error" in r for r in rows.values()) else 0


def main(argv: list[str] | None = None) -> int:
    return run_script(argv, __doc__, ["intrinsym", "none"], run, markdown, "balanced")


if __name__ == "__main__":
    sys.exit(main())
