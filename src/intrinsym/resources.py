"""How much memory this process can still use, and refusing work that would not fit.

A job too large for the machine is reported as a :class:`~intrinsym.errors.ResourceError`
(one line, like every user-facing error) before the allocation is attempted, instead
of failing later with a ``MemoryError`` or being killed by the operating system.
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import ResourceError, path_label


def available_memory() -> int | None:
    """Bytes of memory this process can still use, or None if unknown.

    Uses Linux's ``MemAvailable`` (free memory plus reclaimable cache), capped
    by a cgroup v2 memory limit when one is set, and falls back to
    ``os.sysconf`` (available, then total physical pages) elsewhere.
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
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text(encoding="ascii").strip()
        used = Path("/sys/fs/cgroup/memory.current").read_text(encoding="ascii").strip()
        if limit != "max":
            room = max(int(limit) - int(used), 0)
            avail = room if avail is None else min(avail, room)
    except (OSError, ValueError):
        pass
    return avail


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
    usable = 0.8 * avail
    if nbytes > usable:
        raise ResourceError(
            f"{path_label(path)}: {what} needs {nbytes / 1e9:.1f} GB, more than the "
            f"{usable / 1e9:.1f} GB of memory available"
        )
