"""The command line under hostile conditions: outputs that cannot be written, bad
parameters, corrupt result folders, SIGTERM, a read-only install, memory limits."""

import os
import shutil
import signal
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest

import intrinsym
from conftest import CLI_SMALL as SMALL
from intrinsym import files, pipeline, resources
from intrinsym.app import cli
from intrinsym.errors import OutputError, ResultError


def one_line_error(capsys, code, *words):
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("intrinsym: error: ") and err.count("\n") == 1, err
    for word in words:
        assert word in err, err
    return err


@pytest.fixture
def no_work(monkeypatch):
    """Fail the test if the pipeline starts."""

    def refuse(*args, **kwargs):
        raise AssertionError("the pipeline ran before the output was checked")

    monkeypatch.setattr(pipeline, "detect", refuse)
    monkeypatch.setattr(pipeline, "match", refuse)


@pytest.fixture
def result_dir(example_detected):
    """The session's ``intrinsym detect --example`` result at ``SMALL`` (conftest): read or copied, never written."""
    return example_detected[0]


@pytest.mark.parametrize("where", ["file", "below_file", "unwritable"])
def test_detect_checks_its_output_before_any_work(tmp_path, capsys, monkeypatch, no_work, where):
    (tmp_path / "f").write_text("")
    out = {"file": tmp_path / "f", "below_file": tmp_path / "f" / "out", "unwritable": tmp_path / "ro" / "out"}[where]
    if where == "unwritable":
        monkeypatch.setattr(
            files.tempfile, "mkstemp", lambda **kw: (_ for _ in ()).throw(OSError(30, "Read-only file system"))
        )
    one_line_error(capsys, cli.main(["detect", "--example", "-o", str(out), *SMALL]), str(out))


def test_result_save_refuses_a_file_as_folder(tmp_path, result_dir):
    (tmp_path / "f").write_text("")
    with pytest.raises(OutputError, match="exists and is not a folder"):
        intrinsym.Result.load(result_dir).save(tmp_path / "f")


@pytest.mark.parametrize(
    "args, message",
    [
        (["--seed", "-1"], "--seed must be at least 0"),
        (["--source", "0"], "--source must be at least 2"),
        (["--source-spacing", "0"], "--source-spacing must be positive"),
        (["--calibration-k", "100000"], "--calibration-k must be at most --target"),
        (["--spin-cloud", "0"], "--spin-cloud must lie in"),
        (["--gamma", "inf"], "--gamma must be a finite number"),
        (["--rho", "nan"], "--rho must be a finite number"),
        (["--eigenpairs", "100000"], "--eigenpairs must lie in [2, 1000]"),
        (["--zoomout-seed", "60"], "need 1 <= --zoomout-seed <= --zoomout-final"),
    ],
)
def test_parameters_are_checked_before_any_work_and_named_by_flag(tmp_path, capsys, no_work, args, message):
    out = tmp_path / "out"
    one_line_error(capsys, cli.main(["detect", "--example", "-o", str(out), *args]), message)
    assert not out.exists()


def _corrupt(src: Path, dst: Path, name: str, how: str) -> None:
    shutil.copytree(src, dst)
    data = (dst / name).read_bytes()
    (dst / name).write_bytes(data[: len(data) // 2] if how == "truncate" else b"\0" * len(data))


@pytest.mark.parametrize("name", ["result.npz", "run.json"])
@pytest.mark.parametrize("how", ["truncate", "zero"])
def test_corrupt_result_folders_give_one_line_errors(tmp_path, capsys, result_dir, name, how):
    out = tmp_path / "bad"
    _corrupt(result_dir, out, name, how)
    with pytest.raises(ResultError, match=name):
        intrinsym.Result.load(out)
    sym = tmp_path / "sym.npy"
    np.save(sym, np.arange(len(intrinsym.load(intrinsym.example_path()).vertices)))
    for argv in (
        ["query", str(out), "--vertex", "0"],
        ["evaluate", str(out), "--symmetry-map", str(sym)],
        ["render", str(out)],
        ["view", str(out)],
    ):
        one_line_error(capsys, cli.main(argv), name)


def test_view_to_a_missing_folder_is_a_one_line_error(tmp_path, capsys, result_dir):
    one_line_error(capsys, cli.main(["view", str(result_dir), "-o", str(tmp_path / "missing" / "v.html")]), "v.html")


@pytest.mark.parametrize(
    ("signum", "threads", "code", "said"),
    [
        (signal.SIGTERM, "2", 143, "terminated"),
        (signal.SIGTERM, "1", 143, "terminated"),
        (signal.SIGINT, "1", 130, "interrupted"),
    ],
)
def test_sigterm_and_ctrl_c_end_the_run_cleanly(tmp_path, signum, threads, code, said):
    # 100 / 1000: seconds of work after the lock, so the signal lands mid-run; no
    # subdivision of spot (2,930 vertices), and shorter kernels than at 200 / 3000, whose
    # running kernel the exit waits for: 27 s once on a loaded machine (usually 0.3-0.5 s).
    # One thread runs the kernels on the main thread, where the signal lands in Numba's
    # dispatcher; two run them on a pool, and the main thread waits on a lock
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "intrinsym.app.cli",
            "detect",
            "--example",
            "-o",
            str(out),
            "--source",
            "100",
            "--target",
            "1000",
        ],
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "NUMBA_NUM_THREADS": threads},
        # a user's Ctrl-C reaches a process with the default SIGINT handler (a child of this
        # one may have inherited "ignore")
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    lock = tmp_path / ".out.lock"
    deadline = time.monotonic() + 120
    while not lock.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert err.strip().splitlines()[-1] == f"intrinsym: {said}"
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no result, no temporary, no lock


@pytest.mark.parametrize("module", ["llvmlite.binding.executionengine", "numba.core.serialize"])
def test_a_signal_inside_numba_is_sent_again_not_raised(monkeypatch, module):
    """An exception cannot leave llvmlite's ctypes callbacks (a SIGTERM while Numba compiles
    on a first run crashed the process with a segmentation fault), and Numba's dispatcher
    turns one raised in the Python code it calls (unpickling a cached kernel, with one
    thread: the kernels run on the main thread) into a SystemError traceback: there the
    handler sends the signal again a moment later; anywhere else it raises Terminated."""
    sent = []
    monkeypatch.setattr(cli.os, "kill", lambda pid, signum: sent.append((pid, signum)))
    ours = types.SimpleNamespace(f_globals={"__name__": "intrinsym._threads"}, f_back=None)
    inside = types.SimpleNamespace(f_globals={"__name__": module}, f_back=ours)
    cli._interrupt(signal.SIGTERM, inside)
    deadline = time.monotonic() + 10
    while not sent and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sent == [(os.getpid(), signal.SIGTERM)]
    with pytest.raises(cli.Terminated):
        cli._interrupt(signal.SIGTERM, ours)
    with pytest.raises(cli.Terminated):
        cli._interrupt(signal.SIGTERM, types.SimpleNamespace(f_globals={"__name__": "numbat"}, f_back=None))
    with pytest.raises(cli.Terminated):
        cli._interrupt(signal.SIGTERM, None)
    with pytest.raises(KeyboardInterrupt) as raised:
        cli._interrupt(signal.SIGINT, ours)
    assert raised.type is KeyboardInterrupt


def test_generate_refuses_sizes_that_do_not_fit(tmp_path, capsys):
    code = cli.main(["generate", "cuboctahedron", "--subdivisions", "12", "-o", str(tmp_path / "c.off")])
    one_line_error(capsys, code, "--subdivisions must lie in [0, 6]")
    assert list(tmp_path.iterdir()) == []


def test_numba_cache_left_alone_when_the_install_is_writable(tmp_path):
    assert intrinsym.numba_cache_dir(tmp_path, {}) is None
    (tmp_path / "file").write_text("")
    blocked = tmp_path / "file" / "pkg"
    assert intrinsym.numba_cache_dir(blocked, {"NUMBA_CACHE_DIR": "/x"}) is None
    assert intrinsym.numba_cache_dir(blocked, {"HOME": str(tmp_path)}) is None  # ~/.cache works
    assert intrinsym.numba_cache_dir(blocked, {"HOME": str(blocked)}) is not None


def test_a_run_that_cannot_fit_is_refused_before_any_work(tmp_path, capsys, monkeypatch, no_work):
    monkeypatch.setattr(resources, "available_memory", lambda: 10**9)
    argv = ["detect", "--example", "-o", str(tmp_path / "out"), "--source", "2000", "--target", "60000"]
    one_line_error(capsys, cli.main(argv), "the run needs about", "GB", "lower --target")


def test_a_long_run_prints_its_estimate_first(tmp_path, capsys, monkeypatch):
    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "detect", stop)
    assert cli.main(["detect", "--example", "-o", str(tmp_path / "out"), "--source", "500", "--target", "20000"]) == 130
    err = capsys.readouterr().err
    assert "intrinsym: this run takes about" in err and "approximate" in err


@pytest.mark.parametrize("name", ["scores.json", "symmetries.json"])
def test_corrupt_side_files_give_one_line_errors(tmp_path, capsys, result_dir, name):
    out = tmp_path / "bad"
    shutil.copytree(result_dir, out)
    (out / name).write_text('{"cut')
    one_line_error(capsys, cli.main(["view", str(out)]), name)
