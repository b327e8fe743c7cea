"""The GPU BP backend against the CPU kernels on the same MRFs, side by side in one run.

For every mesh, runs :func:`intrinsym.detect` at the given sizes to build its MRF (the
unary BP ran on, the source graph, the target rings), then runs BP on that one MRF with
the CPU colour schedule (the default), the CPU flooding schedule and the GPU flooding
schedule (:mod:`intrinsym.bp_gpu`), each to convergence, and prints seconds per iteration
(median), iterations, seconds to convergence, and how far the GPU's marginals lie from
the CPU flooding ones (the same messages: largest relative difference, and the share of
rows whose argmax agrees)::

    python benchmarks/gpu.py MESH [MESH ...] [--sizes 271 12722] [--json]

Exits 1 when the GPU backend is unavailable or its marginals disagree with the CPU's.
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
from intrinsym import bp, bp_gpu, model

#: Largest relative difference of the GPU's marginals from the CPU flooding ones
#: (float32 messages both, float64 products; tests/test_bp.py asserts 1e-4 on a small MRF).
MAX_RELATIVE = 1e-3


def mrf_of(path: Path, n_source: int, n_target: int) -> tuple[model.MRF, dict]:
    """The MRF a default detect run solved (its final unary), and the run's sizes."""
    res = intrinsym.detect(path, n_source=n_source, n_target=n_target, iterations=1, trivial_weight=0.0)
    mrf = model.MRF(res.unary, res.edges, res.support.edge_length, res.support.targets,
                    res.info["resolved"]["lambda_normalised"], res.params.rho)
    return mrf, res.info["sizes"]


def run_backend(mrf: model.MRF, schedule: str, backend: str) -> bp.BPResult:
    bp.belief_propagation(mrf, schedule, 2, 1e-4, backend=backend)  # compile / warm up
    return bp.belief_propagation(mrf, schedule, 200, 1e-4, backend=backend)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("meshes", nargs="+", type=Path)
    parser.add_argument("--sizes", nargs=2, type=int, default=(271, 12722), metavar=("PS", "PT"),
                        help="|Ps| |Pt| (default: the paper's elephant, 271 12722)")
    parser.add_argument("--json", action="store_true", help="one JSON object per mesh instead of a table")
    args = parser.parse_args(argv)
    if not bp_gpu.available():
        print("the GPU backend is unavailable: CuPy sees no CUDA device", file=sys.stderr)
        return 1
    import cupy

    device = cupy.cuda.runtime.getDeviceProperties(0)["name"].decode()
    print(f"GPU: {device}; CPU: {os.cpu_count()} cores (Numba threads: {numba.get_num_threads()})")
    failed = False
    if not args.json:
        print("| mesh | Ps / Pt | messages | backend | s / iteration | iterations | s to convergence | GPU vs CPU flooding |")
        print("|---|---|---|---|---|---|---|---|")
    for path in args.meshes:
        mrf, sizes = mrf_of(path, *args.sizes)
        runs = {name: run_backend(mrf, schedule, backend) for name, schedule, backend in
                (("cpu colour", "colour", "cpu"), ("cpu flooding", "flooding", "cpu"),
                 ("gpu flooding", "flooding", "gpu"))}
        cpu, gpu = runs["cpu flooding"].marginals, runs["gpu flooding"].marginals
        relative = float(np.abs(gpu / cpu - 1.0).max())
        argmax = float(np.mean(gpu.argmax(axis=1) == cpu.argmax(axis=1)))
        failed |= relative > MAX_RELATIVE or runs["gpu flooding"].iterations != runs["cpu flooding"].iterations
        row = {name: {"seconds_per_iteration": float(np.median(r.seconds)), "iterations": r.iterations,
                      "seconds": float(np.sum(r.seconds)), "converged": r.converged} for name, r in runs.items()}
        if args.json:
            print(json.dumps({"mesh": str(path), "sizes": sizes, "device": device, "backends": row,
                              "gpu_relative_difference": relative, "gpu_argmax_agreement": argmax}))
            continue
        for name, r in row.items():
            agree = f"max rel. diff {relative:.1e}, argmax {argmax:.3f}" if name == "gpu flooding" else ""
            print(f"| {path.name} | {sizes['source']} / {sizes['target']} | {sizes['directed_edges']} | {name} | "
                  f"{r['seconds_per_iteration']:.4f} | {r['iterations']} | {r['seconds']:.2f} | {agree} |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
