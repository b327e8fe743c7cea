"""Output files and folders that are never left half-written.

:func:`atomic_write` replaces one file; :func:`write_set` replaces a folder's set of
files at once (a reader sees the old set or the new one, never a mix), under a lock
that keeps a second writer out (:func:`output_lock`). :func:`check_output_dir` and
:func:`check_output_file` say before any work whether an output can be written.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import fcntl
import os
import shutil
import tempfile
import time
import zipfile
import zlib
from collections.abc import Callable, Collection, Iterator, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

from .errors import OutputError, path_label

#: A writer of one file of a set: called with the path to write.
Writer = Callable[[Path], None]

#: Deflate level of :func:`save_npz`. Level 1 writes a default-size result.npz (17 MB of
#: float arrays) 2.6x faster than NumPy's ``savez_compressed`` (zlib's level 6) for a
#: file 2 % larger: float noise barely compresses at any level (docs/benchmarks.md).
NPZ_LEVEL = 1
#: :func:`save_npz` stores an array without compression when deflating its first
#: ``NPZ_PROBE_BYTES`` saves less than ``NPZ_MIN_SAVING`` of them: the sorted float64
#: geodesics of an elephant-size result (87 MB) deflate by 8 % (7 % on the probe) in 2.2
#: s, its marginals by 27 % (18 % on the probe), the index arrays by half or more
#: (docs/benchmarks.md).
NPZ_MIN_SAVING = 0.1
NPZ_PROBE_BYTES = 1 << 18

_HELD: dict[Path, int] = {}
_RENAME_EXCHANGE = 2


def atomic_write(path: str | os.PathLike, write: Callable[[IO[Any]], None], binary: bool = False) -> None:
    """Call ``write(f)`` on a temporary file beside ``path``, then rename it into place.

    A failure (or an interrupt) leaves no file at ``path`` and no temporary behind. The
    file gets the permissions of a plainly created one (0666 less the umask), not the
    0600 of the temporary.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb" if binary else "w") as f:
            write(f)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def _deflates(array: np.ndarray, level: int) -> bool:
    """Whether deflate at ``level`` saves at least :data:`NPZ_MIN_SAVING` of the array's
    first :data:`NPZ_PROBE_BYTES` (in C order)."""
    head = np.ascontiguousarray(array.flat[: max(1, NPZ_PROBE_BYTES // max(1, array.itemsize))]).tobytes()
    return len(zlib.compress(head, level)) <= (1.0 - NPZ_MIN_SAVING) * len(head)


def save_npz(path: str | os.PathLike, arrays: Mapping[str, np.ndarray], level: int = NPZ_LEVEL) -> None:
    """Write ``arrays`` to ``path`` as NumPy's ``savez_compressed`` does (one ``NAME.npy``
    per array, read back by ``np.load``), each deflated at ``level`` unless deflate
    hardly shrinks it (:func:`_deflates`), then stored as it is."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=level) as archive:
        for name, value in arrays.items():
            array = np.asanyarray(value)
            member: str | zipfile.ZipInfo = f"{name}.npy"
            if array.size and not _deflates(array, level):
                member = zipfile.ZipInfo(f"{name}.npy", date_time=time.localtime()[:6])
                member.compress_type = zipfile.ZIP_STORED
            with archive.open(member, "w", force_zip64=True) as f:
                np.lib.format.write_array(f, array, allow_pickle=False)


def _umask() -> int:
    """The process umask (reading it means setting it, so it is set straight back)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _existing_ancestor(path: Path) -> Path:
    """The deepest existing folder at or above ``path``'s parent; :class:`OutputError`
    when a file stands in the way."""
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"{path_label(path)}: cannot write below {parent}, which is a file")
            return parent
    raise OutputError(f"{path_label(path)}: no folder to write into")


def _probe(folder: Path, path: Path) -> None:
    """Create and remove a file in ``folder``: the one sure test of writing there
    (permissions, a read-only file system, a full disk's inodes)."""
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".intrinsym-probe.", suffix=".tmp")
    except OSError as err:
        reason = err.strerror or type(err).__name__
        raise OutputError(f"{path_label(path)}: cannot write in {folder} ({reason})") from None
    os.close(fd)
    os.unlink(probe)


def check_output_dir(out: str | os.PathLike) -> Path:
    """Raise :class:`~intrinsym.errors.OutputError` unless a result folder can be
    written at ``out``: no file there or above it, and a writable folder to create it
    in (its parent, or the deepest existing folder above it). Creates nothing.

    Returns
    -------
    Path
        ``out`` as a path.
    """
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{path_label(path)}: exists and is not a folder")
    _probe(_existing_ancestor(path), path)
    return path


def check_output_file(path: str | os.PathLike) -> Path:
    """Raise :class:`~intrinsym.errors.OutputError` unless the file ``path`` can be
    written: its folder exists and is writable, and ``path`` is not a folder."""
    path = Path(path)
    folder = path.absolute().parent
    if path.is_dir():
        raise OutputError(f"{path_label(path)}: is a folder, expected a file name")
    if not folder.is_dir():
        _existing_ancestor(path)
        raise OutputError(f"{path_label(path)}: no folder {folder}")
    _probe(folder, path)
    return path


def _lock_path(out: Path) -> Path:
    return out.absolute().parent / f".{out.name}.lock"


@contextlib.contextmanager
def output_lock(out: str | os.PathLike) -> Iterator[Path]:
    """Hold the lock of the result folder ``out`` (a file ``.NAME.lock`` beside it) for
    the duration; re-entrant within one process.

    Checks ``out`` first (:func:`check_output_dir`) and creates its parent folders.

    Raises
    ------
    OutputError
        When ``out`` cannot be written, or another process holds its lock.
    """
    path = check_output_dir(out)
    lock = _lock_path(path)
    if lock in _HELD:
        yield path
        return
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"{path_label(path)}: cannot create {lock.parent} ({err.strerror})") from None
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            os.close(fd)
            if err.errno in (errno.EAGAIN, errno.EACCES):
                raise OutputError(f"{path_label(path)}: another process is writing it (lock {lock})") from None
            raise
        try:  # the holder before us may have removed the file we locked: lock the new one
            if os.stat(lock).st_ino == os.fstat(fd).st_ino:
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    _HELD[lock] = fd
    try:
        yield path
    finally:
        del _HELD[lock]
        with contextlib.suppress(OSError):
            os.unlink(lock)
        os.close(fd)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux ``renameat2(RENAME_EXCHANGE)``); False where
    the system cannot."""
    name = ctypes.util.find_library("c")
    try:
        renameat2 = ctypes.CDLL(name, use_errno=True).renameat2
    except (OSError, AttributeError, TypeError):
        return False
    at_fdcwd = -100
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _carry(old: Path, new: Path, names: set[str]) -> None:
    """Hard-link (or copy) every entry of ``old`` not in ``names`` into ``new``."""
    for entry in old.iterdir():
        if entry.name in names:
            continue
        target = new / entry.name
        if entry.is_dir() and not entry.is_symlink():
            shutil.copytree(entry, target, symlinks=True, copy_function=_link_or_copy)
        elif entry.is_symlink():
            os.symlink(os.readlink(entry), target)
        else:
            _link_or_copy(entry, target)


def _link_or_copy(src: str | os.PathLike, dst: str | os.PathLike) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def write_set(out: str | os.PathLike, writers: Mapping[str, Writer], owned: Collection[str] = ()) -> Path:
    """Write a folder's set of files at once.

    Each ``writers[name](path)`` writes ``path``, inside a temporary folder beside
    ``out``; the other entries of an existing ``out`` (but those named in ``owned``) are hard-linked (else copied) into
    it, and it then replaces ``out`` in one step (an atomic exchange on Linux, else two
    renames). Until then the previous folder stays whole; a failure or an interrupt
    leaves it as it was and removes the temporary folder. Holds :func:`output_lock`.

    Parameters
    ----------
    out : path
        The folder.
    writers : mapping of file name to callable
        ``{"result.npz": write_npz, ...}``; each is called with the path to write.
    owned : collection of str
        Further names of the set, removed from ``out`` when not written (a file the
        previous set had and this one has not).

    Returns
    -------
    Path
        ``out``.
    """
    with output_lock(out) as path:
        path = path.absolute()
        new = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"))
        tmp: Path | None = new  # what is left to remove
        old: Path | None = None
        try:
            os.chmod(new, 0o777 & ~_umask())
            for name, write in writers.items():
                write(new / name)
            if path.is_dir():
                _carry(path, new, {*writers, *owned})
                if not _exchange(new, path):
                    old = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".old"))
                    os.replace(path, old)
                    os.replace(new, path)
                    old, tmp = None, old
            else:
                os.replace(new, path)
                tmp = None
        except BaseException:
            if old is not None and not path.exists():
                os.replace(old, path)
            raise
        finally:
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
    return Path(out)
