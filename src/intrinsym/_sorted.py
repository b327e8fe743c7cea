"""Bisection in a sorted slice, for Numba kernels.

``np.searchsorted`` inside a kernel compiles for about 1 s per side and signature on the
first run after install; these compile in a tenth of that.
"""

from __future__ import annotations

import numba as nb

__all__ = ["left", "right"]


@nb.njit(cache=True, nogil=True)
def right(values, lo, hi, x):  # pragma: no cover
    """The first index in [lo, hi) of the sorted ``values`` whose value exceeds ``x``
    (hi if none): ``lo + np.searchsorted(values[lo:hi], x, "right")``."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if values[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@nb.njit(cache=True, nogil=True)
def left(values, lo, hi, x):  # pragma: no cover
    """The first index in [lo, hi) of the sorted ``values`` whose value is at least ``x``
    (hi if none): ``lo + np.searchsorted(values[lo:hi], x, "left")``."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if values[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo
