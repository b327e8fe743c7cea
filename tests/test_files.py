import os
import subprocess
import sys
import zipfile
import zlib

import numpy as np
import pytest

from intrinsym import files
from intrinsym.errors import OutputError
from intrinsym.files import atomic_write, save_npz, write_set


def test_atomic_write_writes_with_umask_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write(tmp_path / "a.txt", lambda f: f.write("hello"))
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").read_text() == "hello"
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644


def test_atomic_write_failure_leaves_nothing(tmp_path):
    (tmp_path / "b.bin").write_bytes(b"old")

    def boom(f):
        f.write(b"partial")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        atomic_write(tmp_path / "b.bin", boom, binary=True)
    assert (tmp_path / "b.bin").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.bin"]


def _writers(**content):
    def writer(text):
        return lambda path: path.write_text(text)

    return {name.replace("_", "."): writer(text) for name, text in content.items()}


def _hidden(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_write_set_replaces_the_whole_set_and_keeps_other_files(tmp_path):
    out = tmp_path / "out"
    write_set(out, _writers(a_txt="old a", b_txt="old b"))
    (out / "figures").mkdir()
    (out / "figures" / "f.png").write_text("figure")
    (out / "notes.txt").write_text("mine")
    write_set(out, _writers(a_txt="new a"), owned=["b.txt"])
    assert (out / "a.txt").read_text() == "new a"
    assert not (out / "b.txt").exists()  # owned by the set, not rewritten: gone
    assert (out / "notes.txt").read_text() == "mine" and (out / "figures" / "f.png").read_text() == "figure"
    assert _hidden(tmp_path) == []  # no temporary folder, no lock left


def test_write_set_failure_or_interrupt_keeps_the_previous_set(tmp_path):
    out = tmp_path / "out"
    write_set(out, _writers(a_txt="old a", b_txt="old b"))

    def boom(path):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_set(out, {"a.txt": lambda path: path.write_text("new a"), "b.txt": boom})
    assert (out / "a.txt").read_text() == "old a" and (out / "b.txt").read_text() == "old b"
    assert _hidden(tmp_path) == []


def test_write_set_without_an_atomic_exchange_restores_the_old_folder(tmp_path, monkeypatch):
    out = tmp_path / "out"
    write_set(out, _writers(a_txt="old"))
    monkeypatch.setattr(files, "_exchange", lambda a, b: False)
    real = os.replace
    calls = []

    def second_fails(src, dst):
        calls.append(src)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        real(src, dst)

    monkeypatch.setattr(files.os, "replace", second_fails)
    with pytest.raises(OSError):
        write_set(out, _writers(a_txt="new"))
    monkeypatch.setattr(files.os, "replace", real)
    assert (out / "a.txt").read_text() == "old" and _hidden(tmp_path) == []
    write_set(out, _writers(a_txt="new"))
    assert (out / "a.txt").read_text() == "new" and _hidden(tmp_path) == []


def test_a_second_writer_is_refused_while_the_lock_is_held(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from intrinsym import files\n"
            f"with files.output_lock({str(out)!r}):\n    print('held', flush=True); time.sleep(60)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(OutputError, match="another process is writing it"):
            write_set(out, _writers(a_txt="x"))
    finally:
        holder.kill()
        holder.wait()
    write_set(out, _writers(a_txt="x"))  # the lock died with its holder
    assert (out / "a.txt").read_text() == "x"


@pytest.mark.parametrize("where", ["file", "below_file"])
def test_output_checks_name_the_output(tmp_path, where):
    (tmp_path / "f").write_text("")
    out = tmp_path / "f" if where == "file" else tmp_path / "f" / "out"
    with pytest.raises(OutputError, match=f"^{out}: "):
        files.check_output_dir(out)
    with pytest.raises(OutputError, match=f"^{out}: "):
        write_set(out, _writers(a_txt="x"))


def test_output_check_reports_an_unwritable_folder(tmp_path, monkeypatch):
    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(files.tempfile, "mkstemp", refuse)
    with pytest.raises(OutputError, match=r"out: cannot write in .* \(Permission denied\)"):
        files.check_output_dir(tmp_path / "out")
    with pytest.raises(OutputError, match=r"v.html: cannot write in"):
        files.check_output_file(tmp_path / "v.html")
    with pytest.raises(OutputError, match=r"no folder"):
        files.check_output_file(tmp_path / "missing" / "v.html")


def test_save_npz_reads_back_as_numpys_own_archive(tmp_path):
    rng = np.random.default_rng(0)
    arrays = {
        "floats": rng.standard_normal((300, 40)).astype(np.float32),
        "ints": np.arange(5000, dtype=np.int64).reshape(100, 50)[:, ::2],
        "scalar": np.float64(0.25),
        "flag": np.bool_(True),
        "empty": np.zeros((0, 3), dtype=np.int32),
        "noise": np.sort(rng.random((200, 400)), axis=1),  # sorted float64 rows: 6 % smaller deflated
    }
    save_npz(tmp_path / "ours.npz", arrays)
    np.savez_compressed(tmp_path / "numpy.npz", **arrays)
    with np.load(tmp_path / "ours.npz") as ours, np.load(tmp_path / "numpy.npz") as theirs:
        assert ours.files == theirs.files == list(arrays)
        for name in arrays:
            assert ours[name].dtype == theirs[name].dtype
            np.testing.assert_array_equal(ours[name], theirs[name])
    with zipfile.ZipFile(tmp_path / "ours.npz") as archive:
        ints = archive.getinfo("ints.npy")
        assert ints.compress_type == zipfile.ZIP_DEFLATED and ints.compress_size < ints.file_size / 2
        # deflate saves too little on float noise: stored as it is, not deflated for nothing
        noise = archive.getinfo("noise.npy")
        assert noise.compress_type == zipfile.ZIP_STORED and noise.compress_size == noise.file_size
        assert len(zlib.compress(archive.read("noise.npy"), 1)) > (1 - files.NPZ_MIN_SAVING) * noise.file_size
