"""A shared machine or a cluster node: another user's folder in the shared temporary
folder, an address-space limit (``ulimit -v``) and a full disk, each met by a real
``intrinsym`` process."""

from __future__ import annotations

import json
import os
import pickle
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from numba.core.caching import _CacheLocator

import intrinsym
from conftest import sphere_result
from intrinsym import pipeline
from intrinsym.app import cli
from intrinsym.app.batching.engine import thread_environment
from intrinsym.geodesics import _dijkstra

SRC = Path(intrinsym.__file__).parent


class _Payload:
    """A pickle that, once loaded, creates the file ``marker`` (as a command would run)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple:
        return open, (str(self.marker), "w")


def _read_only_install(tmp_path: Path) -> dict[str, str]:
    """The environment of a user who can write neither in the install (a copy of the
    package whose ``__pycache__`` is a file) nor in a home, with ``tmp_path/tmp`` as
    the temporary folder."""
    copy = tmp_path / "ro"
    shutil.copytree(SRC, copy / "intrinsym", ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "intrinsym" / "__pycache__").write_text("")
    (tmp_path / "file").write_text("")
    (tmp_path / "tmp").mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME")}
    env.update(HOME=str(tmp_path / "file" / "home"), PYTHONPATH=str(copy), TMPDIR=str(tmp_path / "tmp"))
    return env


@pytest.mark.parametrize("planted", ["world_writable", "writable_subfolder", "another_user"])
def test_a_numba_cache_planted_in_the_temporary_folder_is_not_loaded(tmp_path: Path, planted: str) -> None:
    """Another user creates the cache folder this user's run falls back to and puts an
    index there whose unpickling runs a command; the run compiles elsewhere, unharmed."""
    env = _read_only_install(tmp_path)
    shared = tmp_path / "tmp" / f"intrinsym-numba-cache-{os.getuid()}"
    kernel = tmp_path / "ro" / "intrinsym" / "geodesics" / "_dijkstra.py"
    index = (
        shared
        / _CacheLocator.get_suitable_cache_subpath(str(kernel))
        / _dijkstra.grow_int._cache._cache_file._index_name
    )
    index.parent.mkdir(parents=True)
    marker = tmp_path / "ran"
    index.write_bytes(pickle.dumps(_Payload(marker)))
    if planted == "world_writable":
        shared.chmod(0o777)
    elif planted == "writable_subfolder":
        shared.chmod(0o700)
        index.parent.chmod(0o777)
    else:
        if os.getuid() != 0:
            pytest.skip("needs root to give the folder to another user")
        for path in (shared, index.parent, index):
            os.chown(path, 65534, 65534)
        shared.chmod(0o755)
    code = (
        "import os, numpy as np, intrinsym\n"
        "from intrinsym.geodesics import _dijkstra\n"
        "_dijkstra.grow_int(np.zeros(2, np.int64), 1)\n"
        "cache = os.environ['NUMBA_CACHE_DIR']\n"
        "print(cache, oct(os.stat(cache).st_mode & 0o777))\n"
    )
    p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert not marker.exists(), "the planted index was unpickled"
    cache, mode = p.stdout.split()
    assert Path(cache) != shared and Path(cache).parent == tmp_path / "tmp" and mode == "0o700"
    assert not Path(cache).exists()  # the process's own folder goes with it
    assert f"{shared} is not private to this user" in p.stderr


def test_the_numba_cache_fallback_is_created_private_and_kept(tmp_path: Path) -> None:
    """Without a writable home or install, the package (the read-only copy, not this
    checkout) and its cached kernels import, caching in a private folder of the temporary
    folder (formerly also tests/test_reliability.py's own process)."""
    env = _read_only_install(tmp_path)
    shared = tmp_path / "tmp" / f"intrinsym-numba-cache-{os.getuid()}"
    code = "import os, intrinsym, intrinsym.unary.descriptors; print(intrinsym.__file__, os.environ['NUMBA_CACHE_DIR'])"
    for _ in range(2):  # created the first time, taken as it is the second
        p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
        assert p.returncode == 0 and p.stderr == "", p.stderr
        where, cache = p.stdout.split()
        assert where.startswith(str(tmp_path / "ro" / "intrinsym")), where
        assert cache == str(shared) and shared.stat().st_mode & 0o777 == 0o700


def _one_line_error(code: int, err: str, *words: str) -> None:
    assert code == 2 and err.startswith("intrinsym: error: ") and err.count("\n") == 1, err
    for word in words:
        assert word in err, err


def test_an_address_space_limit_is_refused_before_any_work(tmp_path: Path) -> None:
    """``prlimit --as`` / ``ulimit -v``, as cluster schedulers set them: a run that cannot
    fit is refused up front in one line, not a MemoryError traceback later."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (800_000_000, 800_000_000))

    out = tmp_path / "out"
    argv = [sys.executable, "-m", "intrinsym", "detect", "--example", "-o", str(out), "--target", "8000"]
    env = {**os.environ, **thread_environment(1)}  # BLAS maps buffers per thread: as on a one-core job
    p = subprocess.run(argv, env=env, preexec_fn=limit, capture_output=True, text=True, timeout=120)
    _one_line_error(p.returncode, p.stderr, "the run needs about", "address-space limit (ulimit -v)", "lower --target")
    assert list(tmp_path.iterdir()) == []


def test_running_out_of_memory_beyond_the_estimate_is_one_line(tmp_path: Path, monkeypatch, capsys) -> None:
    def allocate(*args: object, **kwargs: object) -> None:
        raise MemoryError("Unable to allocate 8.00 GiB for an array with shape (1073741824,) and data type float64")

    monkeypatch.setattr(pipeline, "detect", allocate)
    code = cli.main(["detect", "--example", "-o", str(tmp_path / "out"), "-q", "--source", "30", "--target", "300"])
    _one_line_error(code, capsys.readouterr().err, "out of memory (Unable to allocate 8.00 GiB")
    assert list(tmp_path.iterdir()) == []


#: Run in a mount namespace of its own on a 4 MB tmpfs at ``argv[1]``, with the saved
#: result ``argv[2]``: first with all but 200 kB of the disk taken (refused before the
#: pipeline runs), then with the earlier result in OUT and the disk filling up while
#: the pipeline runs (the save fails). Prints what each gave, as JSON.
FULL_DISK = """
import contextlib, io, json, os, shutil, sys
from pathlib import Path
from intrinsym import Result, pipeline
from intrinsym.app import cli

disk, saved = Path(sys.argv[1]), Path(sys.argv[2])
out, filler = disk / "out", disk / "filler"
argv = ["detect", "--example", "-o", str(out), "-q", "--source", "30", "--target", "300"]

def fill(leave):
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    block = b"\\0" * 4096
    with contextlib.suppress(OSError):
        while shutil.disk_usage(disk).free > leave:
            os.write(fd, block)
    os.close(fd)

def run():
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = cli.main(argv)
    return code, err.getvalue()

def refuse(*args, **kwargs):
    raise AssertionError("the pipeline ran")

fill(200_000)
pipeline.detect = refuse
before = run()
filler.unlink()
shutil.copytree(saved, out)
result = Result.load(saved)

def fills_the_disk(*args, **kwargs):
    fill(0)
    return result

pipeline.detect = fills_the_disk
during = run()
filler.unlink()
files = {p.name: p.read_bytes() == (saved / p.name).read_bytes() for p in out.iterdir()}
print(json.dumps({"before": before, "during": during, "disk": sorted(os.listdir(disk)), "out": files}))
"""


def test_a_full_disk_is_one_line_naming_out_and_the_earlier_result_survives(tmp_path: Path) -> None:
    saved, _ = sphere_result(tmp_path)
    disk = tmp_path / "disk"
    disk.mkdir()
    mount = f'mount -t tmpfs -o size=4m tmpfs {disk} && exec {sys.executable} -c "$0" {disk} {saved}'
    command = ["unshare", "--user", "--map-root-user", "--mount", "sh", "-c", mount, FULL_DISK]
    try:
        p = subprocess.run(command, capture_output=True, text=True, timeout=120)
    except FileNotFoundError:
        pytest.skip("no unshare command")
    if "unshare:" in p.stderr or "mount:" in p.stderr:
        pytest.skip(f"cannot mount a small file system here: {p.stderr.strip()}")
    assert p.returncode == 0, p.stderr
    report = json.loads(p.stdout)
    out = disk / "out"
    _one_line_error(*report["before"], f"{out}: not enough disk space", "needs about 1.2 MB", "0.2 MB free")
    _one_line_error(*report["during"], f"{out}: not enough disk space", "needs about 1.2 MB", "filled up while writing")
    assert report["disk"] == ["out"]  # no temporary folder, no lock
    assert report["out"] and all(report["out"].values()), report["out"]  # the earlier result, whole
