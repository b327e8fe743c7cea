"""Output files and folders that are never left half-written.

:func:`atomic_write` replaces one file; :func:`write_set` replaces a folder's set of
files at once (a reader sees the old set or the new one, never a mix), under a lock
that keeps a second writer out (:func:`output_lock`). :func:`check_output_dir` and
:func:`check_output_file` say before any work whether an output can be written.

A result folder given as a symbolic link is written where the link points; a folder
that is replaced keeps its mode, owner, group and extended attributes (ACLs), and one
its caller may not write (or could not give back to its owner) is refused.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import fcntl
import math
import os
import re
import shutil
import stat
import tempfile
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
#: file 2 % larger: float noise barely compresses at any level (docs/notes/2026-11-28-speed-behind-the-defaults.md).
NPZ_LEVEL = 1
#: :func:`save_npz` stores an array without compression when deflating its first
#: ``NPZ_PROBE_BYTES`` saves less than ``NPZ_MIN_SAVING`` of them: the sorted float64
#: geodesics of an elephant-size result (87 MB) deflate by 8 % (7 % on the probe) in 2.2
#: s, its marginals by 27 % (18 % on the probe), the index arrays by half or more
#: (docs/notes/2026-11-28-speed-behind-the-defaults.md).
NPZ_MIN_SAVING = 0.1
NPZ_PROBE_BYTES = 1 << 18

#: Date of every member of :func:`save_npz`'s archive (the zip format's earliest): two
#: saves of the same arrays are the same bytes.
ZIP_DATE = (1980, 1, 1, 0, 0, 0)

_HELD: dict[Path, int] = {}
_RENAME_EXCHANGE = 2
#: The random part of a name from :func:`tempfile.mkdtemp` and :func:`tempfile.mkstemp`.
_RANDOM = "[a-z0-9_]{8}"


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
    hardly shrinks it (:func:`_deflates`), then stored as it is. Every member is dated
    :data:`ZIP_DATE`: the same arrays give the same bytes."""
    with zipfile.ZipFile(path, "w") as archive:
        for name, value in arrays.items():
            array = np.asanyarray(value)
            member = zipfile.ZipInfo(f"{name}.npy", date_time=ZIP_DATE)
            if array.size and not _deflates(array, level):
                member.compress_type = zipfile.ZIP_STORED
            else:
                member.compress_type = zipfile.ZIP_DEFLATED
                member._compresslevel = level  # type: ignore[attr-defined]  # ZipFile.open reads it
            with archive.open(member, "w", force_zip64=True) as f:
                np.lib.format.write_array(f, array, allow_pickle=False)


def _npy_header(f: IO[bytes], name: str) -> tuple[tuple[int, ...], np.dtype, int]:
    """Shape, dtype and total size in bytes (header and data) that the ``.npy`` array at
    the start of ``f`` (called ``name`` in messages) declares; ``f`` is left at its data."""
    readers = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}
    read = readers.get(np.lib.format.read_magic(f))
    if read is None:
        raise ValueError(f"{name} is not a .npy array of format version 1 or 2")
    shape, _, dtype = read(f)
    return shape, dtype, f.tell() + math.prod(shape) * dtype.itemsize


def _declared(name: str, shape: tuple[int, ...], dtype: np.dtype, nbytes: int) -> ValueError:
    return ValueError(f"{name} declares {shape} x {dtype} but holds {nbytes} bytes")


def read_npy(path: str | os.PathLike) -> np.ndarray:
    """``np.load(path, allow_pickle=False)`` of a ``.npy`` file whose header is first
    checked against the file's size: a header that declares more than the file holds is
    a ValueError, not an allocation of what it declares.

    Raises
    ------
    ValueError
        Not a ``.npy`` array of format version 1 or 2, or another size than it declares.
    OSError
        The file cannot be read.
    """
    with open(path, "rb") as f:
        shape, dtype, size = _npy_header(f, Path(path).name)
        nbytes = os.fstat(f.fileno()).st_size
        if size != nbytes:
            raise _declared(Path(path).name, shape, dtype, nbytes)
        f.seek(0)
        return np.load(f, allow_pickle=False)


def npz_headers(path: str | os.PathLike) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """The shape and dtype of every array of the ``.npz`` archive ``path``, by name, from
    the members' headers alone: nothing else is inflated.

    Raises
    ------
    ValueError
        A member that is not a ``.npy`` array of format version 1 or 2, or whose header
        declares another size than the archive's directory gives it.
    OSError, zipfile.BadZipFile, zlib.error
        The file is missing, not a zip archive, or corrupt.
    """
    headers = {}
    with zipfile.ZipFile(path) as archive:
        for member in archive.infolist():
            with archive.open(member) as f:
                shape, dtype, size = _npy_header(f, member.filename)
            if not member.filename.endswith(".npy") or size != member.file_size:
                raise _declared(member.filename, shape, dtype, member.file_size)
            headers[member.filename.removesuffix(".npy")] = (shape, dtype)
    return headers


def _umask() -> int:
    """The process umask (reading it means setting it, so it is set straight back)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _existing_ancestor(path: Path, label: Path | None = None) -> Path:
    """The deepest existing folder at or above ``path``'s parent; :class:`OutputError`
    (naming ``label``, default ``path``) when a file stands in the way."""
    name = path_label(path if label is None else label)
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"{name}: cannot write below {parent}, which is a file")
            return parent
    raise OutputError(f"{name}: no folder to write into")


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


def _real(out: str | os.PathLike) -> Path:
    """Where the folder ``out`` is: a symbolic link (at ``out`` or above it) followed."""
    return Path(os.path.realpath(out))


def _writable(folder: Path, info: os.stat_result) -> bool:
    """Whether the caller may write in ``folder`` (``info`` its status); for root, which
    may write anywhere, whether its owner may (``chmod a-w`` makes it read-only)."""
    if os.geteuid() == 0:
        return bool(info.st_mode & stat.S_IWUSR)
    return os.access(folder, os.W_OK)


def _check_replaceable(path: Path, info: os.stat_result) -> None:
    """Refuse to replace the folder ``path`` (``info`` its status) unless the caller may
    write it and give the new folder its owner and group."""
    if not _writable(path, info):
        raise OutputError(f"{path_label(path)}: the folder is read-only for you; choose another output folder")
    groups = {os.getegid(), *os.getgroups()}
    if os.geteuid() != 0 and (info.st_uid != os.geteuid() or info.st_gid not in groups):
        raise OutputError(
            f"{path_label(path)}: owned by user {info.st_uid}, group {info.st_gid}, which a new result "
            "could not keep; choose another output folder"
        )


def check_output_dir(out: str | os.PathLike) -> Path:
    """Raise :class:`~intrinsym.errors.OutputError` unless a result folder can be
    written at ``out``: no file there or above it, and a writable folder to create it
    in (its parent, or the deepest existing folder above it); an existing folder must be
    writable by the caller, and replaceable by one of its owner and group
    (:func:`write_set`). Creates nothing.

    Returns
    -------
    Path
        ``out`` as a path.
    """
    path = Path(out)
    real = _real(path)
    if real.exists():
        if not real.is_dir():
            raise OutputError(f"{path_label(path)}: exists and is not a folder")
        _check_replaceable(path, real.stat())
    _probe(_existing_ancestor(real, path), path)
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


def _lock_path(real: Path) -> Path:
    return real.parent / f".{real.name}.lock"


def _open_lock(lock: Path, path: Path) -> int:
    """Open (or create) the lock file ``lock`` of the folder ``path``, never through a
    symbolic link and only when it is a plain file."""
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o666)
    except OSError as err:
        reason = "it is a symbolic link; remove it" if err.errno == errno.ELOOP else err.strerror
        raise OutputError(f"{path_label(path)}: cannot open its lock {lock} ({reason})") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OutputError(f"{path_label(path)}: its lock {lock} is not a plain file; remove it")
    return fd


@contextlib.contextmanager
def output_lock(out: str | os.PathLike) -> Iterator[Path]:
    """Hold the lock of the result folder ``out`` (a file ``.NAME.lock`` beside it, or
    beside the folder a symbolic link ``out`` points to) for the duration; re-entrant
    within one process. The lock file is opened without following a symbolic link.

    Checks ``out`` first (:func:`check_output_dir`) and creates its parent folders.

    Raises
    ------
    OutputError
        When ``out`` cannot be written, its lock is not a plain file, or another process
        holds it.
    """
    path = check_output_dir(out)
    lock = _lock_path(_real(path))
    if lock in _HELD:
        yield path
        return
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"{path_label(path)}: cannot create {lock.parent} ({err.strerror})") from None
    while True:
        fd = _open_lock(lock, path)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            os.close(fd)
            if err.errno in (errno.EAGAIN, errno.EACCES):
                raise OutputError(f"{path_label(path)}: another process is writing it (lock {lock})") from None
            raise
        try:  # the holder before us may have removed the file we locked: lock the new one
            if os.lstat(lock).st_ino == os.fstat(fd).st_ino:
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


def _temporaries(names: Collection[str]) -> re.Pattern[str]:
    """The names :func:`tempfile.mkdtemp` and :func:`tempfile.mkstemp` give the
    temporaries of :func:`write_set` and :func:`atomic_write` for any of ``names``."""
    return re.compile(rf"\.(?:{'|'.join(map(re.escape, names))})\.{_RANDOM}\.(?:tmp|old)")


def _carry(old: Path, new: Path, names: set[str]) -> None:
    """Hard-link (or copy) every entry of ``old`` not in ``names`` into ``new``, but the
    temporaries of an interrupted write of one of ``names``."""
    temporary = _temporaries(names)
    for entry in old.iterdir():
        if entry.name in names or temporary.fullmatch(entry.name):
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


def _sweep(real: Path) -> None:
    """Remove the temporary folders that killed :func:`write_set` calls of ``real`` left
    beside it; called with its lock held, so no live writer owns one. Only the caller's
    own folders of exactly the temporaries' names are touched. When a kill left ``real``
    moved aside (where no atomic exchange exists), it is first put back."""
    temporary = _temporaries([real.name])
    found = []
    for entry in os.scandir(real.parent):
        if temporary.fullmatch(entry.name):
            info = entry.stat(follow_symlinks=False)
            if stat.S_ISDIR(info.st_mode) and info.st_uid == os.geteuid():
                found.append((info.st_mtime, Path(entry.path)))
    moved = sorted(item for item in found if item[1].suffix == ".old")
    if moved and not real.exists():
        os.replace(moved[-1][1], real)
        found.remove(moved[-1])
    for _, folder in found:
        shutil.rmtree(folder, ignore_errors=True)


def _keep_attributes(old: Path, info: os.stat_result, new: Path, written: Collection[str]) -> None:
    """Give the folder ``new`` the owner, group, extended attributes (ACLs) and mode of
    ``old`` (``info`` its status); the files ``written`` in it its owner and group too."""
    if (info.st_uid, info.st_gid) != (os.geteuid(), os.getegid()):
        for entry in (new, *(new / name for name in written)):
            os.lchown(entry, info.st_uid, info.st_gid)
    try:
        names = os.listxattr(old)
    except OSError as err:
        if err.errno not in (errno.ENOTSUP, errno.ENODATA, errno.EINVAL):
            raise
        names = []
    for name in names:
        try:
            os.setxattr(new, name, os.getxattr(old, name))
        except OSError as err:  # a namespace this caller may not set (security.*), or none there
            if err.errno not in (errno.EPERM, errno.ENOTSUP, errno.ENODATA, errno.EINVAL):
                raise
    os.chmod(new, stat.S_IMODE(info.st_mode))


def write_set(out: str | os.PathLike, writers: Mapping[str, Writer], owned: Collection[str] = ()) -> Path:
    """Write a folder's set of files at once.

    Each ``writers[name](path)`` writes ``path``, inside a temporary folder beside
    ``out`` (private to the caller while it is written); the other entries of an existing
    ``out`` (but those named in ``owned``) are hard-linked (else copied) into it, it gets
    the mode, owner, group and extended attributes of ``out`` (a new folder: 0777 less
    the umask), and it then replaces ``out`` in one step (an atomic exchange on Linux,
    else two renames). Until then the previous folder stays whole; a failure or an
    interrupt leaves it as it was and removes the temporary folder, and the temporary
    folders of a killed call are removed by the next (:func:`_sweep`). A symbolic link
    ``out`` stays: the folder it points to is replaced. Holds :func:`output_lock`.

    Parameters
    ----------
    out : path
        The folder.
    writers : mapping of file name to callable
        ``{"result.npz": write_npz, ...}``; each is called with the path to write.
    owned : collection of str
        Further names of the set, removed from ``out`` when not written (a file the
        previous set had and this one has not, a file derived from the previous set).

    Returns
    -------
    Path
        ``out``.
    """
    with output_lock(out) as path:
        real = _real(path)
        _sweep(real)
        new = Path(tempfile.mkdtemp(dir=real.parent, prefix=f".{real.name}.", suffix=".tmp"))
        tmp: Path | None = new  # what is left to remove
        old: Path | None = None
        try:
            for name, write in writers.items():
                write(new / name)
            if real.is_dir():
                _carry(real, new, {*writers, *owned})
                _keep_attributes(real, real.stat(), new, writers)
                if not _exchange(new, real):
                    old = Path(tempfile.mkdtemp(dir=real.parent, prefix=f".{real.name}.", suffix=".old"))
                    os.replace(real, old)
                    os.replace(new, real)
                    old, tmp = None, old
            else:
                os.chmod(new, 0o777 & ~_umask())
                os.replace(new, real)
                tmp = None
        except BaseException:
            if old is not None and not real.exists():
                os.replace(old, real)
            raise
        finally:
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
    return Path(out)
