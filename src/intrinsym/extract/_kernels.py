"""Numba kernels of the symmetry extraction (:mod:`intrinsym.extract.extract`).

They work on raw CSR arrays: the source graph (``g_ptr``, ``g_nbr``, ``g_len``, see
:class:`~intrinsym.extract.support.SourceGraph`) and the sparse, distance-sorted target-target
geodesics (``t_ptr``, ``t_idx``, ``t_dist``, see
:class:`~intrinsym.geodesics.geodesics.SparseDistances`). Maps are (S,) int64 arrays of target
samples, -1 where unmapped.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .._sorted import left, right


@nb.njit(cache=True)
def find(t_ptr, t_idx, t_dist, a, b, limit):
    """d_T(a, b) when b lies in row a within ``limit``, else inf."""
    lo = t_ptr[a]
    hi = right(t_dist, lo, t_ptr[a + 1], limit)
    for k in range(lo, hi):
        if t_idx[k] == b:
            return t_dist[k]
    return np.inf


@nb.njit(cache=True)
def peaks(cand, n_t, t_ptr, t_idx, t_dist, radius):
    """Distinct peaks among candidate targets ``cand``, given strongest first.

    Greedy non-maximum suppression: the strongest remaining candidate is a peak and
    suppresses every target within ``radius`` of it.
    """
    gone = np.zeros(n_t, dtype=np.bool_)
    out = np.empty(len(cand), dtype=np.int64)
    k = 0
    for t in cand:
        if gone[t]:
            continue
        out[k] = t
        k += 1
        lo = t_ptr[t]
        hi = right(t_dist, lo, t_ptr[t + 1], radius)
        for j in range(lo, hi):
            gone[t_idx[j]] = True
    return out[:k]


@nb.njit(cache=True)
def fit(image, n, candidate, g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, cap):
    """How candidate fits as the image of n, over the mapped neighbours k of n.

    Returns the number of them with |d_T(f(k), candidate) - d_S(k, n)| < d_error, the
    number with that residual < cap, and the sum of min(residual, cap)^2 (cap >= d_error).
    """
    count = 0
    within_cap = 0
    total = 0.0
    for e in range(g_ptr[n], g_ptr[n + 1]):
        k = g_nbr[e]
        if image[k] >= 0:
            r = abs(find(t_ptr, t_idx, t_dist, image[k], candidate, g_len[e] + cap) - g_len[e])
            count += r < d_error
            within_cap += r < cap
            total += min(r, cap) ** 2
    return count, within_cap, total


@nb.njit(cache=True)
def grow(
    norm,
    g_ptr,
    g_nbr,
    g_len,
    t_ptr,
    t_idx,
    t_dist,
    threshold,
    d_error,
    min_support,
    self_target,
    identity_radius,
    side,
    image,
):
    """Region growing of Sec. 5.1 (breadth first) from the samples already in ``image``.

    ``image`` (S,) holds the map so far (-1 = unmapped) and is extended in place. A
    neighbour n of a mapped m may take any target t' >= threshold with
    |d_T(f(m), t') - d_S(m, n)| < d_error (a contiguous slice of the sorted row of f(m)).
    Among those it takes the one that agrees with most of its mapped neighbours, then
    the largest marginal, if at least ``min_support`` of them agree and no more than
    half of them contradict it by more than 2 d_error (beyond the paper: where two
    maps meet, e.g. rotations of a star at its centre, a candidate can keep the
    parent's length and no other; the looser bar lets near-isometric bends through).
    ``side`` 1 (0) allows only targets within (outside) ``identity_radius`` of n
    itself, the target ``self_target[n]``; -1 allows all. Returns the map's size.
    """
    cand = np.empty(norm.shape[1], dtype=np.int64)
    support_of = np.empty(norm.shape[1], dtype=np.int64)
    loose_of = np.empty(norm.shape[1], dtype=np.int64)
    # one mapped neighbour's target row at a time, scattered: what fit's find looks up
    # per candidate (a scan of the row) becomes one read
    dense = np.full(norm.shape[1], np.inf)
    cap = 2 * d_error
    queue = np.empty(len(image), dtype=np.int64)
    tail = 0
    for m in range(len(image)):  # np.flatnonzero compiles for 0.6 s on the first run
        if image[m] >= 0:
            queue[tail] = m
            tail += 1
    head = 0
    while head < tail:
        m = queue[head]
        head += 1
        row_lo, row_hi = t_ptr[image[m]], t_ptr[image[m] + 1]
        for e in range(g_ptr[m], g_ptr[m + 1]):
            n = g_nbr[e]
            if image[n] >= 0:
                continue
            lo = right(t_dist, row_lo, row_hi, g_len[e] - d_error)
            hi = left(t_dist, row_lo, row_hi, g_len[e] + d_error)
            n_cand = 0
            for k in range(lo, hi):
                if norm[n, t_idx[k]] < threshold:
                    continue
                if side >= 0:
                    near = find(t_ptr, t_idx, t_dist, self_target[n], t_idx[k], identity_radius) <= identity_radius
                    if near != (side == 1):
                        continue
                cand[n_cand] = t_idx[k]
                n_cand += 1
            best, best_support, best_value = -1, -1, threshold
            if n_cand == 0:
                continue
            # fit's counts for every candidate at once, the neighbours' rows read once each
            mapped = 0
            support_of[:n_cand] = 0
            loose_of[:n_cand] = 0
            for f in range(g_ptr[n], g_ptr[n + 1]):
                k = image[g_nbr[f]]
                if k < 0:
                    continue
                mapped += 1
                near_lo = t_ptr[k]
                near_hi = right(t_dist, near_lo, t_ptr[k + 1], g_len[f] + cap)
                for j in range(near_lo, near_hi):
                    dense[t_idx[j]] = t_dist[j]
                for c in range(n_cand):
                    r = abs(dense[cand[c]] - g_len[f])
                    support_of[c] += r < d_error
                    loose_of[c] += r < cap
                for j in range(near_lo, near_hi):
                    dense[t_idx[j]] = np.inf
            for c in range(n_cand):
                value = norm[n, cand[c]]
                support, loose = support_of[c], loose_of[c]
                if support < min_support or 2 * loose < mapped:
                    continue
                if support > best_support or (support == best_support and value >= best_value):
                    best, best_support, best_value = cand[c], support, value
            if best >= 0:
                image[n] = best
                queue[tail] = n
                tail += 1
    return tail


@nb.njit(cache=True)
def refine(image, g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, min_neighbours, passes):
    """Move the inconsistent samples of a map to the target that best keeps their edge lengths.

    A sample n is inconsistent when the distortion of its image (:func:`fit`,
    residuals capped at 3 d_error) exceeds d_error^2 per mapped neighbour; samples that agree with
    their neighbours stay. Candidates for n are the targets at d_S(k, n) +- d_error from
    the image of each mapped neighbour k; n moves to the one of least distortion when
    that is less than half of its current image's. Repeated ``passes`` times or until
    nothing moves. Returns the number of moves.
    """
    cap = 3.0 * d_error
    moves = 0
    for _ in range(passes):
        moved = 0
        for n in range(len(image)):
            if image[n] < 0:
                continue
            mapped = 0
            for e in range(g_ptr[n], g_ptr[n + 1]):
                mapped += image[g_nbr[e]] >= 0
            if mapped < min_neighbours:
                continue
            best = image[n]
            best_cost = fit(image, n, best, g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, cap)[2]
            current = best_cost
            if current <= mapped * d_error**2:
                continue
            for e in range(g_ptr[n], g_ptr[n + 1]):
                k = g_nbr[e]
                if image[k] < 0:
                    continue
                row_lo, row_hi = t_ptr[image[k]], t_ptr[image[k] + 1]
                lo = right(t_dist, row_lo, row_hi, g_len[e] - d_error)
                hi = left(t_dist, row_lo, row_hi, g_len[e] + d_error)
                for j in range(lo, hi):
                    cost = fit(image, n, t_idx[j], g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, cap)[2]
                    if cost < best_cost:
                        best, best_cost = t_idx[j], cost
            if best != image[n] and best_cost < 0.5 * current:
                image[n] = best
                moved += 1
        moves += moved
        if moved == 0:
            break
    return moves


@nb.njit(cache=True)
def _compared(a, b, u, internal, e, g_nbr):
    """Whether edge ``e`` (u, v) is one :func:`edge_agreement` compares, u mapped by a and
    not compared on its own images."""
    v = g_nbr[e]
    return not (b[v] < 0 or (not internal and a[v] >= 0) or (internal and v < u))


@nb.njit(cache=True)
def _comparisons(a, b, internal, g_ptr, g_nbr):
    """How many comparisons :func:`edge_agreement` makes."""
    n = 0
    for u in range(len(a)):
        if a[u] < 0:
            continue
        if b[u] >= 0 and not internal:
            n += 1
            continue
        for e in range(g_ptr[u], g_ptr[u + 1]):
            if _compared(a, b, u, internal, e, g_nbr):
                n += 1
    return n


@nb.njit(cache=True)
def edge_agreement(a, b, internal, g_ptr, g_nbr, g_len, t_ptr, t_idx, t_dist, d_error, same_tol, share=0.0):
    """(agreeing, disagreeing) counts between maps a and b, both (S,) with -1 = unmapped.

    A sample mapped by both agrees when its two images lie within ``same_tol``; an edge
    (u, v) with u mapped only by a and v only by b agrees when the images keep the edge
    length within ``d_error``. With ``internal`` (and a = b) it counts the edges inside
    one map instead: its consistency.

    With ``share`` > 0 it stops as soon as ``agreeing >= share * (agreeing + disagreeing)``
    is out of reach whatever the comparisons left give (most pairs of different maps
    disagree early): the counts are then those made so far, and they fail that test too.
    """
    remaining = _comparisons(a, b, internal, g_ptr, g_nbr) if share > 0 else 0
    good, bad = 0, 0
    for u in range(len(a)):
        if a[u] < 0:
            continue
        if b[u] >= 0 and not internal:
            remaining -= 1
            if find(t_ptr, t_idx, t_dist, a[u], b[u], same_tol) <= same_tol:
                good += 1
            else:
                bad += 1
                if share > 0 and good + remaining < share * (good + remaining + bad):
                    return good, bad
            continue
        for e in range(g_ptr[u], g_ptr[u + 1]):
            if not _compared(a, b, u, internal, e, g_nbr):
                continue
            remaining -= 1
            d = find(t_ptr, t_idx, t_dist, a[u], b[g_nbr[e]], g_len[e] + d_error)
            if abs(d - g_len[e]) < d_error:
                good += 1
            else:
                bad += 1
                if share > 0 and good + remaining < share * (good + remaining + bad):
                    return good, bad
    return good, bad


@nb.njit(cache=True)
def dilate(mask, centres, t_ptr, t_idx, t_dist, radius):
    """mask[t] = True for every target t within ``radius`` of a centre (-1 skipped)."""
    for c in centres:
        if c < 0:
            continue
        lo = t_ptr[c]
        hi = right(t_dist, lo, t_ptr[c + 1], radius)
        for k in range(lo, hi):
            mask[t_idx[k]] = True


@nb.njit(cache=True)
def mark_covered(covered, image, t_ptr, t_idx, t_dist, radius):
    """covered[s, t] = True for every t within ``radius`` of image[s]."""
    for s in range(len(image)):
        dilate(covered[s], image[s : s + 1], t_ptr, t_idx, t_dist, radius)
