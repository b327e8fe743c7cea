"""Two versions of intrinsym side by side: whole-process ``detect`` seconds per stage and scores.

For every case, runs ``detect`` of the old version (``--old SRC``, the ``src`` folder of
another checkout, put first on ``PYTHONPATH``) and of the installed one, each in a fresh
process (``import intrinsym``, then ``detect(mesh, n_source=..., n_target=...)``),
alternating old and new, and prints one JSON line per run: process wall time, import
and ``detect`` seconds, seconds per stage, BP iterations and seconds per iteration, peak
memory, and the marginal scores of unary and BP and the symmetry map's scores
(:func:`intrinsym.evaluation.evaluate.score_marginals`, :func:`intrinsym.evaluation.evaluate.score_map`,
computed here by the installed version from what each run saved). Cases: ``spot`` (the
shipped example; truth: its best reflection), ``cat1``, ``michael1`` (defaults 250 /
4000) and ``michael1-elephant`` (271 / 12722). Command::

    OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/speed.py --old ../base/src \\
        [--data DATA] [--cases spot cat1 michael1 michael1-elephant] [--backend gpu] [--repeat N] [--cold]

Warm the Numba caches of both versions first (one small ``detect`` each), so that no run
pays for compilation. ``--cold`` instead gives every run an empty Numba cache
(``NUMBA_CACHE_DIR``), so that each compiles every kernel it calls: the first run after
a fresh install.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _data import add_data_argument, data_folder, no_data
from intrinsym import example_path, load
from intrinsym.evaluation import evaluate

#: Case name -> (mesh relative to the data folder, or None for the shipped example; |Ps|; |Pt|).
CASES = {
    "spot": (None, 250, 4000),
    "cat1": ("tosca_sym/cat1.off", 250, 4000),
    "michael1": ("tosca_sym/michael1.off", 250, 4000),
    "michael1-elephant": ("tosca_sym/michael1.off", 271, 12722),
}

#: What each child process runs; works with the old ``detect(shape, preset, log, **params)``
#: and the new ``detect(shape, params, *, n_source, n_target, ...)``.
CHILD = """
import json, resource, sys, time
t0 = time.perf_counter()
import numpy as np
import intrinsym
mesh, ns, nt, out, backend = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
t1 = time.perf_counter()
r = intrinsym.detect(mesh, intrinsym.make_params(backend=backend), n_source=ns, n_target=nt)
t2 = time.perf_counter()
info = r.info
if isinstance(info, dict):
    seconds, iters, per = info["seconds"], info["bp"]["iterations"], info["bp"]["seconds_per_iteration"]
else:
    seconds, iters, per = dict(info.seconds), info.bp.iterations, info.bp.seconds_per_iteration
def attr(*names):
    for n in names:
        v = getattr(r, n, None)
        if v is not None and not callable(v):
            return np.asarray(v)
np.savez(out, marginals=r.marginals, unary=r.unary, sv=attr("source_point_vertex", "source_vertex"),
         tv=attr("target_point_vertex", "target_vertex"), vmap=np.asarray(r.symmetry_map()))
print(json.dumps({"import": t1 - t0, "detect": t2 - t1, "seconds": seconds, "iters": iters, "per_iter": per,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def run_once(
    src: str | None, mesh: str, n_source: int, n_target: int, out: Path, backend: str = "cpu", cache: str | None = None
) -> dict:
    """One ``detect`` in a fresh process; ``src`` first on PYTHONPATH (None: the installed
    version); ``cache``: the Numba cache folder (None: the usual one)."""
    env = dict(os.environ)
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = cache
    if src is not None:
        env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH")) if p)
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, mesh, str(n_source), str(n_target), str(out), backend],
        env=env,
        capture_output=True,
        text=True,
    )
    if proc.returncode:
        raise RuntimeError(proc.stderr[-2000:])
    row = json.loads(proc.stdout.strip().splitlines()[-1])
    row["wall"] = time.perf_counter() - start
    return row


def scores(saved: Path, shape, sym: np.ndarray) -> dict:
    """Marginal scores of unary and BP, and the map's scores, of one saved run."""
    z = np.load(saved)
    row = {}
    for column in ("unary", "marginals"):
        sc = evaluate.score_marginals(z[column], z["sv"], z["tv"], shape, sym, seed=0).as_dict()
        row[column] = {k: round(v, 4) for k, v in sc.items() if isinstance(v, float)}
    ms = evaluate.score_map(z["vmap"], shape, sym)
    row["map"] = {"w05": round(ms.within(0.05), 4), "w10": round(ms.within(0.10), 4), "err": round(ms.mean_error, 4)}
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--old", required=True, help="src folder of the old version")
    add_data_argument(parser)
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--backend", choices=("cpu", "gpu"), default="cpu", help="BP backend of both versions")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each version per case, alternating")
    parser.add_argument("--cold", action="store_true", help="every run with an empty Numba cache (the first run)")
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    if data is None and any(CASES[c][0] is not None for c in args.cases):
        print(no_data("speed.py", args.data))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases:
            rel, n_source, n_target = CASES[case]
            mesh = str(example_path()) if rel is None else str(data / rel)
            shape = load(mesh)
            if rel is None:
                sym = evaluate.extrinsic_mirror(shape.vertices)[0]
            else:
                stem = Path(rel).stem.rstrip("0123456789")
                sym = evaluate.load_symmetry_map(Path(mesh).with_name(f"{stem}.sym"), len(shape.vertices))
            for k in range(args.repeat):
                for version, src in (("old", args.old), ("new", None)):
                    out = Path(tmp) / f"{case}_{version}.npz"
                    cache = tempfile.mkdtemp(prefix=f"numba_{case}_{version}_{k}_", dir=tmp) if args.cold else None
                    row = run_once(src, mesh, n_source, n_target, out, args.backend, cache)
                    line = {"case": case, "version": version, "backend": args.backend, "cold": args.cold, **row}
                    print(json.dumps({**line, **scores(out, shape, sym)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
