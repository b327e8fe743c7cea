"""The GPU BP backend against the CPU kernels on the same MRFs, side by side in one run.

For every mesh, runs :func:`intrinsym.detect` at the given sizes to build its MRF (the
unary BP ran on, the source graph, the target rings), then runs BP on that one MRF with
the colour schedule (the default on the GPU) and the flooding schedule, each on the CPU and on the
GPU (:mod:`intrinsym.mrf.bp.gpu`), each to convergence, and prints seconds per iteration
(median), iterations, seconds to convergence, and how far the GPU's marginals lie from
the CPU's of the same schedule (the same messages: largest relative difference, and the
share of rows whose argmax agrees)::

    python benchmarks/gpu.py MESH [MESH ...] [--sizes 271 12722] [--json]

Exits 1 when the GPU backend is unavailable or its marginals disagree with the CPU's.
The CPU runs on every core Numba sees; name the machine beside the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numba
import numpy as np

import intrinsym
from intrinsym.mrf import bp, model

#: Largest relative difference of the GPU's marginals from the CPU's
#: (float32 messages both, float64 products; tests/test_bp.py asserts 1e-4 on a small MRF).
MAX_RELATIVE = 1e-3


def mrf_of(path: Path, n_source: int, n_target: int) -> tuple[model.MRF, dict]:
    """The MRF a default detect run solved (its final unary), and the run's sizes."""
    params = intrinsym.make_params(n_source=n_source, n_target=n_target, iterations=1, trivial_weight=0.0)
    res = intrinsym.detect(path, params)
    return res.mrf(), res.info.sizes


def run_backend(mrf: model.MRF, schedule: str, backend: str) -> bp.BPResult:
    bp.belief_propagation(mrf, schedule, 2, 1e-4, backend=backend)  # compile / warm up
    return bp.belief_propagation(mrf, schedule, 200, 1e-4, backend=backend)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("meshes", nargs="+", type=Path)
    parser.add_argument(
        "--sizes",
        nargs=2,
        type=int,
        default=(271, 12722),
        metavar=("PS", "PT"),
        help="|Ps| |Pt| (default: the paper's elephant, 271 12722)",
    )
    parser.add_argument("--json", action="store_true", help="one JSON object per mesh instead of a table")
    args = parser.parse_args(argv)
    if not bp.gpu_available():
        print("the GPU backend is unavailable: CuPy sees no CUDA device", file=sys.stderr)
        return 1
    import cupy

    device = cupy.cuda.runtime.getDeviceProperties(0)["name"].decode()
    print(f"GPU: {device}; CPU: {os.cpu_count()} cores (Numba threads: {numba.get_num_threads()})")
    failed = False
    if not args.json:
        print("| mesh | Ps / Pt | messages | backend | s / iteration | iterations | s to convergence | GPU vs CPU |")
        print("|---|---|---|---|---|---|---|---|")
    for path in args.meshes:
        mrf, sizes = mrf_of(path, *args.sizes)
        runs = {
            (schedule, backend): run_backend(mrf, schedule, backend)
            for schedule in ("colour", "flooding")
            for backend in ("cpu", "gpu")
        }
        agreement = {}
        for schedule in ("colour", "flooding"):
            cpu, gpu = runs[schedule, "cpu"], runs[schedule, "gpu"]
            relative = float(np.abs(gpu.marginals / cpu.marginals - 1.0).max())
            argmax = float(np.mean(gpu.marginals.argmax(axis=1) == cpu.marginals.argmax(axis=1)))
            agreement[schedule] = {"relative_difference": relative, "argmax_agreement": argmax}
            failed |= relative > MAX_RELATIVE or gpu.iterations != cpu.iterations
        row = {
            f"{backend} {schedule}": {
                "seconds_per_iteration": float(np.median(r.seconds)),
                "iterations": r.iterations,
                "seconds": float(np.sum(r.seconds)),
                "converged": r.converged,
            }
            for (schedule, backend), r in runs.items()
        }
        if args.json:
            print(
                json.dumps(
                    {"mesh": str(path), "sizes": sizes, "device": device, "backends": row, "gpu_against_cpu": agreement}
                )
            )
            continue
        for schedule, backend in runs:
            r, a = row[f"{backend} {schedule}"], agreement[schedule]
            agree = (
                f"max rel. diff {a['relative_difference']:.1e}, argmax {a['argmax_agreement']:.3f}"
                if backend == "gpu"
                else ""
            )
            print(
                f"| {path.name} | {sizes['source']} / {sizes['target']} | {sizes['directed_edges']} "
                f"| {backend} {schedule} "
                f"| {r['seconds_per_iteration']:.4f} | {r['iterations']} | {r['seconds']:.2f} | {agree} |"
            )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
