"""How much memory this process can still use and how much disk its result needs, and
refusing work that would not fit.

A job too large for the machine is reported as a :class:`~intrinsym.errors.ResourceError`
(one line, like every user-facing error) before the allocation is attempted, instead
of failing later with a ``MemoryError`` or being killed by the operating system; a
result set the disk has no room for, as an :class:`~intrinsym.errors.OutputError`
before the run (:func:`check_disk`) or, should the disk fill up meanwhile, when it is
written (:func:`disk_room`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import OutputError, ResourceError, path_label

if TYPE_CHECKING:
    from .params import Params

#: BP iterations per pass the time estimate assumes: the median over the 36 shapes of
#: docs/results.md's benchmark (7-16 on 32 of them, 20, 24, 41 and 72 on the others).
TYPICAL_ITERATIONS = 11


def available_memory() -> int | None:
    """Bytes of memory this process can still use, or None if unknown.

    Uses Linux's ``MemAvailable`` (free memory plus reclaimable cache), capped
    by the memory limits of this process's cgroup and its ancestors (v1 or v2,
    :func:`cgroup_room`) and by its address-space limit (:func:`address_space_room`),
    and falls back to ``os.sysconf`` (available, then total physical pages) elsewhere.
    """
    avail = None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        avail = None
    if avail is None:
        for name in ("SC_AVPHYS_PAGES", "SC_PHYS_PAGES"):
            try:
                pages, page_size = os.sysconf(name), os.sysconf("SC_PAGE_SIZE")
            except (ValueError, OSError, AttributeError):
                continue
            if pages > 0 and page_size > 0:
                avail = pages * page_size
                break
    for room in (cgroup_room(), address_space_room()):
        if room is not None:
            avail = room if avail is None else min(avail, room)
    return avail


def address_space_room() -> int | None:
    """Bytes of address space this process may still map under its ``RLIMIT_AS`` limit
    (``ulimit -v``, ``prlimit --as``, set by many cluster schedulers): the limit less
    the address space mapped now; None without a limit.

    Mapped space counts more than the memory used (libraries, thread stacks and
    allocator arenas are mapped but mostly not touched), so this is an upper bound of
    what the process can still allocate.
    """
    try:
        import resource
    except ImportError:  # no resource limits on this system
        return None
    limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    if limit == resource.RLIM_INFINITY:
        return None
    return max(limit - _mapped_bytes(), 0)


def _mapped_bytes() -> int:
    """Bytes of address space this process maps now (``/proc/self/statm``; 0 where unknown)."""
    try:
        pages = int(Path("/proc/self/statm").read_text(encoding="ascii").split()[0])
        return pages * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


#: Where the cgroup file systems are mounted, and this process's cgroup membership.
CGROUP_ROOT = Path("/sys/fs/cgroup")
PROC_CGROUP = Path("/proc/self/cgroup")
#: A cgroup-v1 limit at or above this means "no limit" (the kernel's unlimited value is ~2**63).
_UNLIMITED = 2**60


def _read_int(path: Path) -> int | None:
    """The integer in a cgroup file; None when absent, unreadable or "max"."""
    try:
        text = path.read_text(encoding="ascii").strip()
        return None if text == "max" else int(text)
    except (OSError, ValueError):
        return None


def _room_along(leaf: Path, top: Path, limit_file: str, usage_file: str) -> int | None:
    """The least room (limit - usage) of the cgroups from ``leaf`` up to ``top``."""
    room = None
    folder = leaf
    while True:
        limit, used = _read_int(folder / limit_file), _read_int(folder / usage_file)
        if limit is not None and limit < _UNLIMITED:
            here = max(limit - (used or 0), 0)
            room = here if room is None else min(room, here)
        if folder == top or top not in folder.parents:
            return room
        folder = folder.parent


def cgroup_room(root: Path | None = None, proc_cgroup: Path | None = None) -> int | None:
    """Bytes this process may still allocate under its cgroups' memory limits.

    Reads the process's cgroup from ``/proc/self/cgroup`` and walks from it up to the
    hierarchy's root: cgroup v2 ``memory.max`` / ``memory.current``, cgroup v1
    ``memory.limit_in_bytes`` / ``memory.usage_in_bytes`` (the memory controller's
    mount, e.g. ``/sys/fs/cgroup/memory``). A nested group's limit counts as much as
    the top one's; the least room wins.

    Parameters
    ----------
    root : Path, optional
        Where the cgroup file systems are mounted (default :data:`CGROUP_ROOT`).
    proc_cgroup : Path, optional
        The membership file (default :data:`PROC_CGROUP`).

    Returns
    -------
    int or None
        None when no limit is set or none can be read.
    """
    root = CGROUP_ROOT if root is None else root
    proc_cgroup = PROC_CGROUP if proc_cgroup is None else proc_cgroup
    try:
        lines = proc_cgroup.read_text(encoding="utf-8").splitlines()
    except OSError:
        lines = []
    rooms = []
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        _, controllers, group = parts
        relative = group.strip().lstrip("/")
        if controllers == "":
            top, files = root, ("memory.max", "memory.current")
        elif "memory" in controllers.split(","):
            mounts = [root / "memory", root / controllers]
            top = next((m for m in mounts if m.is_dir()), mounts[0])
            files = ("memory.limit_in_bytes", "memory.usage_in_bytes")
        else:
            continue
        leaf = top / relative if (top / relative).is_dir() else top  # a namespace shows "/"
        room = _room_along(leaf, top, *files)
        if room is not None:
            rooms.append(room)
    if not lines:
        room = _room_along(root, root, "memory.max", "memory.current")
        if room is not None:
            rooms.append(room)
    return min(rooms) if rooms else None


def _available(avail: int) -> str:
    """The phrase "the 1.2 GB of memory available" (80 % of ``avail``), naming the
    address-space limit when it is what binds."""
    room = address_space_room()
    limit = " under this process's address-space limit (ulimit -v)" if room is not None and room <= avail else ""
    return f"the {format_bytes(0.8 * avail)} of memory available{limit}"


def format_bytes(nbytes: float) -> str:
    """Human-readable size: GB down to 0.1 GB, then MB, kB, bytes."""
    if nbytes >= 1e8:
        return f"{nbytes / 1e9:.1f} GB"
    if nbytes >= 1e5:
        return f"{nbytes / 1e6:.1f} MB"
    if nbytes >= 1e3:
        return f"{nbytes / 1e3:.1f} kB"
    return f"{int(nbytes)} bytes"


def check_memory(nbytes: int, what: str, path: str = "") -> None:
    """Refuse an allocation that would not fit in memory.

    Parameters
    ----------
    nbytes : int
        Size of the planned allocation, in bytes.
    what : str
        What the memory is for, e.g. ``"the 30000 x 30000 distance matrix"``.
    path : str
        The input file the work is for (starts the error message).

    Raises
    ------
    ResourceError
        If ``nbytes`` exceeds 80% of the memory currently available. The
        message reports the usable amount (80% of what is available). When
        the available memory cannot be determined nothing is checked.
    """
    avail = available_memory()
    if avail is None:
        return
    if nbytes > 0.8 * avail:
        raise ResourceError(f"{path_label(path)}: {what} needs {format_bytes(nbytes)}, more than {_available(avail)}")


@dataclass(frozen=True)
class Estimate:
    """Approximate peak memory and time of a run (:func:`estimate_run`).

    Attributes
    ----------
    nbytes : int
        Peak memory, bytes.
    seconds : float
        Wall-clock time on a 2-core machine (AMD EPYC), seconds.
    n_source, n_target : int
        The sample counts assumed.
    disk : int
        Bytes of the result set (:meth:`intrinsym.Result.save`), before compression.
    """

    nbytes: int
    seconds: float
    n_source: int
    n_target: int
    disk: int = 0

    def describe(self) -> str:
        """One line: "about 12 min and 3.4 GB (|Ps| = 2000, |Pt| = 60000; approximate)"."""
        t = self.seconds
        when = f"{t / 3600:.1f} h" if t >= 5400 else f"{t / 60:.0f} min" if t >= 90 else f"{t:.0f} s"
        return (
            f"about {when} and {format_bytes(self.nbytes)} (|Ps| = {self.n_source}, |Pt| = {self.n_target}; "
            "approximate, from a model of the stage times on a 2-core machine)"
        )


def _count(n: int | None, spacing: float | None) -> int:
    """Samples of a unit-area surface: the count, or the hexagonal packing of ``spacing``."""
    if n is not None and spacing is None:
        return n
    assert spacing is not None
    return max(int(2.0 / (np.sqrt(3.0) * spacing**2)), 2)


def estimate_run(n_vertices: int, p: Params, self_match: bool = True) -> Estimate:
    """Approximate peak memory and time of a run of ``p`` on a mesh of ``n_vertices``.

    A model of the measured stages (TOSCA cat1 and michael1 at |Ps| = 250, |Pt| = 4000
    and at the paper's elephant size, 271 / 12722, on the 2-core development machine;
    docs/notes/2026-11-28-speed-behind-the-defaults.md): the interpreter and libraries take 150 MB and 2 s; the working
    shape (a mesh of fewer than ``WORK_PER_SAMPLE`` max(|Ps|, |Pt|) vertices subdivided,
    each round four times as many) 11 kB and 0.16 ms per vertex (cleaning, geodesic
    graph, eigenpairs, the global map); the target distances 10 ns per vertex and
    target; the descriptors 0.8 us and 8 bytes per source-target pair and unary term.
    BP holds 6 (plus 2 per further pass) float32 |Ps| x |Pt| arrays and 2 messages of
    |Pt| per source edge (about 3 |Ps| edges), plus the target rings (about 23 |Pt| /
    |Ps| neighbours per target); one iteration visits each edge's ring rows, about
    0.07 us sqrt(|Ps|) |Pt|^1.5, for ``TYPICAL_ITERATIONS`` per pass. Within 40 % of
    the measured time and 20 % of the memory on the runs of docs/notes/2026-11-28-speed-behind-the-defaults.md; a run
    that needs many more BP iterations than the median takes longer. The result set
    holds the unary, the marginals of each pass and the target rings (12 bytes per
    neighbour) as float32 |Ps| x |Pt| arrays, and about 100 bytes per input vertex.

    Parameters
    ----------
    n_vertices : int
        Vertices of the (larger) input mesh.
    p : Params
    self_match : bool
        detect (True) or match (False: two passes by default, both shapes' descriptors).

    Returns
    -------
    Estimate
    """
    from .params import WORK_PER_SAMPLE  # here: the mesh readers use this module, and params sits above them

    s = _count(p.n_source, p.source_spacing)
    t = _count(p.n_target, p.target_spacing)
    passes = p.passes if p.passes is not None else 1 if self_match else 2
    work = max(n_vertices, 1)
    while work < WORK_PER_SAMPLE * max(s, t):  # each midpoint subdivision round quadruples a mesh
        work *= 4
    terms = len(p.unary_terms) * (1 if self_match else 2)
    itemsize = np.dtype(p.dtype).itemsize
    model = (6 + 2 * (passes - 1)) * s * t * 4 + 2 * 3 * s * t * itemsize + 272 * t * t // s
    unary = (terms + 1) * s * t * 8 + t * p.spin_bins**2 * 3 + 48 * p.spin_cloud
    nbytes = int(150e6 + 11000 * work + model + unary)
    iteration = 7e-8 * np.sqrt(s) * t**1.5
    bp = passes * min(p.iterations, TYPICAL_ITERATIONS) * iteration
    seconds = 2.0 + 1.6e-4 * work + 1e-8 * work * t + 8e-7 * s * t * terms + bp
    disk = (2 + (passes if passes > 1 else 0)) * s * t * 4 + 276 * t * t // s + 100 * max(n_vertices, 1)
    return Estimate(nbytes, float(seconds), s, t, int(disk))


def check_run(n_vertices: int, p: Params, path: str = "", self_match: bool = True) -> Estimate:
    """:func:`estimate_run`, refusing a run whose estimate does not fit in memory.

    Raises
    ------
    ResourceError
        When the estimate exceeds 80% of the memory available (:func:`available_memory`,
        cgroup limits included), naming the estimate and the options that lower it.
    """
    estimate = estimate_run(n_vertices, p, self_match)
    avail = available_memory()
    if avail is not None and estimate.nbytes > 0.8 * avail:
        raise ResourceError(
            f"{path_label(path)}: the run needs {estimate.describe()}, more than {_available(avail)}; "
            "lower --target, then --source "
            "(or raise --target-spacing, --source-spacing)"
        )
    return estimate


def check_disk(out: str | os.PathLike, nbytes: int) -> None:
    """Refuse a result set of ``nbytes`` that the file system of the result folder
    ``out`` has no room for (the new set is written beside the old one, which stays
    until the new one is whole).

    Raises
    ------
    OutputError
        Naming ``out``, the space needed and the space free.
    """
    folder = Path(out).absolute().parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:  # the folder's own check (files.check_output_dir) reports what is wrong
        return
    if nbytes > free:
        raise OutputError(_no_room(out, nbytes, free))


def _no_room(out: str | os.PathLike, nbytes: int, free: int) -> str:
    return (
        f"{path_label(out)}: not enough disk space for the result set: it needs about {format_bytes(nbytes)}, "
        f"{format_bytes(free)} free"
    )


@contextlib.contextmanager
def disk_room(out: str | os.PathLike, nbytes: int) -> Iterator[None]:
    """:func:`check_disk`, then the ``with`` block, in which a full disk (or quota) is
    reported as an :class:`~intrinsym.errors.OutputError` naming ``out`` and ``nbytes``
    instead of an ``OSError`` (the earlier result set in ``out`` stays whole,
    :func:`intrinsym.files.write_set`)."""
    check_disk(out, nbytes)
    try:
        yield
    except OSError as err:
        if err.errno not in (errno.ENOSPC, errno.EDQUOT):
            raise
        try:
            free = shutil.disk_usage(Path(out).absolute().parent).free
        except OSError:
            free = 0
        raise OutputError(f"{_no_room(out, nbytes, free)} (the disk filled up while writing)") from None
