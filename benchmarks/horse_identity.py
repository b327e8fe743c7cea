"""Is the identity between Sumner's horse-01 and horse-03 a mode of the two-shape MRF?

Matches horse-01 to horse-03 (:func:`intrinsym.match`, two BP passes), then runs BP
again on the same MRF started from the messages of a point mass on the true identity
(every source sample certain of its own target cell: m_{s->q}(fq) = Psi(d(s,q),
d(f*_s, fq))), once with the first pass's unary and once with the second pass's (the
first pass's argmax removed), and, as a control, from the true left/right swap with the
first pass's unary; it prints after how many iterations how many of the
off-plane source samples have their argmax within 0.05 sqrt(area) of the identity and
of the left/right swap (judged on the mirror-symmetric reference pose, as
``benchmarks/generated.py`` judges the horse). A mode of the model would keep BP there::

    python benchmarks/horse_identity.py [--data DIR] [--sizes 150 1500]

The frames are ``sumner_horse/`` of the data folder (``--data`` or ``$INTRINSYM_DATA``);
without it the script says so in one line and exits 0.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np

import intrinsym
from _data import add_data_argument, data_folder, no_data
from intrinsym.evaluation import evaluate
from intrinsym.mesh.shape import surface_area
from intrinsym.mrf import bp, model

#: Iteration counts after which the argmax is scored (BP stops earlier when it converges).
CHECKPOINTS = (1, 3, 10, 100)


def point_mass_messages(mrf: model.MRF, labels: np.ndarray) -> np.ndarray:
    """(2E, T) messages of senders certain of ``labels``: directed edge d sends from
    ``edges[d >> 1, d & 1]``, Psi of Eq. 6 of its edge length against d(label, fq)."""
    n_t = mrf.unary.shape[1]
    messages = np.full((2 * len(mrf.edges), n_t), mrf.rho**2, dtype=np.float32)
    for d in range(len(messages)):
        e = d >> 1
        idx, dist = mrf.targets.row(labels[mrf.edges[e, d & 1]])
        messages[d, idx] = np.maximum(np.exp(-mrf.lam * (mrf.edge_length[e] - dist) ** 2), mrf.rho**2)
    return messages


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(parser, "research data folder with sumner_horse/")
    parser.add_argument("--sizes", nargs=2, type=int, default=(150, 1500), metavar=("PS", "PT"))
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    horse = None if data is None else data / "sumner_horse"
    if horse is None or not horse.is_dir():
        print(no_data("horse_identity.py", args.data if horse is None else horse))
        return 0
    res = intrinsym.match(
        horse / "horse-01.obj", horse / "horse-03.obj", n_source=args.sizes[0], n_target=args.sizes[1]
    )
    ref = intrinsym.load(horse / "horse_ref.obj")
    vertices = np.asarray(ref.vertices)
    scale = np.sqrt(surface_area(ref))
    swap = evaluate.extrinsic_mirror(vertices)[0]
    a, tv = res.source_point_vertex, res.target_point_vertex
    off_plane = np.abs(vertices[a, 0] - vertices[:, 0].mean()) > 0.05 * scale

    def score(beliefs: np.ndarray) -> str:
        image = vertices[tv[beliefs.argmax(axis=1)]]
        same = np.linalg.norm(image - vertices[a], axis=1) < 0.05 * scale
        swapped = np.linalg.norm(image - vertices[swap[a]], axis=1) < 0.05 * scale
        return f"identity {np.mean(same[off_plane]):.2f}, swap {np.mean(swapped[off_plane]):.2f}"

    print(f"off-plane source samples ({off_plane.sum()} of {len(a)}) within 0.05 of:")
    print(f"  pass 1 (from uniform messages): {score(res.marginals)}")
    print(f"  pass 2 (from uniform messages): {score(res.pass_marginals[0])}")
    mrf = res.mrf()
    runs = (
        ("pass 1", res.unary, "identity", a),
        ("pass 2", res.passes[0][1], "identity", a),
        ("pass 1", res.unary, "swap", swap[a]),
    )
    for name, unary, truth, vertex in runs:
        start = point_mass_messages(mrf, res.support.vertex_target[vertex])
        for k in CHECKPOINTS:
            run = bp.belief_propagation(
                dataclasses.replace(mrf, unary=unary), "colour", k, res.params.bp_tol, backend="cpu", initial=start
            )
            print(f"  {name} unary, from the true {truth}, {run.iterations} iterations: {score(run.marginals)}")
            if run.converged:
                break
    return 0


if __name__ == "__main__":
    sys.exit(main())
