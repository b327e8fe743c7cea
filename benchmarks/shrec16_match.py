"""Partial-to-full matching on SHREC'16 (cuts, holes), beside pyFM, with both answers scored.

Runs the default :func:`intrinsym.match` (seed 0: the common unit, a part's unary
``partial_unary``) of every partial shape of ``shrec16_partial/{cuts,holes}`` to its null
shape and scores it with the SHREC'16 convention: per vertex of the partial shape, the
geodesic distance on the null shape (mesh edges, :func:`intrinsym.evaluation.partial_truth.edge_graph`)
from the predicted image to the nearer of its true point and its mirror point (each taken
at its nearest null vertex), in units of sqrt(area(null)); the shares within 0.05, 0.10 and 0.25 and the
mean (over mapped vertices; an unmapped vertex counts as a miss in the shares).

Beside it, pyFM from partial to full (PyPI ``pyfmaps``: WKS, ``fit``, ZoomOut 20 ->
100), and the scores of intrinsym's marginals and modes: per source sample whose true
and mirror points lie more than 0.10 apart, the share whose marginal (the marginals
given each mode, mixed: :meth:`intrinsym.Result.mixed_marginals`) puts at least 0.1 of its mass
within 0.05 of each ("both modes"), of the true one alone and
of the mirror one alone; whether mode 0 is the true answer (more of the far-apart
vertices within 0.10 of the true point than of the mirror point; its mean over pairs is
the frequency mode 0's confidence claims); and the two maps of
:func:`intrinsym.result.modes.two_modes`:
per partial vertex whose true and mirror points lie more than 0.10 apart, the share
where one mode lies within 0.05 (0.10) of the true point and the other of the mirror
point, both modes holding at least 0.1 of the confidence ("both answers"). Every match
is given its null shape's own symmetry map (``target_symmetry``: the default
:func:`intrinsym.detect` of the null shape, run once per class and process, its seconds
``null_detect_seconds`` not in the pair's), so mode 1 is that symmetry after mode 0, and
its null shape prepared once per class and process (:func:`intrinsym.prepare`, its seconds
``null_prepare_seconds`` not in the pair's; the first pair's match solves the eigenpairs
the others share: the same maps as a match of the two files); the
same scores without it (mode 1 from the marginals and the extraction) beside them.

The reverse direction, ``match(null, partial)``, whose vertex map is the inverse of this
run's (:func:`intrinsym.pipeline.invert_part_match`, what ``match`` computes for a part
target; so it is scored from this run rather than solved again): per shape, the
convention (true or mirror answer) under which more of the matched null vertices lie
within 0.10 of their image's answer point; under it, the null vertices farther than
:data:`CUT` from every partial vertex's answer point (cut away) and those within
:data:`KEPT` (kept; the band between is not scored); the share of the cut-away ones left
unmatched (-1), of the kept ones matched, and of the matched kept ones within 0.10 of the
nearer answer; and the same shares at other reaches of the inversion (:data:`REACHES`,
the margin of ``COVER_SPACINGS``), in a second table. With ``--reverse`` the script also
times ``match(null, partial)`` itself (method "reverse": its seconds and stages, and the
same reverse scores of the map it returns).

With ``--truth`` (method "truth") the script also weighs the true map as ``match`` weighs
its candidate maps of a part (:func:`intrinsym.globalmap.part_map.least_distorted`: the
share of the part's short geodesic distances a map changes, on the meshes ``match``
prepares), the lower of the true and the mirror answer's (each partial vertex sent to the
null vertex nearest its point), beside the share of the map ``match`` kept; a line under
the table counts the pairs within 0.10 on less than :data:`RIGHT` of their vertices on
which the true map changes fewer of them by more than :data:`MARGIN` (the search never
offered it: the test would have kept it) and those on which it does not (the test would
not keep it). Command::

    OPENBLAS_NUM_THREADS=1 python benchmarks/shrec16_match.py --data DATA [--cache DIR --tag TAG]
        [--shapes cuts_cat holes ...] [--jobs N] [--param NAME=VALUE ...] [--no-pyfm] [--reverse]
        [--truth] [-o TABLE.md]

``DATA`` holds ``shrec16_partial/`` (default ``$INTRINSYM_DATA``; skipped, exit 0, when
absent). ``--shapes`` and ``--cache`` as in ``benchmarks/partial.py`` (one JSON file per
shape and method, ``DIR/match/<shape>.<method>.json``, reused when its tag, version and
parameters match, so an interrupted run resumes). ``--jobs N`` runs N at once.

Output: one Markdown table, a row per shape, then the mean and worst rows per kind,
per class and over all shapes.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

import intrinsym
from intrinsym.evaluation import evaluate, partial_truth
from intrinsym.globalmap.part_map import least_distorted
from intrinsym.mesh.shape import surface_area
from intrinsym.pipeline import COVER_SPACINGS, invert_part_match
from intrinsym.pipeline.inputs import min_vertices
from intrinsym.result import modes
from intrinsym.surface import prepare_pair
from partial import _group, _value, confidence_row, run_script
from tosca import score_histogram

#: The contest's thresholds (units of sqrt(area(null))).
THRESHOLDS = (0.05, 0.10, 0.25)
#: A source sample scores "both modes" when its true and mirror points are this far apart ...
FAR = 0.10
#: ... and its marginal holds at least MODE_MASS within MODE_RADIUS of each.
MODE_MASS = 0.1
MODE_RADIUS = 0.05
#: A null vertex farther than CUT from every partial vertex's answer point is cut away,
#: one within KEPT is kept (issue 46's protocol band, partial_truth.PARTNERED / UNPARTNERED).
KEPT, CUT = partial_truth.PARTNERED, partial_truth.UNPARTNERED
#: The inversion's reaches (sample spacings) scored: the default's and others (its margin).
REACHES = (1.0, 1.5, 2.0, 3.0, 4.0, float("inf"))
assert COVER_SPACINGS in REACHES
#: Scores whose worst is the highest.
LOWER_IS_BETTER = ("mean_error", "kept_changed", "truth_changed", "seconds")
#: A pair's map is wrong when it is within 0.10 on less than this share of the vertices...
RIGHT = 0.80
#: ... and the test that keeps a part's map would have kept the true map when that changes
#: fewer of the part's short distances than the kept map by more than this share.
MARGIN = 0.01
#: Scores of a row, with their table headers; the methods that have them.
SCORES = (
    ("within_005", "≤0.05", ("intrinsym", "pyfm")),
    ("within_010", "≤0.10", ("intrinsym", "pyfm")),
    ("within_025", "≤0.25", ("intrinsym", "pyfm")),
    ("mean_error", "mean error", ("intrinsym", "pyfm")),
    ("both_modes", "both modes", ("intrinsym",)),
    ("true_only", "true mode only", ("intrinsym",)),
    ("answers_005", "both answers ≤0.05", ("intrinsym",)),
    ("answers_010", "both answers ≤0.10", ("intrinsym",)),
    ("answers_005_alone", "both answers ≤0.05, no target symmetry", ("intrinsym",)),
    ("confidence0", "confidence mode 0", ("intrinsym",)),
    ("mode0_true", "mode 0 is the true answer", ("intrinsym",)),
    ("cut_unmatched", "reverse: cut-away unmatched", ("intrinsym", "reverse")),
    ("kept_matched", "reverse: kept matched", ("intrinsym", "reverse")),
    ("reverse_within_010", "reverse: matched kept ≤0.10", ("intrinsym", "reverse")),
    ("kept_changed", "kept map: distances changed", ("intrinsym",)),
    ("truth_changed", "true map: distances changed", ("truth",)),
    ("seconds", "seconds", ("intrinsym", "pyfm", "reverse")),
)


def pyfm_match(partial: intrinsym.Shape, null: intrinsym.Shape) -> np.ndarray:
    """(N_partial,) int64: pyFM's map of every partial vertex to a null vertex (WKS, ZoomOut 20 -> 100)."""
    from pyFM.functional import FunctionalMapping
    from pyFM.mesh import TriMesh

    # pyFM's point-to-point map goes from its second mesh to its first
    model = FunctionalMapping(
        TriMesh(np.asarray(null.vertices), np.asarray(null.faces)),
        TriMesh(np.asarray(partial.vertices), np.asarray(partial.faces)),
    )
    model.preprocess(n_descr=100, descr_type="WKS", subsample_step=5, k_process=100, verbose=False)
    model.fit(K=(20, 20), w_descr=1.0, w_lap=1e-2, w_dcomm=1e-1, w_orient=0.0, verbose=False)
    model.zoomout_refine(nit=16, step=5, verbose=False)
    return np.asarray(model.get_p2p(), dtype=np.int64)


def mode_masses(result: intrinsym.Result, true: np.ndarray, mirror: np.ndarray, graph) -> tuple[np.ndarray, np.ndarray]:
    """Per source sample, the mixed marginals' mass (:meth:`intrinsym.Result.mixed_marginals`)
    within :data:`MODE_RADIUS` of its true and of its mirror point.

    Parameters
    ----------
    result : Result
    true, mirror : (N_partial,) int64
        Null vertex of every partial vertex's true and mirror point.
    graph : (N_null, N_null) sparse
        The null shape's edge graph in units of sqrt(area(null)).

    Returns
    -------
    pair of (S,) float64
    """
    src = result.source_point_vertex
    points = np.unique(np.r_[true[src], mirror[src]])
    dist = dijkstra(graph, indices=points, limit=MODE_RADIUS)
    row = {p: k for k, p in enumerate(points)}
    m = result.mixed_marginals()
    near = np.isfinite(dist[:, result.target_point_vertex])

    def mass(at: np.ndarray) -> np.ndarray:
        return np.array([m[s, near[row[at[v]]]].sum() for s, v in enumerate(src)])

    return mass(true), mass(mirror)


def reverse_scores(vmap: np.ndarray, true: np.ndarray, mirror: np.ndarray, graph) -> dict:
    """Scores of a map of the null shape onto the partial one (``match(null, partial)``).

    Parameters
    ----------
    vmap : (N_null,) int64
        Partial vertex of every null vertex, -1 for "no match".
    true, mirror, graph
        As in :func:`mode_masses`.

    Returns
    -------
    dict
        ``convention`` ("true" or "mirror": the answer more matched null vertices lie
        within 0.10 of), ``cut_unmatched`` (share of the cut-away null vertices, farther
        than :data:`CUT` from every answer point of that convention, left unmatched; None
        when none is), ``kept_matched`` (share of those within :data:`KEPT` matched) and
        ``reverse_within_010`` (share of the matched kept ones whose image's nearer answer
        point lies within 0.10 of them; None when none is matched).
    """
    matched = np.flatnonzero(vmap >= 0)
    error = {}
    for name, answer in (("true", true), ("mirror", mirror)):
        error[name] = np.full(len(vmap), np.inf)
        error[name][matched] = evaluate.map_errors(answer[vmap[matched]], matched, graph)
    agree = {name: float(np.mean(e[matched] <= 0.10)) if len(matched) else 0.0 for name, e in error.items()}
    convention = "true" if agree["true"] >= agree["mirror"] else "mirror"
    answer = true if convention == "true" else mirror
    near = dijkstra(graph, indices=np.unique(answer), min_only=True, limit=CUT * 1.01)
    cut, kept, mapped = near > CUT, near <= KEPT, vmap >= 0
    right = np.minimum(error["true"], error["mirror"]) <= 0.10
    return {
        "convention": convention,
        "cut_vertices": int(cut.sum()),
        "cut_unmatched": float(np.mean(~mapped[cut])) if cut.any() else None,
        "kept_matched": float(np.mean(mapped[kept])) if kept.any() else None,
        "reverse_within_010": float(np.mean(right[kept & mapped])) if (kept & mapped).any() else None,
    }


@functools.cache
def null_symmetry(path: Path) -> tuple[np.ndarray, float]:
    """The null shape's own symmetry map (default :func:`intrinsym.detect`) and its seconds."""
    start = time.perf_counter()
    vmap = intrinsym.detect(intrinsym.load(path)).symmetry_map()
    return vmap, time.perf_counter() - start


@functools.cache
def prepared_null(path: Path, n_source: int | None, n_target: int | None) -> tuple[intrinsym.Surface, float]:
    """The null shape prepared (:func:`intrinsym.prepare`) once per process for the matches
    onto it at these sample counts, which share its eigenpairs and chord graph, and the
    seconds of the preparation."""
    start = time.perf_counter()
    whole = intrinsym.prepare(path, n_source=n_source, n_target=n_target)
    return whole, time.perf_counter() - start


def mode_errors(
    two: modes.Modes, true: np.ndarray, mirror: np.ndarray, graph, far: np.ndarray
) -> dict[tuple[int, str], np.ndarray]:
    """Per mode (0, 1) and answer ("true", "mirror"), the geodesic distance from the
    mode's image of every partial vertex in ``far`` to that answer's point."""
    return {
        (k, name): evaluate.map_errors(two.maps[k], answer, graph)[far]
        for k in (0, 1)
        for name, answer in (("true", true), ("mirror", mirror))
    }


def both_answers(two: modes.Modes, error: dict[tuple[int, str], np.ndarray]) -> dict:
    """Per partial vertex of :func:`mode_errors`, whether one mode lies within 0.05 (0.10)
    of the true point and the other within it of the mirror point; 0 without a second mode."""
    out = {}
    for t in (0.05, 0.10):
        straight = (error[0, "true"] <= t) & (error[1, "mirror"] <= t)
        held = straight | ((error[0, "mirror"] <= t) & (error[1, "true"] <= t))
        out[f"{round(t * 100):03d}"] = float(np.mean(held)) if two.both and len(held) else 0.0
    return out


def true_answer(error: dict[tuple[int, str], np.ndarray]) -> float | None:
    """1.0 when mode 0 lies within 0.10 of the true point at more of the partial vertices
    of :func:`mode_errors` than of the mirror point, 0.0 when at fewer, 0.5 on a tie;
    None without such vertices. Its mean over pairs is the frequency that mode 0's
    confidence (``confidence0``) claims: the calibration of the modes' confidences."""
    if not len(error[0, "true"]):
        return None
    on_true, on_mirror = (int(np.sum(error[0, name] <= 0.10)) for name in ("true", "mirror"))
    return 0.5 if on_true == on_mirror else float(on_true > on_mirror)


def run(path: Path, method: str, overrides: Mapping) -> dict:
    """One shape matched to its null shape under ``method`` ("intrinsym" or "pyfm"), or
    its null shape matched to it ("reverse")."""
    shape = intrinsym.load(path)
    null = intrinsym.load(partial_truth.null_shape_path(path))
    n = len(shape.vertices)
    base = path.with_suffix("")
    unit = float(np.sqrt(surface_area(null)))
    tree = cKDTree(null.vertices)
    true = tree.query(partial_truth.load_barycentric(f"{base}.baryc_gt", null, n))[1]
    mirror = tree.query(partial_truth.load_barycentric(f"{base}.baryc_gt_sym", null, n))[1]
    graph = partial_truth.edge_graph(null, unit)
    row: dict = {"shape": path.stem, "class": _group(path.stem)[1], "method": method, "vertices": n}
    start = time.perf_counter()
    result = None
    if method == "truth":
        params = intrinsym.make_params(**overrides)
        part, whole = prepare_pair(shape, null, min_vertices(params), params.match_scale)
        row["truth_changed"] = least_distorted([true, mirror], part, whole)[1]
        row["seconds"] = time.perf_counter() - start
        return row
    if method == "reverse":
        result = intrinsym.match(null, shape, intrinsym.make_params(**overrides))
        row["seconds"] = time.perf_counter() - start
        row["stages"] = dict(result.info.seconds)
        return {**row, **reverse_scores(result.symmetry_map(), true, mirror, graph)}
    if method == "pyfm":
        vmap = pyfm_match(shape, null)
        row["seconds"] = time.perf_counter() - start
    else:
        null_path = partial_truth.null_shape_path(path)
        # the detect's seconds, paid by the first shape of its class in a process
        symmetry, row["null_detect_seconds"] = null_symmetry(null_path)
        params = intrinsym.make_params(**overrides)
        # prepared by the first shape of its class in a process (and its eigenpairs solved
        # in that shape's match), as a user matching many parts to one whole would
        whole, row["null_prepare_seconds"] = prepared_null(null_path, params.n_source, params.n_target)
        start = time.perf_counter()
        result = intrinsym.match(shape, whole, params, target_symmetry=symmetry)
        row["seconds"] = time.perf_counter() - start
        vmap = result.symmetry_map()
        if result.info.part_map is not None:
            row["part_map"] = result.info.part_map.source
            row["part_map_distortion"] = result.info.part_map.distortion
            row["part_map_final"] = result.info.part_map.final
            row["part_map_seconds"] = result.info.seconds.get("part map")
        two = modes.two_modes(result)
        row["confidence0"], row["confidence1"] = (float(c) for c in two.confidence)
        far_vertices = evaluate.map_errors(true, mirror, graph) > FAR
        error = mode_errors(two, true, mirror, graph, far_vertices)
        held = both_answers(two, error)
        row["mode0_true"] = true_answer(error)
        row["answers_005"], row["answers_010"] = held["005"], held["010"]
        alone = modes.two_modes(dataclasses.replace(result, target_symmetry=None))
        alone_error = mode_errors(alone, true, mirror, graph, far_vertices)
        row["answers_005_alone"] = both_answers(alone, alone_error)["005"]
        src = result.source_point_vertex
        far = evaluate.map_errors(true[src], mirror[src], graph) > FAR
        at_true, at_mirror = (m[far] >= MODE_MASS for m in mode_masses(result, true, mirror, graph))
        row["far_samples"] = int(far.sum())
        row["both_modes"] = float(np.mean(at_true & at_mirror)) if far.any() else None
        row["true_only"] = float(np.mean(at_true & ~at_mirror)) if far.any() else None
        row["mirror_only"] = float(np.mean(~at_true & at_mirror)) if far.any() else None
        start = time.perf_counter()
        inverse = {COVER_SPACINGS: invert_part_match(result, shape, null)}
        row["reverse_seconds"] = time.perf_counter() - start
        inverse.update({k: invert_part_match(result, shape, null, k) for k in REACHES if k not in inverse})
        row["reaches"] = {str(k): reverse_scores(inverse[k], true, mirror, graph) for k in REACHES}
    errors = np.minimum(evaluate.map_errors(vmap, true, graph), evaluate.map_errors(vmap, mirror, graph))
    if result is not None:
        mapped = vmap >= 0
        right = {"within_0.05": errors[mapped] <= 0.05}
        row["reliability"] = {"match_score": score_histogram(result.symmetry_score()[mapped], right)}
        if result.info.part_map is not None:
            # the score of the part's confidence: one value per pair
            kept = np.full(int(mapped.sum()), result.info.part_map.kept)
            row["reliability"]["part_kept"] = score_histogram(kept, right)
        row["confidence"] = confidence_row(result.symmetry_confidence()[mapped], right["within_0.05"])
    for t in THRESHOLDS:
        row[f"within_{round(t * 100):03d}"] = float(np.mean(errors <= t))
    mapped = np.isfinite(errors)
    row["coverage"] = float(mapped.mean())
    row["mean_error"] = float(errors[mapped].mean()) if mapped.any() else None
    return row


def markdown(rows: dict[tuple[str, str], dict], names: list[str], methods: list[str]) -> str:
    """The table: a row per shape, then mean and worst per kind, per class and overall;
    then the reverse scores at every reach (:func:`reach_table`)."""
    # the reverse scores at the default reach, the kept map's share of changed distances
    rows = {k: {**r, **r.get("reaches", {}).get(str(COVER_SPACINGS), {}), **_kept(r)} for k, r in rows.items()}
    columns = [(key, m) for key, _, have in SCORES for m in methods if m in have]
    labels = {key: label for key, label, _ in SCORES}
    head = ["shape", *(f"{labels[key]} ({m})" for key, m in columns)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def cells(members: list[str], worst: bool) -> list[str]:
        out = []
        for key, m in columns:
            values = np.array([_value(rows.get((n, m)), key) for n in members])
            # worst: the lowest share, the highest error, share of distances changed or time
            agg = np.nanmax if key in LOWER_IS_BETTER else np.nanmin
            out.append("–" if np.all(np.isnan(values)) else f"{(agg if worst else np.nanmean)(values):.3f}")
        return out

    for n in names:
        lines.append("| " + " | ".join([n, *cells([n], False)]) + " |")
    groups: dict[str, list[str]] = {}
    for n in names:
        kind, cls, _, _ = n.split("_")
        for g in (kind, cls, f"{kind} {cls}", "all"):
            groups.setdefault(g, []).append(n)
    for g, members in groups.items():
        if len(members) > 1:
            lines.append("| " + " | ".join([f"**mean {g}** ({len(members)})", *cells(members, False)]) + " |")
            lines.append("| " + " | ".join([f"worst {g}", *cells(members, True)]) + " |")
    if "truth" in methods:
        lines += ["", search_or_test(rows, names)]
    lines += ["", reach_table(rows, names) if "intrinsym" in methods else ""]
    return "\n".join(lines).rstrip("\n") + "\n"


def _kept(row: dict) -> dict:
    """``{"kept_changed": share}``: the share of the part's short distances the map
    ``match`` kept changes (its ``part_map_distortion`` under ``part_map_final``); empty
    without one."""
    final = row.get("part_map_final")
    share = row.get("part_map_distortion", {}).get(final) if final else None
    return {} if share is None else {"kept_changed": share}


def search_or_test(rows: dict[tuple[str, str], dict], names: list[str]) -> str:
    """The line that says what failed on the pairs whose map is wrong (within 0.10 on
    less than :data:`RIGHT` of the vertices): the search, where the true map changes fewer
    of the part's short distances than the kept map by more than :data:`MARGIN` (the test
    would have kept it), or the test, where it does not. ``rows`` as :func:`markdown`
    reads them (``kept_changed`` merged in)."""
    search, test = [], []
    for n in names:
        mine = rows.get((n, "intrinsym"))
        kept, true = _value(mine, "kept_changed"), _value(rows.get((n, "truth")), "truth_changed")
        # nan: no row, a failed run or no part map; not a wrong pair
        if np.isnan(kept) or np.isnan(true) or not _value(mine, "within_010") < RIGHT:
            continue
        (search if true < kept - MARGIN else test).append(n)
    return (
        f"Pairs within 0.10 on less than {RIGHT:.2f} of their vertices: {len(search) + len(test)}. "
        f"The true map changes fewer of the part's short distances than the kept map (by more than "
        f"{MARGIN:g}) on {len(search)}: the search never offered it ({', '.join(search) or 'none'}); "
        f"not on {len(test)}: the test would not keep it ({', '.join(test) or 'none'}).\n"
    )


def reach_table(rows: dict[tuple[str, str], dict], names: list[str]) -> str:
    """The reverse scores at every reach of :data:`REACHES` (the default's marked): mean
    and worst shape over cuts, holes and all shapes."""
    head = ["reach (sample spacings)"]
    kinds = {"cuts": [n for n in names if n.startswith("cuts")], "holes": [n for n in names if n.startswith("holes")]}
    kinds["all"] = names
    for kind in kinds:
        head += [f"cut-away unmatched, {kind} (mean / worst)", f"kept matched, {kind} (mean / worst)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for k in REACHES:
        cells = [f"**{k:g}** (default)" if k == COVER_SPACINGS else f"{k:g}"]
        for members in kinds.values():
            for key in ("cut_unmatched", "kept_matched"):
                v = np.array(
                    [_value((rows.get((n, "intrinsym")) or {}).get("reaches", {}).get(str(k)), key) for n in members]
                )
                cells.append("–" if np.all(np.isnan(v)) else f"{np.nanmean(v):.3f} / {np.nanmin(v):.3f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    return run_script(
        argv,
        __doc__,
        ["intrinsym"],
        run,
        markdown,
        "within_010",
        cache_folder="match",
        optional={
            "reverse": "also time match(null, partial) itself and score the map it returns",
            "truth": "also weigh the true map as match weighs a part's maps, beside the kept one",
        },
    )


if __name__ == "__main__":
    sys.exit(main())
