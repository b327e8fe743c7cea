"""Shared fixtures: small generated shapes and the optional research data set."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

# One OpenBLAS thread for the run and the processes it starts (before NumPy and SciPy
# load the library, which reads it once): on two cores its threads spin against each
# other and against the Numba workers, and the small problems of the tests gain nothing
# from them (a spot detect at 20 / 200: descriptors 1.4-4.5 s -> 0.5 s on a loaded
# machine). A value the caller set is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pytest

# The rest (trimesh, SciPy, Hypothesis, the package) is imported where it is used: the
# pytest-xdist controller imports this file too, before it starts the workers, and runs
# no test (the imports took it 1.1 s).
if TYPE_CHECKING:
    from intrinsym.mesh import generated as shapes


def pytest_configure(config: pytest.Config) -> None:
    """Property tests draw the same examples on every run (a test that fails, fails again
    on a fresh clone); HYPOTHESIS_PROFILE=explore draws new ones, to look for new failures.
    Loaded in each process that runs tests (not in the pytest-xdist controller), before
    the test modules are collected."""
    if getattr(config, "workerinput", None) is None and config.getoption("numprocesses", None):
        return
    from hypothesis import settings

    settings.register_profile("reproducible", derandomize=True, database=None)
    settings.register_profile("explore", derandomize=False)
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "reproducible"))


#: The research data folder: $INTRINSYM_DATA, else the development checkout's default beside the repository.
DATA = Path(os.environ.get("INTRINSYM_DATA") or Path(__file__).resolve().parents[2] / "shared" / "data")


def shared(relative: str) -> Path:
    """Path of a file of the research data folder ``DATA``, skipping the test when it is absent."""
    path = DATA / relative
    if not path.exists():
        pytest.skip(f"research data not available: {path} (set INTRINSYM_DATA to the research data folder)")
    return path


#: The default run's budget (issue 49): its wall time on a quiet 2-core machine, both cores
#: working (pytest-xdist, ``-n 2`` in pyproject's addopts). Heavier cases are marked
#: ``slow`` and run by CI's ``-m slow`` line.
BUDGET_S = 90.0


#: Test modules that share a fixture of seconds (a detect, a match, a browser) computed once
#: per process: the scheduler below gives the modules of one group to one worker, which
#: computes it once (plain ``load`` scheduling computed it on each worker that drew one of
#: their tests). ``example_detected``, ``browser`` and ``turned_figure_match`` are session
#: fixtures of two modules each (the last two's modules one group); the others hold module
#: fixtures (``spot_result`` and ``spot_again``, ``star`` and ``figure``, ``mirror_results``,
#: ``star``, ``half_matched``).
SHARED_FIXTURE_GROUPS = {
    "test_cli.py": "example_detected",
    "test_reliability.py": "example_detected",
    "test_viewer.py": "browser, turned_figure_match",
    "test_export.py": "browser, turned_figure_match",
    "test_match_modes.py": "browser, turned_figure_match",
    "test_pipeline.py": "test_pipeline.py",
    "test_generated.py": "test_generated.py",
    "test_unary.py": "test_unary.py",
    "test_symmetry_group.py": "test_symmetry_group.py",
}


def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object | None:
    """For ``--dist load`` (the default with ``-n``): pytest-xdist's scope scheduling with one
    work unit per group of :data:`SHARED_FIXTURE_GROUPS` and per other test, the groups
    first (xdist sorts the units by their number of tests), so that the tail is single tests.
    (``--dist loadgroup`` would do it by ``xdist_group`` marks, but pytest-xdist 3.8 renames
    the node ids it groups by through ``Item._nodeid``, which pytest 9.2 no longer reads.)"""
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class SharedFixtureScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0].rsplit("/", 1)[-1]
            return SHARED_FIXTURE_GROUPS.get(module, nodeid)

    return SharedFixtureScheduling(config, log)


_STARTED = pytest.StashKey[float]()


def pytest_sessionstart(session: pytest.Session) -> None:
    session.config.stash[_STARTED] = time.perf_counter()
    share_the_cores()


def share_the_cores() -> None:
    """In a pytest-xdist worker, give this process's Numba kernels its share of the cores.

    The workers already run tests on every core: a kernel that also starts a thread per
    core oversubscribes them (the default run beside a one-core job, side by side: 259 s of
    CPU against 291 s with every kernel on two threads). Only this process's count is
    lowered: ``NUMBA_NUM_THREADS`` stays as it is (Numba reads it again when it compiles,
    on a fresh install, and refuses a value other than that of the threads it launched),
    so ``tests/test_threads.py`` can still raise the count to test the threaded paths, and
    processes the tests start keep theirs.
    """
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if workers < 2:
        return
    import numba

    share = max(1, (os.cpu_count() or 1) // workers)
    numba.set_num_threads(min(share, numba.config.NUMBA_NUM_THREADS))


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter, config: pytest.Config) -> None:
    """Print the run's wall time beside the budget, and its summed test durations (after ``--durations``)."""
    total = sum(
        getattr(report, "duration", 0.0)
        for reports in terminalreporter.stats.values()
        for report in reports
        if isinstance(report, pytest.TestReport)
    )
    wall = time.perf_counter() - config.stash.get(_STARTED, time.perf_counter())
    workers = getattr(config.option, "numprocesses", None) or 1
    selection = config.option.markexpr or "all"
    budget = f"budget {BUDGET_S:.0f} s on a quiet 2-core machine" if "not slow" in selection else "no budget"
    terminalreporter.write_line(
        f"tests ({selection}): {wall:.1f} s wall, {total:.1f} s of test durations over {workers} worker(s); {budget}"
    )


# A square pyramid: quad base (0, 1, 2, 3) and apex 4.
PYRAMID_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1.0]], dtype=np.float64)
PYRAMID_F = np.array(  # the quad fan-triangulated from its first corner, then the sides
    [[0, 3, 2], [0, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]], dtype=np.int64
)


def sphere_points(n: int, seed: int = 0, radius: float = 1.0) -> np.ndarray:
    """(n, 3) random points on the sphere of the given radius."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    return radius * p / np.linalg.norm(p, axis=1, keepdims=True)


def unit_sphere(subdivisions: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of an icosphere of unit area."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(s.vertices) / np.sqrt(4 * np.pi), np.asarray(s.faces)


def mirror_shape(subdivisions: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A bent ellipsoid whose only symmetry is the mirror x -> -x, with its vertex map:
    an icosphere of ``subdivisions`` (4: 2,562 vertices; 3: 642, the working size of a
    detect at 300 targets, not subdivided), bent.

    Returns vertices (N,3), faces (F,3) and sym (N,) with vertex sym[i] the mirror of i.
    """
    import trimesh
    from scipy.spatial import cKDTree

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = sphere.vertices * [0.6, 1.5, 0.5]
    v[:, 2] += 0.35 * v[:, 1] ** 2 + 0.25 * v[:, 1]
    v[:, 0] *= 1.0 + 0.3 * np.tanh(v[:, 1])
    reflected = v * [-1.0, 1.0, 1.0]
    dist, sym = cKDTree(v).query(reflected)
    assert dist.max() < 1e-9
    return v, np.asarray(sphere.faces), sym.astype(np.int64)


@pytest.fixture
def mirror():
    return mirror_shape()


def cli_run(capsys: pytest.CaptureFixture[str], *args: object) -> subprocess.CompletedProcess:
    """``intrinsym ARGS`` in this process, as a process would end: the exit code
    (``cli.main``'s, or an argument error's SystemExit), standard output and error.

    For the tests of what a command prints and returns (a process costs 1-2 s of imports).
    The commands as processes: ``python -m intrinsym.app.cli detect`` (``example_detected``,
    read by test_cli and test_reliability), ``python -m intrinsym`` (test_shared_machines'
    address-space limit, test_batch's cluster), and those a test needs a process for
    (signals, resource limits, environments, memory).
    What the test printed before is read from ``capsys`` and dropped.
    """
    from intrinsym.app import cli

    argv = [str(a) for a in args]
    capsys.readouterr()
    try:
        code = cli.main(argv)
    except SystemExit as stop:
        code = stop.code
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(argv, code, out, err)


#: The browser of the viewer tests: Debian's chromium (CI installs it in .ci/run).
CHROMIUM = Path("/usr/bin/chromium")


@pytest.fixture(scope="session")
def browser():
    """A headless Chromium driven by Playwright, started once for the session (about 1.5 s
    a start): each viewer test opens its own page in it (a fresh browser context), and
    closes it. Skips where Playwright or chromium is missing."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install -e .[test])")
    executable = CHROMIUM if CHROMIUM.exists() else shutil.which("chromium")
    if executable is None:
        pytest.skip("chromium is not installed (apt-get install -y chromium; CI installs it in .ci/run)")
    pw = sync_api.sync_playwright().start()
    try:
        # SwiftShader: WebGL on a machine without a GPU.
        swiftshader = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
        chromium = pw.chromium.launch(executable_path=str(executable), args=["--no-sandbox", *swiftshader])
        yield chromium
        chromium.close()
    finally:
        pw.stop()


#: The command line's small sizes on the shipped example: every run takes seconds.
CLI_SMALL = ["--source", "30", "--target", "300", "--spin-cloud", "5000", "--iterations", "5"]


@pytest.fixture(scope="session")
def example_detected(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """``intrinsym detect --example -o OUT --json`` at ``CLI_SMALL``, run once per session
    as its own process: the result folder and the summary printed on standard output.

    Shared by every test that reads such a result: read it, or copy it
    (``shutil.copytree``) before writing into it.
    """
    out = tmp_path_factory.mktemp("example") / "spot"
    argv = [sys.executable, "-m", "intrinsym.app.cli", "detect", "--example", "-o", str(out), *CLI_SMALL, "--json"]
    p = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    return out, p.stdout


@pytest.fixture(scope="session")
def turned_figure_match():
    """The posed figure (434 vertices) matched to itself turned by 90 degrees about z, at
    50 / 500, given the turned copy's own mirror map (``target_symmetry``): the figure A,
    the turned copy B, the mirror map and the result. Computed once per session for the
    tests of the match's two answers (test_match_modes.py) and of the viewer's page of
    such a match (test_viewer.py), which read it and write nothing into it."""
    import intrinsym
    from intrinsym.mesh import generated as shapes
    from intrinsym.mesh.shape import from_arrays

    figure = shapes.figure(6)
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    a, b = from_arrays(figure.vertices, figure.faces), from_arrays(figure.vertices @ turn.T, figure.faces)
    mirror = figure.symmetries[0]
    result = intrinsym.match(a, b, intrinsym.make_params(n_source=50, n_target=500), target_symmetry=mirror)
    return a, b, mirror, result


def sphere_result(folder: Path) -> tuple[Path, np.ndarray]:
    """A saved self-matching result on a unit icosphere whose marginals are known.

    Every vertex is a target sample; every 16th vertex is a source sample, and its
    marginal is 1 at the target nearest its antipode and 1e-3 elsewhere. The mesh is
    written as ``folder/sphere.off`` and named in run.json.

    Returns the result directory and the (V, 3) vertices.
    """
    import trimesh
    from scipy.spatial import cKDTree

    from intrinsym import Params, Result
    from intrinsym.result.runinfo import BPStats, Resolved, RunInfo, Sizes

    sphere = trimesh.creation.icosphere(subdivisions=3)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    path = folder / "sphere.off"
    with open(path, "w") as fh:
        fh.write(f"OFF\n{len(v)} {len(f)} 0\n")
        np.savetxt(fh, v)
        np.savetxt(fh, np.column_stack([np.full(len(f), 3), f]), fmt="%d")
    sources = np.arange(0, len(v), 16)
    _, antipode = cKDTree(v).query(-v[sources])
    marginals = np.full((len(sources), len(v)), 1e-3, dtype=np.float32)
    marginals[np.arange(len(sources)), antipode] = 1.0
    _, nearest = cKDTree(v[sources]).query(v[sources], k=4)
    edges = np.unique(np.sort(np.column_stack([np.repeat(nearest[:, 0], 3), nearest[:, 1:].ravel()]), axis=1), axis=0)
    info = RunInfo(
        mode="detect",
        input=str(path),
        sizes=Sizes(len(sources), len(v), len(edges), 2 * len(edges), 3, 0, len(v), len(v)),
        resolved=Resolved(1.0, 1.0, 0.1, 0.05, 0.5, 1e-3, 1.0),
        seconds={"bp": 0.0},
        bp=BPStats("cpu", 1, True, 0.0, (0.0,), 0.0, 0.0, 0),
    )
    out = folder / "out"
    Result(
        v[sources], v.copy(), sources, np.arange(len(v)), edges.astype(np.int64), marginals, marginals, Params(), info
    ).save(out)
    return out, v


def unit_square_grid(n=24):
    """The unit square (area 1) as a triangulated (n+1) x (n+1) grid, vertex i*(n+1)+j at
    (i/n, j/n): flat and convex, so geodesics are straight lines."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    v = np.column_stack([i.ravel() / n, j.ravel() / n, np.zeros(i.size)])
    a = (i[:-1, :-1] * (n + 1) + j[:-1, :-1]).ravel()
    f = np.concatenate([np.column_stack([a, a + n + 1, a + 1]), np.column_stack([a + 1, a + n + 1, a + n + 2])])
    return v, f


@pytest.fixture(scope="session")
def figure_and_part() -> tuple[shapes.GeneratedShape, np.ndarray]:
    """The posed figure (434 vertices) and the vertices of it above y = -1 (one limb's
    end cut away, 361 vertices)."""
    from intrinsym.mesh import generated as shapes

    figure = shapes.figure(6)
    keep = figure.vertices[:, 1] > -1.0
    return figure, np.flatnonzero(keep)


def cut_mesh(vertices: np.ndarray, faces: np.ndarray, keep: np.ndarray):
    """The mesh of the triangles whose three corners ``keep`` (bool, one per vertex) holds,
    renumbered, and the original index of each of its vertices (a kept vertex left without
    a triangle is dropped)."""
    from intrinsym.mesh.shape import from_arrays

    kept = faces[keep[faces].all(axis=1)]
    used = np.unique(kept)
    index = np.full(len(vertices), -1)
    index[used] = np.arange(len(used))
    return from_arrays(vertices[used], index[kept]), used


def part_of(figure: shapes.GeneratedShape, used: np.ndarray):
    """The figure's mesh restricted to ``used`` (faces with all three corners in it)."""
    keep = np.zeros(len(figure.vertices), dtype=bool)
    keep[used] = True
    part, kept = cut_mesh(figure.vertices, figure.faces, keep)
    assert np.array_equal(kept, used), "a vertex of the part lost every triangle"
    return part


def right_share(figure: shapes.GeneratedShape, used: np.ndarray, images: np.ndarray) -> float:
    """Share of the part's vertices whose image lies within 0.10 sqrt(area) of their own
    vertex of the figure or of its image under one of the figure's symmetries."""
    from intrinsym.evaluation import evaluate
    from intrinsym.geodesics import geodesics
    from intrinsym.mesh.shape import from_arrays, surface_area

    unit = np.sqrt(surface_area(from_arrays(figure.vertices, figure.faces)))
    graph = geodesics.surface_graph(figure.vertices / unit, figure.faces)
    truths = [used, *(np.asarray(s)[used] for s in figure.symmetries)]
    errors = np.min([evaluate.map_errors(images, t, graph) for t in truths], axis=0)
    return float(np.mean(errors <= 0.10))
