"""``intrinsym batch`` on a real Dask cluster (two worker processes on loopback): the
results are those of ``detect``, a corrupt file is a failed row, a killed worker's item
is run again and reported once, an interrupted batch resumes without redoing what it
finished, a separately started ``dask scheduler`` + ``dask worker`` serves the same
batch, and pairs mode runs ``match`` over the Sumner horse frames."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlparse

import numpy as np
import psutil
import pytest

import intrinsym
from conftest import shared
from intrinsym import Params, Result
from intrinsym.app.batching import engine, items, work
from intrinsym.app.batching import rows as batch_rows
from intrinsym.app.cli import main
from intrinsym.mesh import generated as shapes
from intrinsym.result.modes import two_modes

# Distributed and pandas are imported by the tests that use them: every pytest-xdist worker
# collects this module, and their imports took each worker 0.9 s before any test ran
if TYPE_CHECKING:
    import pandas as pd

#: Tiny sizes: every item takes seconds.
TINY = {"n_source": 20, "n_target": 200, "spin_cloud": 2000, "iterations": 5}
TINY_FLAGS = ["--source", "20", "--target", "200", "--spin-cloud", "2000", "--iterations", "5"]
PARAMS = Params(**TINY)
#: The tests on the module's LocalCluster of two worker processes: CI runs them (-m slow); the
#: default run's end-to-end batch is tests/test_examples.py's batch_folder.py.
CLUSTER = pytest.mark.slow
#: Environment of every process started here: one thread each (two cores in CI).
ONE_THREAD = engine.thread_environment(1)


@pytest.fixture(scope="module")
def meshes(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two generated shapes with their symmetry maps, the shipped example and a corrupt file."""
    folder = tmp_path_factory.mktemp("meshes")
    shapes.save(shapes.cuboctahedron(subdivisions=2), folder / "cubo.off")
    shapes.save(shapes.star(resolution=6), folder / "star.off")
    shutil.copy(intrinsym.example_path(), folder / "spot.obj")
    (folder / "broken.off").write_text("OFF\n3 1 0\n0 0 0\n1 0\n")
    return folder


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of two single-threaded worker processes on loopback."""
    import dask
    import distributed

    with dask.config.set({"distributed.scheduler.allowed-failures": engine.ALLOWED_FAILURES}):
        with distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            env=ONE_THREAD,
            dashboard_address="127.0.0.1:0",
            silence_logs=40,
        ) as c:
            yield c


@pytest.fixture(scope="module")
def by_path(meshes: Path, cluster, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, pd.DataFrame]:
    out = tmp_path_factory.mktemp("by_path")
    frame = intrinsym.batch([str(meshes)], out, PARAMS, scheduler=cluster.scheduler_address, transport="path")
    return out, frame


def _mtimes(folder: Path) -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}


def test_a_manifest_cell_that_is_no_value_names_the_file_and_column(tmp_path: Path) -> None:
    (tmp_path / "m.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    (tmp_path / "list.csv").write_text("mesh,rho,n_source\nm.off,0.3,\n")
    assert items.read_manifest(str(tmp_path / "list.csv"))[0]["params"] == {"rho": 0.3}
    (tmp_path / "bad.csv").write_text("mesh,rho\nm.off,high\n")
    with pytest.raises(intrinsym.ParameterError, match=r"bad\.csv: manifest column rho: 'high' is not a float"):
        items.read_manifest(str(tmp_path / "bad.csv"))


@CLUSTER
def test_results_are_those_of_detect_and_a_corrupt_file_is_a_failed_row(by_path, meshes: Path, tmp_path: Path) -> None:
    import pandas as pd

    out, frame = by_path
    assert sorted(frame["name"]) == ["broken", "cubo", "spot", "star"]
    rows = frame.set_index("name")
    assert rows.loc["broken", "status"] == "failed" and "broken.off" in rows.loc["broken", "error"]
    assert rows.loc["spot", "status"] == "done", rows.loc["spot", "error"]
    for name, mesh in (("cubo", "cubo.off"), ("star", "star.off")):
        assert rows.loc[name, "status"] == "done", rows.loc[name, "error"]
        saved = Result.load(out / name)
        alone = tmp_path / name  # `intrinsym detect` with the workers' threads (BLAS sums depend on them)
        command = [sys.executable, "-m", "intrinsym", "detect", str(meshes / mesh), "-o", str(alone), *TINY_FLAGS, "-q"]
        subprocess.run(command, env={**os.environ, **ONE_THREAD}, check=True, timeout=300)
        for file in ("marginals", "unary"):
            np.testing.assert_array_equal(getattr(saved, file), getattr(Result.load(alone), file))
        np.testing.assert_array_equal(np.load(out / name / "symmetry_map.npy"), np.load(alone / "symmetry_map.npy"))
        assert json.loads((out / name / "symmetries.json").read_text()) == json.loads(
            (alone / "symmetries.json").read_text()
        )
        assert (
            saved.info.content_key
            == rows.loc[name, "key"]
            == items.content_key(items.Item(name, str(meshes / mesh), PARAMS))
        )
    # the generated shapes carry their symmetry maps: scored as `intrinsym evaluate` scores them
    star_scores = json.loads((out / "star" / "scores.json").read_text())
    assert star_scores["group"]["maps"] == 19  # all of star.maps.npy: scored against the nearest true map
    assert star_scores["mirror_hit"] == rows.loc["star", "mirror_hit"]
    assert star_scores["map"]["area_within_0.10"] == rows.loc["star", "map_area_within_0.10"]
    # the star's true map is a symmetry of the mesh itself: it keeps every distance
    assert rows.loc["star", "truth_distortion"] == star_scores["truth_distortion"]["above_0.05"] == 0.0
    assert np.isnan(rows.loc["spot", "mirror_hit"])
    # the global confidence needs no truth; its calibration against the truth does
    for name in ("spot", "star", "cubo"):
        if rows.loc[name, "global_symmetry"]:
            mean = float(np.load(out / name / "symmetry_confidence.npy").mean())
            assert rows.loc[name, "global_confidence"] == pytest.approx(mean, abs=1e-6)
        else:
            assert rows.loc[name, "global_confidence"] is None or np.isnan(rows.loc[name, "global_confidence"])
    assert star_scores["confidence"]["expected_calibration_error"] == rows.loc["star", "confidence_ece"]
    # a finished folder's row, read back as a re-run or another worker reads it, is the same
    for name in ("star", "cubo"):
        item = items.Item(name, str(meshes / f"{name}.off"), PARAMS)
        read_back = batch_rows.row_of_folder(item, rows.loc[name, "key"], out / name)
        for column in ("global_score", "global_confidence", "confidence_ece", "map_within_0.10"):
            assert read_back[column] == pytest.approx(rows.loc[name, column], nan_ok=True), column
    assert np.isnan(rows.loc["spot", "confidence_ece"])
    on_disk = pd.read_csv(out / "summary.csv")
    assert list(on_disk["name"]) == list(frame["name"])


@CLUSTER
def test_a_rerun_skips_what_is_done_and_new_parameters_recompute(
    by_path, meshes: Path, cluster, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    shutil.copytree(by_path[0], out)
    before = _mtimes(out / "star")
    again = intrinsym.batch([str(meshes / "star.off"), str(meshes / "cubo.off")], out, PARAMS, scheduler="tcp://0:1")
    assert list(again["status"]) == ["skipped", "skipped"]  # no cluster needed: nothing to run
    assert _mtimes(out / "star") == before
    assert again["seconds"].tolist() == by_path[1].set_index("name").loc[["star", "cubo"], "seconds"].tolist()
    # a skipped row reads the global confidence back from the folder
    assert again["global_confidence"].tolist() == pytest.approx(
        by_path[1].set_index("name").loc[["star", "cubo"], "global_confidence"].tolist(), nan_ok=True
    )
    seed = Params(**{**TINY, "seed": 1})
    changed = intrinsym.batch([str(meshes / "star.off")], out, seed, scheduler=cluster.scheduler_address)
    assert list(changed["status"]) == ["done"] and _mtimes(out / "star") != before


@CLUSTER
def test_bytes_transport_gives_the_same_result(by_path, meshes: Path, cluster, tmp_path: Path) -> None:
    out, _ = by_path
    frame = intrinsym.batch(
        [str(meshes / "cubo.off"), str(meshes / "broken.off")],
        tmp_path,
        PARAMS,
        scheduler=cluster.scheduler_address,
        transport="bytes",
    )
    assert list(frame["status"]) == ["done", "failed"]
    sent, read = Result.load(tmp_path / "cubo"), Result.load(out / "cubo")
    np.testing.assert_array_equal(sent.marginals, read.marginals)
    assert sent.info.input == str(meshes / "cubo.off")  # the original path, not the worker's copy
    assert frame["mirror_hit"].iloc[0] == pytest.approx(read_scores(out / "cubo")["mirror_hit"])


def read_scores(folder: Path) -> dict:
    return json.loads((folder / "scores.json").read_text())


@CLUSTER
def test_a_killed_worker_s_item_runs_again_and_is_reported_once(meshes: Path, cluster, tmp_path: Path) -> None:
    import distributed

    killed: list[str] = []

    def kill_one_busy_worker() -> None:
        with distributed.Client(cluster.scheduler_address, timeout="20s") as client:
            pids = client.run(os.getpid)  # asked beforehand: the kill follows the poll at once
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and not killed:
                busy = [w for w, keys in client.processing().items() if keys and w in pids]
                if busy:
                    os.kill(pids[busy[0]], signal.SIGKILL)
                    killed.append(busy[0])
                time.sleep(0.05)

    killer = threading.Thread(target=kill_one_busy_worker)
    killer.start()
    inputs = [str(meshes / name) for name in ("cubo.off", "star.off")]
    frame = intrinsym.batch(inputs, tmp_path, PARAMS, scheduler=cluster.scheduler_address)
    killer.join()
    assert killed, "no worker was killed"
    assert sorted(frame["name"]) == ["cubo", "star"]  # each item exactly once
    assert (frame["status"] == "done").all(), frame[["name", "error"]]
    assert killed[0] not in set(frame["worker"])  # every item was finished by a live worker
    cluster.wait_for_workers(2, timeout=120)


def _wait_for(condition, seconds: float = 180) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.1)


@pytest.mark.slow  # a scheduler, a worker and two batch processes started from scratch (CI: -m slow)
def test_an_interrupted_batch_resumes_on_a_separately_started_scheduler(meshes: Path, tmp_path: Path) -> None:
    """``dask scheduler`` + ``dask worker`` on loopback, ``--scheduler``; SIGINT after the
    first item; the re-run leaves the finished folders untouched and runs the rest."""
    import pandas as pd

    env = {**os.environ, **ONE_THREAD}
    bin_dir = Path(sys.executable).parent
    file = tmp_path / "scheduler.json"
    scheduler = subprocess.Popen(
        [
            bin_dir / "dask",
            "scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--no-dashboard",
            "--scheduler-file",
            file,
        ],
        env=env,
        stderr=subprocess.DEVNULL,
    )
    worker = None
    try:
        _wait_for(file.is_file, 60)
        worker = subprocess.Popen(
            [bin_dir / "dask", "worker", "--scheduler-file", file, "--nthreads", "1", "--no-dashboard"],
            env=env,
            stderr=subprocess.DEVNULL,
        )
        address = json.loads(file.read_text())["address"]
        out = tmp_path / "out"
        # twice each shape: several items are still to run when the first is stored
        folder = tmp_path / "in"
        folder.mkdir()
        for m in ("cubo.off", "star.off", "spot.obj"):
            for copy in ("", "_b"):
                shutil.copy(meshes / m, folder / m.replace(".", f"{copy}."))
        names = ["cubo", "star", "spot", "cubo_b", "star_b", "spot_b"]
        inputs = [str(p) for p in sorted(folder.iterdir())]
        command = [sys.executable, "-m", "intrinsym", "batch", *inputs, "-o", str(out), "--scheduler", address]
        # a user's Ctrl-C reaches a process with the default SIGINT handler; a child
        # inherits "ignore" from a parent (here: the test runner) that has set it
        client = subprocess.Popen(
            [*command, *TINY_FLAGS, "--quiet"],
            env=env,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        _wait_for(lambda: any(items.stored_key(out / n) for n in names))
        client.send_signal(signal.SIGINT)
        assert client.wait(60) == 130
        interrupted = pd.read_parquet(out / "summary.parquet")
        assert "interrupted" in set(interrupted["status"])
        finished = [n for n in names if items.stored_key(out / n)]
        assert len(finished) < len(names)
        before = {n: _mtimes(out / n) for n in finished}
        rerun = subprocess.run([*command, *TINY_FLAGS, "--json"], env=env, capture_output=True, text=True, timeout=300)
        assert rerun.returncode == 0, rerun.stderr
        report = json.loads(rerun.stdout)
        # an item running when the client stopped may finish on the worker meanwhile: done or skipped, once
        assert report["skipped"] >= len(finished) and report["done"] >= 1
        assert report["skipped"] + report["done"] == len(names)
        assert {n: _mtimes(out / n) for n in finished} == before
        frame = pd.read_parquet(out / "summary.parquet")
        assert sorted(frame["name"]) == sorted(names) and set(frame["status"]) == {"done", "skipped"}
    finally:
        for process in (worker, scheduler):
            if process is not None:
                process.terminate()
                process.wait(30)


@CLUSTER
def test_pairs_mode_matches_the_horse_frames(cluster, tmp_path: Path) -> None:
    frames = [str(shared(f"sumner_horse/horse-0{i}.obj")) for i in (1, 2)]
    frame = intrinsym.batch(frames, tmp_path, PARAMS, pairs=True, scheduler=cluster.scheduler_address)
    assert list(frame["name"]) == ["horse-01--horse-02", "horse-02--horse-01"]
    assert (frame["status"] == "done").all(), frame["error"]
    assert (frame["mode"] == "match").all()
    run = Result.load(tmp_path / "horse-02--horse-01").info
    # run.json records each input's resolved path (the data folder may be a symbolic link)
    assert run.mode == "match" and run.target_input is not None
    assert (Path(run.input), Path(run.target_input)) == (Path(frames[1]).resolve(), Path(frames[0]).resolve())


@CLUSTER
def test_report_prints_the_aggregate_and_writes_the_plot(by_path, capsys: pytest.CaptureFixture) -> None:
    out, _ = by_path
    assert main(["batch", "--report", "-o", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert set(report["report"]) == {"broken", "cubo", "spot", "star", "all"}
    assert report["report"]["all"]["failed"] == 1 and report["report"]["all"]["items"] == 4
    assert Path(report["plot"]).stat().st_size > 1000


def test_a_manifest_sets_parameters_per_row_and_groups_pairs(meshes: Path, tmp_path: Path) -> None:
    manifest = tmp_path / "set.csv"
    manifest.write_text(
        f"mesh,symmetry_map,class,n_source,zoomout\n"
        f"{meshes / 'star.off'},{meshes / 'star.sym.npy'},a,30,false\n"
        f"{meshes / 'cubo.off'},,a,,\n"
        f"{meshes / 'spot.obj'},,b,,\n"
    )
    listed = items.collect([str(manifest)], PARAMS)
    assert [(i.name, i.group, i.params.n_source, i.params.zoomout) for i in listed] == [
        ("star", "a", 30, False),
        ("cubo", "a", 20, True),
        ("spot", "b", 20, True),
    ]
    assert listed[0].symmetry_map == str(meshes / "star.sym.npy") and listed[1].symmetry_map is None
    pairs = items.collect([str(manifest)], PARAMS, pairs=True, group_by="class")
    assert [i.name for i in pairs] == ["star--cubo", "cubo--star"]
    keys = {items.content_key(i) for i in (*listed, items.Item("x", listed[1].mesh, PARAMS))}
    assert len(keys) == 3  # the same mesh and parameters give the same key, whatever the folder
    (tmp_path / "typo.csv").write_text("mesh,n_sourec\nx.off,3\n")
    with pytest.raises(intrinsym.ParameterError, match="n_sourec"):
        items.collect([str(tmp_path / "typo.csv")], PARAMS)


def test_a_pairs_manifest_gives_each_match_its_targets_symmetry(meshes: Path, tmp_path: Path) -> None:
    """A ``target_symmetry`` column reaches ``match`` (the second mode is that map after
    the first), enters the content key, and is refused without ``--pairs``."""
    manifest = tmp_path / "pairs.csv"
    manifest.write_text(f"source,target,target_symmetry\n{meshes / 'star.off'},{meshes / 'star.off'},star.sym.npy\n")
    shutil.copy(meshes / "star.sym.npy", tmp_path / "star.sym.npy")
    (item,) = items.collect([str(manifest)], PARAMS, pairs=True)
    assert item.target_symmetry == str(tmp_path / "star.sym.npy")
    assert items.content_key(item) != items.content_key(dataclasses.replace(item, target_symmetry=None))
    result, _ = work._compute(item, str)
    mirror = np.load(meshes / "star.sym.npy")
    assert np.array_equal(result.target_symmetry, mirror)
    first, second = two_modes(result).maps
    assert np.array_equal(second, np.where(first >= 0, mirror[first], -1))
    (tmp_path / "single.csv").write_text(f"mesh,target_symmetry\n{meshes / 'star.off'},star.sym.npy\n")
    with pytest.raises(intrinsym.ParameterError, match="target_symmetry"):
        items.collect([str(tmp_path / "single.csv")], PARAMS)


def test_the_local_cluster_fits_the_cores_and_the_memory() -> None:
    few = [items.Item(str(i), "m.off", PARAMS) for i in range(3)]
    assert engine.plan_cluster(few, n_cores=16, memory=64 << 30) == engine.ClusterPlan(
        3, 5, (64 << 30) // 3, engine.item_bytes(few[0])
    )
    big = [items.Item(str(i), "m.off", Params(n_source=2000, n_target=60000)) for i in range(32)]
    plan = engine.plan_cluster(big, n_cores=16, memory=64 << 30)
    assert plan.workers * plan.item_bytes <= 64 << 30 < (plan.workers + 1) * plan.item_bytes
    assert plan.workers * plan.threads <= 16


def _one_line_error(capsys: pytest.CaptureFixture, code: int, *words: str) -> None:
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("intrinsym: error: ") and err.count("\n") == 1, err
    for word in words:
        assert word in err, err


@pytest.mark.parametrize("name", ["../x", "ABSOLUTE", "..", ".", "a/b", ".hidden", "summary.csv"])
def test_a_manifest_name_that_is_not_a_plain_folder_name_is_refused(
    meshes: Path, tmp_path: Path, capsys: pytest.CaptureFixture, name: str
) -> None:
    """``name`` chooses the item's folder in OUT: a path would put the result set anywhere."""
    name = str(tmp_path / "elsewhere") if name == "ABSOLUTE" else name
    manifest = tmp_path / "list.csv"
    manifest.write_text(f"mesh,name\n{meshes / 'cubo.off'},ok\n{meshes / 'star.off'},{name}\n")
    code = main(["batch", str(manifest), "-o", str(tmp_path / "out"), *TINY_FLAGS])
    _one_line_error(capsys, code, f"{manifest}: line 3: name {name!r} is not a plain folder name")
    assert [p.name for p in tmp_path.iterdir()] == ["list.csv"]
    hidden = tmp_path / ".x.off"  # a mesh whose derived name would be empty: OUT itself
    shutil.copy(meshes / "star.off", hidden)
    with pytest.raises(intrinsym.InputError, match=r"\.x\.off: name '' is not a plain folder name"):
        items.collect([str(hidden)], PARAMS)


def _listening() -> set[tuple[str, int]]:
    """The (address, port) pairs that this process and its children listen on."""
    me = psutil.Process()
    found = set()
    for process in (me, *me.children(recursive=True)):
        with contextlib.suppress(psutil.Error):
            found |= {(c.laddr.ip, c.laddr.port) for c in process.net_connections("inet") if c.status == "LISTEN"}
    return found


def test_the_local_cluster_and_its_dashboard_listen_on_loopback_only() -> None:
    """The dashboard has no authentication: on every interface it would let anyone on the
    network see the batch and its files' names."""
    before = _listening()
    client, cluster = engine.connect(engine.ClusterPlan(1, 1, 2 << 30, 0), None)
    try:
        opened = _listening() - before
        link = urlparse(client.dashboard_link)
        ports = {port for _, port in opened}
        assert link.hostname == "127.0.0.1" and link.port in ports and cluster.scheduler.port in ports
        assert len(ports) >= 4  # scheduler, dashboard, the worker and its nanny
        assert {address for address, _ in opened} == {"127.0.0.1"}, opened
        with urllib.request.urlopen(client.dashboard_link, timeout=30) as page:  # it serves, on loopback
            assert page.status == 200
    finally:
        client.close()
        cluster.close()


def _closed_port() -> int:
    """A loopback port that nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_scheduler_where_nothing_listens_is_a_one_line_error_at_once(
    meshes: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "out"
    address = f"tcp://127.0.0.1:{_closed_port()}"
    start = time.monotonic()
    code = main(["batch", str(meshes / "star.off"), "-o", str(out), "--scheduler", address, "-q"])
    assert time.monotonic() - start < 20
    _one_line_error(capsys, code, f"--scheduler {address}: no scheduler answers there")
    assert not out.exists()


@pytest.mark.parametrize(
    ("flag", "value", "message"),
    [
        ("--workers", "0", "--workers must lie in [1, CORES] (the cores this process may use), not 0"),
        ("--workers", "1000", "--workers must lie in [1, CORES] (the cores this process may use), not 1000"),
        ("--workers", "-1", "--workers must lie in [1, CORES] (the cores this process may use), not -1"),
        ("--scheduler", "tcp://127.0.0.1:port", "--scheduler 'tcp://127.0.0.1:port': not a scheduler address"),
        ("--scheduler", "nonsense", "--scheduler 'nonsense': not a scheduler address (missing port number"),
        ("--scheduler", "tcp://127.0.0.1:70000", "not a scheduler address (port 70000 out of range)"),
    ],
)
def test_a_bad_workers_or_scheduler_value_is_a_one_line_error_before_out(
    meshes: Path, tmp_path: Path, capsys: pytest.CaptureFixture, flag: str, value: str, message: str
) -> None:
    out = tmp_path / "out"
    code = main(["batch", str(meshes / "star.off"), "-o", str(out), flag, value, *TINY_FLAGS])
    _one_line_error(capsys, code, message.replace("CORES", str(engine.cores())))
    assert not out.exists()


@pytest.mark.parametrize("summary", ["kept", "lost"])
@CLUSTER
def test_a_finished_item_with_a_corrupt_map_or_confidence_runs_again(
    by_path, meshes: Path, cluster, tmp_path: Path, summary: str
) -> None:
    """A resumed batch takes a folder as done only when its per-vertex arrays read back,
    whether the earlier summary lists it as done or not."""
    out = tmp_path / "out"
    shutil.copytree(by_path[0], out)
    if summary == "lost":
        (out / "summary.parquet").unlink()
    truncated, zeroed = out / "star" / "symmetry_map.npy", out / "cubo" / "symmetry_confidence.npy"
    truncated.write_bytes(truncated.read_bytes()[:100])
    zeroed.write_bytes(bytes(zeroed.stat().st_size))
    spot = _mtimes(out / "spot")
    inputs = [str(meshes / name) for name in ("star.off", "cubo.off", "spot.obj")]
    frame = intrinsym.batch(inputs, out, PARAMS, scheduler=cluster.scheduler_address).set_index("name")
    assert list(frame.loc[["star", "cubo", "spot"], "status"]) == ["done", "done", "skipped"], frame["error"]
    assert _mtimes(out / "spot") == spot
    for name, file in (("star", "symmetry_map.npy"), ("cubo", "symmetry_confidence.npy")):
        np.testing.assert_array_equal(np.load(out / name / file), np.load(by_path[0] / name / file))
