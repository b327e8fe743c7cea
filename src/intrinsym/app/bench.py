"""Benchmark: seconds per stage and BP figures of a mesh at given sizes.

Every case runs the whole :func:`intrinsym.pipeline.detect` pipeline in a fresh child
process (so that its peak memory is its own), then times a few single messages of the
paper-literal dense form (Eq. 7 with the full |Pt| x |Pt| pairwise table) against ours
on the same edges and the same inputs, and checks that they agree. The paper's Table 1
cases, on stand-in meshes of a data
folder, are ``benchmarks/table1.py`` of the source tree.
"""

from __future__ import annotations

import multiprocessing
import resource
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from queue import Empty
from typing import Any

import numpy as np
from scipy.spatial.distance import cdist

from .. import example_path, pipeline
from ..mesh import sampling
from ..mrf import bp, model
from ..params import OFFSET_TARGETS, Params
from ..progress import BPIteration, ProgressEvent, StageDone
from ..spectral import laplacian
from ..surface import as_shape, prepare
from ..unary import descriptors, unary

#: How often (seconds) the parent checks that a case's child process is still alive.
_POLL_SECONDS = 1.0


@dataclass(frozen=True)
class Case:
    """A benchmark case.

    Attributes
    ----------
    name : str
    mesh : str
        Mesh path.
    n_source, n_target : int
        |Ps| and |Pt|.
    paper_gpu_s, paper_cpu_s : float or None
        The paper's Table 1 times (GTX280; 2.66 GHz CPU), 100 iterations.
    """

    name: str
    mesh: str
    n_source: int
    n_target: int
    paper_gpu_s: float | None = None
    paper_cpu_s: float | None = None


#: One tiny case on the shipped example (a smoke test, seconds).
SMALL = (Case("small", str(example_path()), 40, 400),)


@dataclass
class CaseResult:
    """Measured figures of one case (seconds unless named otherwise).

    Attributes
    ----------
    name, mesh : str
    sizes : dict
        |Ps|, |Pt|, edges, max degree, ... as in ``run.json``.
    stages : dict of str -> float
        Seconds per pipeline stage (load, prepare, sampling, geodesics, descriptors,
        unary, bp, extract).
    bp_setup, bp_per_iteration, bp_total : float
    iterations : int
    converged : bool
    peak_memory_mb : float
        Peak resident memory of the child process that ran the case.
    dense_message_s, sparse_message_s : float
        Mean time of one message, paper-literal dense form and ours, same edges.
    dense_over_sparse : float
    message_max_diff : float
        Largest difference of the two max-normalised messages.
    paper_gpu_s, paper_cpu_s : float or None
    """

    name: str
    mesh: str
    sizes: dict = field(default_factory=dict)
    stages: dict = field(default_factory=dict)
    bp_setup: float = 0.0
    bp_per_iteration: float = 0.0
    bp_total: float = 0.0
    iterations: int = 0
    converged: bool = False
    peak_memory_mb: float = 0.0
    dense_message_s: float = 0.0
    sparse_message_s: float = 0.0
    dense_over_sparse: float = 0.0
    message_max_diff: float = 0.0
    paper_gpu_s: float | None = None
    paper_cpu_s: float | None = None


def message_timing(mrf: model.MRF, n_messages: int = 3, block: int = 1024, seed: int = 0) -> tuple[float, float, float]:
    """Time messages of the dense paper form and of the sparse kernel from the same inputs.

    The inputs are the unary times the first iteration's (uniform) messages. Ours: one
    flooding sweep over every directed edge (the batch the kernel is built for), divided
    by the number of edges. Dense: Eq. 7 with :func:`intrinsym.mrf.model.pairwise_dense` for
    ``n_messages`` random edges, evaluated in blocks of ``block`` rows of the
    |Pt| x |Pt| table (whose construction from the sparse rows is not timed; beyond the
    sparse radius the distance is set to inf, where Psi = rho^2 as for any distance
    beyond longest edge + delta). Those messages are compared with ours.

    Returns
    -------
    dense_s, sparse_s : float
        Mean seconds per message.
    max_diff : float
        Largest difference of the max-normalised messages.
    """
    n_s, n_t = mrf.unary.shape
    n_dir = 2 * len(mrf.edges)
    ptr, directed = bp.incoming_edges(mrf.edges, n_s)
    sweep = bp.sparse_sweep(mrf, np.float32)
    steps = bp.schedule_steps("flooding", np.arange(n_s), mrf.edges, ptr, directed)
    read = np.ones((n_dir, n_t), dtype=np.float32)
    write = read.copy()
    moved = np.zeros(n_dir)
    sweep(read, write, steps, moved)  # compile
    t0 = time.perf_counter()
    sweep(read, write, steps, moved)
    sparse_s = (time.perf_counter() - t0) / max(1, n_dir)
    rng = np.random.default_rng(seed)
    outs = rng.choice(n_dir, size=min(n_messages, n_dir), replace=False)
    sender = mrf.edges[outs >> 1, outs & 1]
    tg = mrf.targets
    rows = np.repeat(np.arange(n_t), np.diff(tg.indptr))
    dense_s = 0.0
    max_diff = 0.0
    for s, out in zip(sender, outs):
        h = mrf.unary[s].astype(np.float64)
        msg = np.zeros(n_t)
        d_edge = float(mrf.edge_length[out >> 1])
        for lo in range(0, n_t, block):
            hi = min(n_t, lo + block)
            dist = np.full((hi - lo, n_t), np.inf)
            sel = (rows >= lo) & (rows < hi)
            dist[rows[sel] - lo, tg.indices[sel]] = tg.dist[sel]
            t0 = time.perf_counter()
            msg += model.pairwise_dense(d_edge, dist, mrf.lam, mrf.rho).T @ h[lo:hi]
            dense_s += time.perf_counter() - t0
        max_diff = max(max_diff, float(np.abs(msg / msg.max() - write[out]).max()))
    return dense_s / max(1, len(outs)), sparse_s, max_diff


def _peak_memory_mb() -> float:
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 2**10


def _describe(event: ProgressEvent) -> str:
    if isinstance(event, BPIteration):
        return f"bp iteration {event.iteration}: max message change {event.max_change:.3g}"
    return f"{event.stage}: {event.seconds:.2f} s"


def run_case(case: Case, iterations: int, n_messages: int, log: Callable[[str], None]) -> CaseResult:
    """Run one case in this process: the pipeline, then the message timing."""
    p = Params(n_source=case.n_source, n_target=case.n_target, iterations=iterations)
    res = pipeline.detect(case.mesh, p, progress=lambda event: log(_describe(event)))
    info = res.info
    log("timing messages, dense paper form against ours")
    dense_s, sparse_s, diff = message_timing(res.mrf(), n_messages)
    return CaseResult(
        name=case.name,
        mesh=case.mesh,
        sizes=asdict(info.sizes),
        stages=dict(info.seconds),
        bp_setup=info.bp.setup_seconds,
        bp_per_iteration=info.bp.seconds_per_iteration,
        bp_total=info.seconds["bp"],
        iterations=info.bp.iterations,
        converged=info.bp.converged,
        peak_memory_mb=_peak_memory_mb(),
        dense_message_s=dense_s,
        sparse_message_s=sparse_s,
        dense_over_sparse=dense_s / sparse_s if sparse_s > 0 else float("inf"),
        message_max_diff=diff,
        paper_gpu_s=case.paper_gpu_s,
        paper_cpu_s=case.paper_cpu_s,
    )


def _child(case: Case, iterations: int, n_messages: int, queue) -> None:
    try:
        result = run_case(case, iterations, n_messages, lambda line: queue.put(("log", line)))
        queue.put(("done", asdict(result)))
    except Exception as err:  # reported to the parent, which raises it
        queue.put(("error", f"{case.name}: {type(err).__name__}: {err}"))


def _next_message(queue, proc, name: str) -> tuple[str, Any]:
    """The child's next message; RuntimeError once it has ended without one (killed, or
    dead before it could report), instead of waiting for ever."""
    while True:
        try:
            return queue.get(timeout=_POLL_SECONDS)
        except Empty:
            if proc.is_alive():
                continue
        try:  # a message sent just before the exit may still be in the pipe
            return queue.get(timeout=_POLL_SECONDS)
        except Empty:
            proc.join()
            code = proc.exitcode
            raise RuntimeError(f"{name}: the benchmark process ended without a result (exit code {code})") from None


def run(
    cases: Sequence[Case],
    iterations: int = 100,
    n_messages: int = 3,
    log: Callable[[str, str], None] | None = None,
) -> list[CaseResult]:
    """Run cases one after another, each in a fresh child process.

    Parameters
    ----------
    cases : sequence of Case
    iterations : int
        Maximum BP iterations (the paper: 100); BP stops earlier when it converges.
    n_messages : int
        Messages timed in the dense-against-sparse comparison.
    log : callable(case name, line), optional
        Progress lines of the running case.

    Returns
    -------
    list of CaseResult
    """
    ctx = multiprocessing.get_context("spawn")
    results = []
    for case in cases:
        queue = ctx.Queue()
        proc = ctx.Process(target=_child, args=(case, iterations, n_messages, queue))
        proc.start()
        while True:
            kind, payload = _next_message(queue, proc, case.name)
            if kind == "log":
                if log is not None:
                    log(case.name, payload)
                continue
            break
        proc.join()
        if kind == "error":
            raise RuntimeError(payload)
        results.append(CaseResult(**payload))
    return results


def table(results: Sequence[CaseResult]) -> list[list[str]]:
    """Rows of the printed table, header first."""
    head = [
        "case",
        "|Ps|",
        "|Pt|",
        "max|N|",
        "geodesics",
        "descriptors",
        "bp setup",
        "bp/iter",
        "bp",
        "iters",
        "total",
        "peak MB",
        "dense/ours",
        "paper GPU",
        "paper CPU",
    ]
    rows = [head]
    for r in results:
        st = r.stages
        rows.append(
            [
                r.name,
                str(r.sizes["source"]),
                str(r.sizes["target"]),
                str(r.sizes["max_degree"]),
                f"{st.get('geodesics', 0):.2f}",
                f"{st.get('descriptors', 0):.2f}",
                f"{r.bp_setup:.2f}",
                f"{r.bp_per_iteration:.3f}",
                f"{r.bp_total:.2f}",
                f"{r.iterations}{'' if r.converged else '+'}",
                f"{sum(st.values()):.1f}",
                f"{r.peak_memory_mb:.0f}",
                f"{r.dense_over_sparse:.0f}x",
                "-" if r.paper_gpu_s is None else f"{r.paper_gpu_s:.1f}",
                "-" if r.paper_cpu_s is None else f"{r.paper_cpu_s:.0f}",
            ]
        )
    return rows


@dataclass(frozen=True)
class Profile:
    """Where the time of one ``detect`` goes (seconds).

    Attributes
    ----------
    mesh : str
    working_vertices : int
        Vertices of the working surface (after subdivision).
    stages : dict of str -> float
        Seconds per pipeline stage, as in ``run.json``.
    bp_iterations : tuple of float
        Seconds of every BP iteration (all passes, in order).
    descriptor_steps : dict of str -> float
        The descriptor stage's steps timed again one by one on the same surface and
        samples: the Laplacian, the eigenpairs (Laplacian included), the WKS distances,
        the spin images' surface cloud, the spin images, their NMI, and the geodesics
        to the calibration targets.
    """

    mesh: str
    working_vertices: int
    stages: dict
    bp_iterations: tuple
    descriptor_steps: dict


def descriptor_steps(mesh: str, p: Params) -> tuple[int, dict[str, float]]:
    """Time the steps of the descriptor stage of a self-matching ``detect`` one by one.

    Returns
    -------
    working_vertices : int
    seconds : dict of str -> float
    """
    seconds: dict[str, float] = {}

    def timed(name: str, fn: Callable, *args, **kwargs):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        seconds[name] = seconds.get(name, 0.0) + time.perf_counter() - t0
        return out

    surf = prepare(as_shape(mesh), pipeline.min_vertices(p))
    ps, pt = pipeline.sample_pair(surf, surf, p)
    v, f = surf.shape.vertices, surf.shape.faces
    timed("laplacian", laplacian.laplace_beltrami, v, f)
    evals, evecs = timed("eigenpairs", unary.spectrum, surf, p.eigenpairs, p.eigen_coarse)

    def wks() -> np.ndarray:
        energies, sigma = descriptors.wks_energies(evals, p.energies)
        a = descriptors.wave_kernel_signature(evals, evecs[ps], energies, sigma)
        return cdist(a, descriptors.wave_kernel_signature(evals, evecs[pt], energies, sigma))

    timed("wks", wks)
    cloud = v if f is None else timed("spin cloud", sampling.area_uniform_points, v, f, p.spin_cloud, seed=p.seed)[0]
    images = [
        timed("spin images", descriptors.spin_images, v[x], surf.normals[x], cloud, p.spin_radius, p.spin_bins)
        for x in (ps, pt)
    ]
    quantized = [descriptors.quantize(im, p.spin_levels) for im in images]
    timed("nmi", descriptors.nmi, quantized[0], quantized[1], p.spin_levels)
    spacing = p.target_spacing or sampling.spacing_for_count(1.0, len(pt))
    timed("near targets", unary.near_targets, surf, ps, pt, max((OFFSET_TARGETS + 2) * spacing, p.trivial_radius))
    return len(v), seconds


def profile(mesh: str, p: Params, log: Callable[[str], None] | None = None) -> Profile:
    """Run ``detect`` on ``mesh`` with ``p`` (in this process), then time the descriptor
    steps again one by one (:func:`descriptor_steps`); Numba kernels are compiled (or
    loaded from the cache) by the first run, so the steps' times are warm."""
    iteration_seconds: list[float] = []
    last = [time.perf_counter()]

    def progress(event: ProgressEvent) -> None:
        now = time.perf_counter()
        if isinstance(event, BPIteration):
            iteration_seconds.append(now - last[0])
        last[0] = now
        if log is not None:
            log(_describe(event) if not isinstance(event, StageDone) else f"{event.stage}: {event.seconds:.2f} s")

    res = pipeline.detect(mesh, p, progress=progress)
    working, steps = descriptor_steps(mesh, p)
    return Profile(mesh, working, dict(res.info.seconds), tuple(iteration_seconds), steps)


def profile_lines(prof: Profile) -> list[str]:
    """The printed profile: stages, descriptor steps, BP iterations."""
    total = sum(prof.stages.values())
    lines = [f"{prof.mesh}: {prof.working_vertices} working vertices, {total:.2f} s in all"]
    lines += [f"  {name:<14}{sec:8.2f} s  {100 * sec / total:5.1f} %" for name, sec in prof.stages.items()]
    lines.append("  descriptor steps (timed again one by one):")
    lines += [f"    {name:<12}{sec:8.2f} s" for name, sec in prof.descriptor_steps.items()]
    its = np.asarray(prof.bp_iterations)
    if its.size:
        lines.append(f"  bp: {its.size} iterations, {its.mean():.3f} s each (min {its.min():.3f}, max {its.max():.3f})")
    return lines
