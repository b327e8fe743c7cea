"""Where does the unary put the true partner? Per shape and unary term.

For every shape with a known symmetry, complete (``tosca.py``'s shapes) or partial (the
SHREC'16 cuts and holes of ``partial.py``), builds the self-matching unary of
:func:`intrinsym.detect` (seed 0, the given ``--param`` fields) one ``--terms`` entry at a
time, removes the trivial match, and measures it at the source samples whose true partner
has a target within 0.05 of it beyond the trivial radius:

* ``argmax ≤0.05`` / ``≤0.10``: the share whose largest potential lies within 0.05 / 0.10
  of the partner (geodesic, units of sqrt(area) of the reference shape);
* ``partner z``: the median distance, in calibrated widths, from the sample's descriptor
  to the best target near its partner (the potential is ``exp(-z^2 / 2)``,
  :func:`intrinsym.unary.unary.calibrated_potential`; z is capped near 37.6, where the
  potential reaches the smallest normal float);
* ``partner at floor``: the share whose partner's potential sits at ``--unary-floor``
  (z above ``sqrt(-2 ln floor)``, 3.72 at the default 1e-3), where the unary says
  "not this" as firmly as anywhere;
* ``best z``: the median z of each sample's best target beyond the trivial radius, what
  the shape offers a sample when no truth is known;
* ``BP argmax ≤0.05`` / ``≤0.10``: the same shares for the argmax of BP's marginals on
  that unary (at ``--unary-floor``, one pass, the trivial match removed: ``trivial_weight``
  0, so that BP's own answer is seen rather than the identity kept as "no partner").

A term whose partner z stays near its best z sees the symmetry; one whose partner sits at
the floor vetoes it. BP's columns above the unary's: the pairwise term spread the
symmetry from the rows that see it; below: it carried the rows to another consistent
answer. Command::

    OPENBLAS_NUM_THREADS=1 python benchmarks/unary_partner.py --data DATA
        [--shapes cat0 holes_cat_shape_1 cuts ...] [--terms wks spin wks*spin] [--param NAME=VALUE ...]
        [--json ROWS.json]

``--shapes`` takes shape or class names of ``tosca.py`` and shape names or prefixes of
``partial.py`` (default: all of both). Prints one Markdown table; ``--json`` also writes
its rows, a list of objects keyed by the column names, which ``partial_targets.py`` reads
to explain each shape that misses a target.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import scipy.sparse as sp

import intrinsym
import partial
import tosca
from _data import add_data_argument, data_folder, no_data
from intrinsym import pipeline
from intrinsym.evaluation import partial_truth
from intrinsym.geodesics import geodesics
from intrinsym.mrf import model
from intrinsym.problem import Problem, sampled
from tosca import _overrides

#: Distances (units of sqrt(area)) within which a target counts as the partner.
NEAR, FAR = 0.05, 0.10
#: Smallest potential the measurement lets the product reach: z up to sqrt(-2 ln TINY).
TINY = float(np.finfo(np.float64).tiny)

COLUMNS = (
    "samples",
    "argmax ≤0.05",
    "argmax ≤0.10",
    "partner z",
    "partner at floor",
    "best z",
    "BP argmax ≤0.05",
    "BP argmax ≤0.10",
)


@dataclasses.dataclass(frozen=True)
class Truth:
    """A shape with its true partner per input vertex.

    Attributes
    ----------
    name : str
    shape : intrinsym.Shape
    partner : (N,) int64
        Input vertex of each input vertex's partner; negative where it has none.
    graph : (M, M) sparse
        Geodesic graph, edge lengths in units of sqrt(area) of the reference shape.
    vertex : (N,) int64
        The graph vertex of every input vertex.
    """

    name: str
    shape: intrinsym.Shape
    partner: np.ndarray
    graph: sp.csr_matrix
    vertex: np.ndarray


def complete_truth(case: tosca.Case) -> Truth:
    """A ``tosca.py`` shape with its symmetry map."""
    mesh = intrinsym.load(case.mesh)
    _, vertex, graph = geodesics.unit_area_graph(mesh)
    return Truth(case.name, mesh, case.truth_map(mesh), graph, vertex)


def partial_shape_truth(path: Path) -> Truth:
    """A SHREC'16 partial shape with its mirror partners (:mod:`intrinsym.evaluation.partial_truth`)."""
    shape, truth = partial_truth.load_shrec16(path)
    graph = partial_truth.edge_graph(shape, truth.unit)
    return Truth(path.stem, shape, truth.partner, graph, np.arange(len(shape.vertices)))


def measure(truth: Truth, term: str, params: intrinsym.Params) -> dict:
    """The columns of :data:`COLUMNS` for one shape and one unary term."""
    if params.potential != "calibrated":
        raise SystemExit("unary_partner.py: the measure needs --param potential=calibrated")
    floor_z = float(np.sqrt(-2.0 * np.log(params.unary_floor)))
    p = dataclasses.replace(params, unary=term, unary_floor=TINY)
    surface = pipeline.prepare(truth.shape, p)
    ps, pt = pipeline.sample_pair(surface, surface, p)
    problem = sampled(surface, surface, ps, pt, p, True)
    phi, _, near, _ = pipeline.unary_model(problem, p)
    assert near is not None
    trivial = near < p.trivial_radius
    z = np.sqrt(-2.0 * np.log(np.maximum(phi, TINY)))
    z[trivial] = np.inf
    partner = truth.partner[problem.source_vertex]
    rows = np.flatnonzero(partner >= 0)
    to_partner = geodesics.distances_from(truth.graph, truth.vertex[partner[rows]], limit=FAR * 1.01)
    to_partner = to_partner[:, truth.vertex[problem.target_vertex]]
    partner_z = np.where(to_partner <= NEAR, z[rows], np.inf).min(axis=1)
    seen = np.isfinite(partner_z)
    rows, to_partner, partner_z = rows[seen], to_partner[seen], partner_z[seen]
    error = to_partner[np.arange(len(rows)), z[rows].argmin(axis=1)]
    # the potential floors the product (calibrated_potential): at TINY it holds every other floor
    marginals = _bp_marginals(
        problem, dataclasses.replace(params, unary=term), np.maximum(phi, params.unary_floor), near
    )
    bp_error = to_partner[np.arange(len(rows)), marginals[rows].argmax(axis=1)]
    return {
        "shape": truth.name,
        "term": term,
        "samples": len(rows),
        "argmax ≤0.05": float(np.mean(error <= NEAR)),
        "argmax ≤0.10": float(np.mean(error <= FAR)),
        "partner z": float(np.median(partner_z)),
        "partner at floor": float(np.mean(partner_z > floor_z)),
        "best z": float(np.median(z[rows].min(axis=1))),
        "BP argmax ≤0.05": float(np.mean(bp_error <= NEAR)),
        "BP argmax ≤0.10": float(np.mean(bp_error <= FAR)),
    }


def _bp_marginals(problem: Problem, p: intrinsym.Params, phi: np.ndarray, near: np.ndarray) -> np.ndarray:
    """(S, T) marginals of one BP pass on the unary ``phi`` (floored at ``p.unary_floor``)
    with the trivial match removed; ``near`` as :func:`intrinsym.pipeline.unary_model` gives it."""
    p = dataclasses.replace(p, trivial_weight=0.0)
    pair = pipeline.pairwise_model(problem, p, 1)
    mrf = model.MRF(phi.astype(np.float32), problem.edges, problem.edge_length, pair.targets, pair.lam, p.rho)
    return pipeline.solve_bp(mrf, phi, p.unary_floor, near, p, True, 1, None).marginals


def markdown(rows: Sequence[Mapping]) -> str:
    """One table row per shape and term."""
    out = ["| shape | term | " + " | ".join(COLUMNS) + " |", "|---|---|" + "---|" * len(COLUMNS)]
    for r in rows:
        cells = [str(r["samples"])] + [f"{r[c]:.2f}" for c in COLUMNS[1:]]
        out.append(f"| {r['shape']} | {r['term']} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def truths(data: Path, names: list[str] | None) -> list[Truth]:
    """The complete and partial shapes named (all of both without names), loaded lazily in order."""
    complete = tosca.cases(data)
    known = {c.name for c in complete} | {c.cls for c in complete}
    chosen = complete if not names else [c for c in complete if c.name in names or c.cls in names]
    found = partial.shapes(data)
    rest = [n for n in names or [] if n not in known]
    unknown = [n for n in rest if not partial.select(found, [n])]
    if unknown:
        raise SystemExit(f"unary_partner.py: unknown shape(s) {', '.join(unknown)}")
    partials = found if not names else (partial.select(found, rest) if rest else [])
    return [complete_truth(c) for c in chosen] + [partial_shape_truth(p) for p in partials]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(parser)
    parser.add_argument("--shapes", nargs="+", metavar="NAME", help="shape or class names (default: all)")
    parser.add_argument("--terms", nargs="+", default=["wks", "spin", "wks*spin"], help="unary values measured")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="a Params field changed")
    parser.add_argument("--json", type=Path, metavar="FILE", help="also write the rows here, as JSON")
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    if data is None:
        print(no_data("unary_partner.py", args.data))
        return 0
    try:
        params = intrinsym.make_params(**_overrides(args.param))
    except intrinsym.ParameterError as err:
        parser.error(f"--param {err}")
    rows = []
    for truth in truths(data, args.shapes):
        for term in args.terms:
            rows.append(measure(truth, term, params))
            print(markdown(rows[-1:]).splitlines()[-1], file=sys.stderr, flush=True)
    print(markdown(rows))
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
