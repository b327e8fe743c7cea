"""A result folder as a set of files on a shared machine: what a new result removes and
keeps, the folder's mode, owner and place (a symbolic link), its lock, what a killed
save leaves behind, and result.npz files that declare more than run.json says."""

import json
import os
import struct
import subprocess
import sys
import time
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from conftest import sphere_result
from intrinsym import Result, files, resources
from intrinsym.app import cli
from intrinsym.app.batching import work
from intrinsym.errors import OutputError, ResourceError, ResultError
from test_reliability import no_work, one_line_error  # noqa: F401 (a fixture)

ROOT = os.geteuid() == 0
NOBODY = 65534


def _contents(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def _writers(**content):
    return {name.replace("_", "."): (lambda path, text=text: path.write_text(text)) for name, text in content.items()}


def test_a_new_result_removes_what_was_derived_from_the_previous_one(tmp_path, capsys):
    out, _ = sphere_result(tmp_path)
    (out / "scores.json").write_text(json.dumps({"mirror_hit": 0.5}))
    (out / "curve.png").write_bytes(b"png")
    (out / "figures").mkdir()
    (out / "figures" / "marginal.png").write_bytes(b"png")
    assert cli.main(["view", str(out), "-q"]) == 0
    (out / "notes.txt").write_text("mine")
    (out / "mine").mkdir()
    (out / "mine" / "a.txt").write_text("mine too")
    result = Result.load(out)
    result.save(out)  # a rerun into the same folder
    names = sorted(p.name for p in out.iterdir())
    assert not {"scores.json", "curve.png", "viewer.html", "figures"} & set(names), names
    assert (out / "notes.txt").read_text() == "mine" and (out / "mine" / "a.txt").read_text() == "mine too"
    assert cli.main(["view", str(out), "-q"]) == 0
    page = (out / "viewer.html").read_text()
    assert json.loads(page.split('id="data">', 1)[1].split("</script>", 1)[0])["scores"] is None
    # A batch item's scores are written with its result set, and go with it.
    work.save(result, {"mirror_hit": 0.75}, out)
    assert json.loads((out / "scores.json").read_text()) == {"mirror_hit": 0.75}
    work.save(result, None, out)
    assert not (out / "scores.json").exists() and (out / "notes.txt").exists()
    assert _hidden(tmp_path) == []


def test_view_writes_its_page_again_and_again(tmp_path, capsys):
    out, _ = sphere_result(tmp_path)
    for _ in range(3):
        assert cli.main(["view", str(out)]) == 0, capsys.readouterr().err
    assert capsys.readouterr().out.count(f"wrote {out / 'viewer.html'}") == 3


def test_a_rerun_keeps_the_folders_mode_owner_group_and_attributes(tmp_path):
    out, _ = sphere_result(tmp_path)
    os.setxattr(out, "user.intrinsym-test", b"kept")
    # an access ACL (the binary form setfacl writes): owner rwx, user 65534 r-x, group r-x, mask r-x, other ---
    entries = [(0x01, 7, -1), (0x02, 5, NOBODY), (0x04, 5, -1), (0x10, 5, -1), (0x20, 0, -1)]
    acl = struct.pack("<I", 2) + b"".join(struct.pack("<HHi", tag, perm, who) for tag, perm, who in entries)
    os.setxattr(out, "system.posix_acl_access", acl)
    owner = (NOBODY, NOBODY) if ROOT else (os.geteuid(), os.getegid())
    os.chown(out, *owner)
    os.chmod(out, 0o2750)
    acl = os.getxattr(out, "system.posix_acl_access")
    Result.load(out).save(out)
    info = out.stat()
    assert oct(info.st_mode & 0o7777) == oct(0o2750)
    assert (info.st_uid, info.st_gid) == owner
    assert (out / "run.json").stat().st_uid == owner[0]
    assert os.getxattr(out, "user.intrinsym-test") == b"kept"
    assert os.getxattr(out, "system.posix_acl_access") == acl
    assert _hidden(tmp_path) == []
    # A new folder gets the umask's mode.
    old = os.umask(0o027)
    try:
        Result.load(out).save(tmp_path / "new")
    finally:
        os.umask(old)
    assert (tmp_path / "new").stat().st_mode & 0o777 == 0o750


@pytest.mark.usefixtures("no_work")
def test_a_read_only_result_folder_is_refused_before_any_work(tmp_path, capsys):
    out, _ = sphere_result(tmp_path)
    before = _contents(out)
    out.chmod(0o555)
    try:
        code = cli.main(["detect", "--example", "-o", str(out), "--source", "30", "--target", "300"])
        one_line_error(capsys, code, str(out), "read-only")
        with pytest.raises(OutputError, match="read-only"):
            Result.load(out).save(out)
    finally:
        out.chmod(0o755)
    assert _contents(out) == before and _hidden(tmp_path) == []


def test_a_folder_of_another_user_is_refused(tmp_path, monkeypatch):
    out, _ = sphere_result(tmp_path)
    os.chmod(out, 0o777)  # writable by all, but a new folder could not be given back to its owner
    monkeypatch.setattr(os, "geteuid", lambda: out.stat().st_uid + 1)
    with pytest.raises(OutputError, match=rf"^{out}: owned by user {out.stat().st_uid}, group"):
        files.check_output_dir(out)


def test_a_symlinked_result_folder_is_written_where_it_points(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    link = tmp_path / "out"
    link.symlink_to(data / "res", target_is_directory=True)
    files.write_set(link, _writers(a_txt="old"))  # a link to a folder still to be made
    assert link.is_symlink() and (data / "res" / "a.txt").read_text() == "old"
    (data / "res" / "mine.txt").write_text("mine")
    files.write_set(link, _writers(a_txt="new"))
    assert link.is_symlink() and os.readlink(link) == str(data / "res")
    assert (data / "res" / "a.txt").read_text() == "new" and (data / "res" / "mine.txt").read_text() == "mine"
    assert _hidden(tmp_path) == [] and _hidden(data) == []


@pytest.mark.usefixtures("no_work")
def test_the_lock_never_follows_a_symbolic_link(tmp_path, capsys):
    out = tmp_path / "out"
    victim = tmp_path / "victim"
    (tmp_path / ".out.lock").symlink_to(victim)
    with pytest.raises(OutputError, match=r"out: cannot open its lock .*\.out\.lock \(it is a symbolic link"):
        files.write_set(out, _writers(a_txt="x"))
    code = cli.main(["detect", "--example", "-o", str(out), "--source", "30", "--target", "300"])
    one_line_error(capsys, code, str(out), "symbolic link")
    assert not victim.exists() and not out.exists()
    (tmp_path / ".out.lock").unlink()
    os.mkfifo(tmp_path / ".out.lock")
    with pytest.raises(OutputError, match="is not a plain file"):
        files.write_set(out, _writers(a_txt="x"))


def _killed_save(out: Path) -> None:
    """Start a save of ``out`` and kill -9 it while it writes."""
    code = (
        "import time\nfrom intrinsym.files import write_set\n"
        "def slow(path):\n    path.write_text('partial')\n    print('writing', flush=True)\n    time.sleep(60)\n"
        f"write_set({str(out)!r}, {{'a.txt': slow}})\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "writing"
    finally:
        proc.kill()
        proc.wait()


def test_the_temporaries_of_a_killed_save_are_swept_by_the_next(tmp_path):
    out = tmp_path / "out"
    files.write_set(out, _writers(a_txt="old"))
    _killed_save(out)
    assert (out / "a.txt").read_text() == "old"
    left = [name for name in _hidden(tmp_path) if name.endswith(".tmp")]
    assert len(left) == 1
    # What is not ours stays: a link, a file of the user's, another user's folder.
    (tmp_path / ".out.linkedxx.tmp").symlink_to(tmp_path / "elsewhere")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / ".out.notes.tmp").write_text("mine")
    kept = [".out.linkedxx.tmp", ".out.notes.tmp"]
    if ROOT:
        (tmp_path / ".out.theirsxx.tmp").mkdir()
        os.chown(tmp_path / ".out.theirsxx.tmp", NOBODY, NOBODY)
        kept.append(".out.theirsxx.tmp")
    # and an atomic write of viewer.html killed inside the folder
    (out / ".viewer.html.abcd1234.tmp").write_text("partial")
    files.write_set(out, _writers(a_txt="new"), owned=["viewer.html"])
    assert (out / "a.txt").read_text() == "new" and sorted(p.name for p in out.iterdir()) == ["a.txt"]
    assert _hidden(tmp_path) == sorted(kept)


def test_a_folder_moved_aside_by_a_killed_save_is_put_back(tmp_path):
    out = tmp_path / "out"
    files.write_set(out, _writers(a_txt="old", b_txt="old b"))
    os.rename(out, tmp_path / ".out.k1ll3d_x.old")  # killed between the two renames (no atomic exchange)
    files.write_set(out, _writers(a_txt="new"))
    assert (out / "a.txt").read_text() == "new" and (out / "b.txt").read_text() == "old b"
    assert _hidden(tmp_path) == []


def _npy_header(shape: tuple[int, ...]) -> bytes:
    """A float32 .npy header (format version 1) declaring ``shape``."""
    text = repr({"descr": "<f4", "fortran_order": False, "shape": shape}).encode("latin1")
    text += b" " * (63 - (10 + len(text)) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text


def _rewrite_member(npz: Path, name: str, shape: tuple[int, ...], chunks: list[bytes] | Iterator[bytes]) -> None:
    """Replace the float32 array ``name`` of ``npz`` by one whose .npy header declares
    ``shape``, followed by ``chunks`` (deflated as they come, at the fastest level:
    level 6 took 4 s over a deflate bomb's 526 MB, level 1 takes 1.4 s)."""
    with zipfile.ZipFile(npz) as archive:
        members = {m.filename: archive.read(m) for m in archive.infolist() if m.filename != name}
    with zipfile.ZipFile(npz, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        for member, data in members.items():
            archive.writestr(member, data)
        with archive.open(name, "w", force_zip64=True) as f:
            f.write(_npy_header(shape))
            for chunk in chunks:
                f.write(chunk)


def test_result_npz_declaring_other_shapes_than_run_json_is_refused_unread(tmp_path, capsys):
    out, _ = sphere_result(tmp_path)
    npz = out / "result.npz"
    # 1 kB whose header declares a 10^6 x 10^6 unary
    _rewrite_member(npz, "unary.npy", (10**6, 10**6), [b"\0" * 64])
    assert npz.stat().st_size < 10_000
    with pytest.raises(ResultError, match=r"result.npz: .*unary.npy declares \(1000000, 1000000\)"):
        Result.load(out)
    for argv in (["query", str(out), "--vertex", "0"], ["view", str(out)], ["render", str(out)]):
        one_line_error(capsys, cli.main(argv), "result.npz", "unary")
    assert not (out / "viewer.html").exists() and not (out / "figures").exists()


def test_npy_files_declaring_more_than_they_hold_are_refused_unread(tmp_path, capsys):
    out, v = sphere_result(tmp_path)
    lying = _npy_header((10**12,)) + bytes(64)
    (out / "symmetry_confidence.npy").write_bytes(lying)
    one_line_error(capsys, cli.main(["view", str(out)]), "symmetry_confidence.npy", "declares (1000000000000,)")
    (tmp_path / "truth.npy").write_bytes(lying)
    code = cli.main(["evaluate", str(out), "--symmetry-map", str(tmp_path / "truth.npy")])
    one_line_error(capsys, code, "truth.npy", "declares (1000000000000,)")
    np.save(tmp_path / "truth.npy", np.arange(len(v)))  # a true .npy reads as before
    assert cli.main(["evaluate", str(out), "--symmetry-map", str(tmp_path / "truth.npy")]) == 0


def test_result_npz_with_more_bp_passes_than_run_json_is_refused(tmp_path):
    out, _ = sphere_result(tmp_path)
    s, t = Result.load(out).unary.shape
    _rewrite_member(out / "result.npz", "pass_marginals.npy", (3, s, t), [bytes(3 * s * t * 4)])
    with pytest.raises(ResultError, match="result.npz: holds 3 further BP passes, more than the 1 of run.json"):
        Result.load(out)


def test_a_deflate_bomb_in_result_npz_is_not_inflated(tmp_path, capsys):
    out, _ = sphere_result(tmp_path)
    npz = out / "result.npz"
    s, t = Result.load(out).unary.shape
    rows = 200 * 1024  # 200k x 642 float32 zeros: 526 MB, 2.3 MB deflated
    _rewrite_member(npz, "unary.npy", (rows, t), (bytes(4 * t * 1024) for _ in range(rows // 1024)))
    assert npz.stat().st_size < 3_000_000
    # the peak of this process's own memory (VmHWM): ru_maxrss keeps, across exec, the
    # high-water mark of the process it was forked from (pytest, large late in the suite)
    code = "import sys\nfrom intrinsym.app.cli import main\n"
    code += f"rc = main(['query', {str(out)!r}, '--vertex', '0'])\n"
    code += "hwm = [l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM:')][0]\n"
    code += "print(hwm, file=sys.stderr); sys.exit(rc)"
    start = time.monotonic()
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    error, peak_kb = p.stderr.splitlines()
    assert p.returncode == 2 and error.startswith("intrinsym: error: "), p.stderr
    assert f"its array unary is ({rows}, {t}), not ({s}, {t}) as run.json's sizes say" in error
    assert int(peak_kb) < 400_000 and time.monotonic() - start < 60


def test_result_npz_larger_than_memory_is_refused_unread(tmp_path, monkeypatch):
    out, _ = sphere_result(tmp_path)
    monkeypatch.setattr(resources, "available_memory", lambda: 100_000)
    with pytest.raises(ResourceError, match=r"result.npz: reading its arrays needs .* more than"):
        Result.load(out)


def test_result_npz_is_the_same_bytes_whatever_the_clock(tmp_path, monkeypatch):
    out, _ = sphere_result(tmp_path)
    result = Result.load(out)
    noise = np.random.default_rng(0).bytes(4 * result.unary.size)  # random bits: stored, not deflated
    result.unary = np.frombuffer(noise, np.float32).reshape(result.unary.shape)
    saved = []
    for zone in ("UTC0", "JST-9"):  # POSIX time zones: no tz database needed
        monkeypatch.setenv("TZ", zone)
        time.tzset()
        result.save(tmp_path / zone)
        saved.append((tmp_path / zone / "result.npz").read_bytes())
    monkeypatch.undo()
    time.tzset()
    assert saved[0] == saved[1]
    with zipfile.ZipFile(tmp_path / "UTC0" / "result.npz") as archive:
        assert {m.date_time for m in archive.infolist()} == {files.ZIP_DATE}
        assert archive.getinfo("unary.npy").compress_type == zipfile.ZIP_STORED
        marginals = archive.getinfo("marginals.npy")  # deflated at NPZ_LEVEL, not zlib's default
        deflate = zlib.compressobj(files.NPZ_LEVEL, zlib.DEFLATED, -15)
        expected = deflate.compress(archive.read(marginals)) + deflate.flush()
        assert marginals.compress_type == zipfile.ZIP_DEFLATED and marginals.compress_size == len(expected)
