"""Point descriptors: spin images with their NMI similarity, and spectral signatures.

This module provides the unary-potential ingredients of the paper (Lasowski et al.,
ICCV 2009, Sec. 4): spin images (Johnson & Hebert 1999) of oriented points computed
against a dense, area-uniform sample of the whole surface, an intensity quantisation
of those images, and the normalised mutual information between quantised images in
the corrected form ``NMI' = NMI - 1 = (H1 + H2 - H12) / H12`` in ``[0, 1]`` (the
paper's Eq. 2-4 give NMI in [1, 2]; Eq. 5 needs a similarity in [0, 1]).

Beyond the paper, the Laplace-Beltrami eigenpairs of :mod:`intrinsym.spectral.laplacian` give
the intrinsic, pose- and reflection-invariant wave- and heat-kernel signatures that the
default unary (``wks*spin``) is built on.

All functions take and return plain NumPy arrays; the hot loops are Numba kernels
parallelised over query points (spin images) or source rows (NMI).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .._sorted import left
from .._threads import map_ranges
from ..errors import ParameterError

#: Largest number of cells a uniform grid may address (cell keys are int64).
_MAX_GRID_CELLS = 2**62
#: Grid cells per support radius: each query scans the (2 * reach + 1)^3 block of cells
#: around it. Half-radius cells (reach 2: 125 cells of edge radius / 2) scan about 30 %
#: fewer cloud points on a surface than radius cells (reach 1: 27 cells).
_CELLS_PER_RADIUS = 2
#: Relative enlargement of the grid cell over ``radius / reach``, so that rounding in
#: the cell coordinates can never push a point at distance exactly ``radius`` out of
#: the block of cells scanned around its query point.
_CELL_SLACK = 1e-9


@njit(cache=True, nogil=True)
def _spin_kernel(
    lo_query: int,
    hi_query: int,
    points: np.ndarray,
    normals: np.ndarray,
    cloud: np.ndarray,
    keys: np.ndarray,
    origin: np.ndarray,
    dims: np.ndarray,
    cell: float,
    reach: int,
    order: np.ndarray,
    radius: float,
    bins: int,
    out: np.ndarray,
) -> None:
    """Accumulate normalised spin images into ``out`` (P, bins, bins) float32, for the
    query points ``order[lo_query:hi_query]``.

    ``cloud`` (M, 3) is sorted by the int64 cell key ``keys`` (M,) of the uniform grid
    with corner ``origin`` (3,), cell edge ``cell`` (>= radius / reach) and ``dims``
    (3,) cells per axis, key = (i * ny + j) * nz + k. Query points are visited in the
    order ``order`` (P,) (spatially sorted, for cache locality).
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    r2 = radius * radius
    inv_alpha = bins / radius  # columns: alpha in [0, radius)
    inv_beta = bins / (2.0 * radius)  # rows: beta in [-radius, radius)
    top = float(bins - 1)
    for qq in range(lo_query, hi_query):
        q = order[qq]
        px = points[q, 0]
        py = points[q, 1]
        pz = points[q, 2]
        nxq = normals[q, 0]
        nyq = normals[q, 1]
        nzq = normals[q, 2]
        img = np.zeros((bins, bins), dtype=np.float64)
        count = 0
        # Cell coordinates, clipped before the integer conversion so that query points
        # far outside the cloud's bounding box cannot overflow.
        lo_clip = -reach - 1.0
        ci = int(min(max(np.floor((px - origin[0]) / cell), lo_clip), nx + reach))
        cj = int(min(max(np.floor((py - origin[1]) / cell), lo_clip), ny + reach))
        ck = int(min(max(np.floor((pz - origin[2]) / cell), lo_clip), nz + reach))
        k0 = max(ck - reach, 0)
        k1 = min(ck + reach, nz - 1)
        if k0 <= k1:
            for i in range(max(ci - reach, 0), min(ci + reach + 1, nx)):
                for j in range(max(cj - reach, 0), min(cj + reach + 1, ny)):
                    # Cells (i, j, k0..k1) are contiguous in the sorted cloud.
                    base = (i * ny + j) * nz
                    lo = left(keys, 0, len(keys), base + k0)
                    hi = left(keys, 0, len(keys), base + k1 + 1)
                    for m in range(lo, hi):
                        dx = cloud[m, 0] - px
                        dy = cloud[m, 1] - py
                        dz = cloud[m, 2] - pz
                        d2 = dx * dx + dy * dy + dz * dz
                        if d2 > r2:
                            continue
                        beta = nxq * dx + nyq * dy + nzq * dz
                        alpha = np.sqrt(max(d2 - beta * beta, 0.0))
                        # Continuous bin coordinates relative to bin centres, clamped
                        # to the image so every support point adds unit mass.
                        u = min(max(alpha * inv_alpha - 0.5, 0.0), top)
                        v = min(max((beta + radius) * inv_beta - 0.5, 0.0), top)
                        iu = min(int(u), bins - 2)
                        iv = min(int(v), bins - 2)
                        fu = u - iu
                        fv = v - iv
                        img[iv, iu] += (1.0 - fv) * (1.0 - fu)
                        img[iv, iu + 1] += (1.0 - fv) * fu
                        img[iv + 1, iu] += fv * (1.0 - fu)
                        img[iv + 1, iu + 1] += fv * fu
                        count += 1
        if count > 0:
            scale = 1.0 / count
            for a in range(bins):
                for b in range(bins):
                    out[q, a, b] = img[a, b] * scale


def spin_images(
    points: np.ndarray,
    normals: np.ndarray,
    cloud: np.ndarray,
    radius: float,
    bins: int = 16,
) -> np.ndarray:
    """Spin images (Johnson & Hebert 1999) of oriented points against a point cloud.

    For the oriented point ``(p, n)`` every cloud point ``x`` with ``|x - p| <= radius``
    contributes at ``beta = n . (x - p)`` (signed height along the normal) and
    ``alpha = sqrt(|x - p|^2 - beta^2)`` (distance from the normal line). The image has
    ``bins`` columns of width ``radius / bins`` covering ``alpha`` in ``[0, radius)``
    and ``bins`` rows of height ``2 * radius / bins`` covering ``beta`` in
    ``[-radius, radius)``; row index grows with ``beta`` (row 0 is ``beta ~ -radius``).
    Each contribution is spread bilinearly over the 4 bins whose centres surround
    ``(alpha, beta)``; coordinates within half a bin of the border (e.g. points near
    the normal line) are clamped to the outermost bin centres, so every support point
    adds exactly unit mass. Each image is then divided by its sum (the number of
    support points); an image with an empty support stays zero.

    The descriptor depends only on distances and the normal, so it is invariant to
    rotations, translations and reflections applied to points, normals and cloud
    together, and to a uniform scaling of the shape together with ``radius``.

    Parameters
    ----------
    points : np.ndarray
        (P, 3) float, positions of the oriented points (length unit of the shape).
    normals : np.ndarray
        (P, 3) float, unit normals at ``points`` (not re-normalised here).
    cloud : np.ndarray
        (M, 3) float, dense area-uniform sample of the whole surface, same unit.
    radius : float
        Support radius (same length unit), > 0.
    bins : int, optional
        Number of rows and of columns of each image, >= 2. Default 16.

    Returns
    -------
    np.ndarray
        (P, bins, bins) float32, ``[q, row, col]`` = mass at
        ``beta ~ -radius + (row + 0.5) * 2 * radius / bins`` and
        ``alpha ~ (col + 0.5) * radius / bins``; each image sums to 1 (or is all 0).

    Notes
    -----
    Neighbours are found with a uniform grid hash (cell edge ``radius / 2``): the cloud
    is sorted by cell key and each query scans the 5 x 5 x 5 block of cells around it
    (25 contiguous runs of the sorted cloud, located by binary search), in parallel over
    the query points taken in grid order.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    cloud = np.ascontiguousarray(cloud, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or normals.shape != points.shape:
        raise ValueError(f"points and normals must both be (P, 3); got {points.shape}, {normals.shape}")
    if cloud.ndim != 2 or cloud.shape[1] != 3:
        raise ValueError(f"cloud must be (M, 3); got {cloud.shape}")
    if not (np.isfinite(points).all() and np.isfinite(normals).all() and np.isfinite(cloud).all()):
        raise ValueError("points, normals and cloud must be finite")
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive finite number; got {radius}")
    if bins < 2:
        raise ValueError(f"bins must be >= 2; got {bins}")
    out = np.zeros((points.shape[0], bins, bins), dtype=np.float32)
    if points.shape[0] == 0 or cloud.shape[0] == 0:
        return out

    reach = _CELLS_PER_RADIUS
    cell = float(radius) / reach * (1.0 + _CELL_SLACK)
    origin = cloud.min(axis=0)
    coords = np.floor((cloud - origin) / cell).astype(np.int64)
    dims = coords.max(axis=0) + 1
    if float(np.prod(dims.astype(np.float64))) >= _MAX_GRID_CELLS:
        raise ValueError(f"radius {radius} is too small for the cloud's extent: grid of {dims} cells")
    keys = (coords[:, 0] * dims[1] + coords[:, 1]) * dims[2] + coords[:, 2]
    cloud_order = np.argsort(keys, kind="stable")
    # Visit the queries in grid order (cells clipped to one layer around the grid).
    qcoords = np.clip(np.floor((points - origin) / cell), -1.0, dims).astype(np.int64) + 1
    qkeys = (qcoords[:, 0] * (dims[1] + 2) + qcoords[:, 1]) * (dims[2] + 2) + qcoords[:, 2]
    query_order = np.argsort(qkeys, kind="stable")
    sorted_cloud = np.ascontiguousarray(cloud[cloud_order])
    sorted_keys = np.ascontiguousarray(keys[cloud_order])
    args = (
        points,
        normals,
        sorted_cloud,
        sorted_keys,
        origin,
        dims,
        cell,
        reach,
        query_order,
        float(radius),
        int(bins),
    )
    map_ranges(_spin_kernel, len(points), *args, out)
    return out


def quantize(images: np.ndarray, levels: int = 8) -> np.ndarray:
    """Quantise non-negative images into ``levels`` intensity levels, per image.

    Each image is scaled by its own maximum: ``level = min(levels - 1,
    floor(levels * v / max))``, so the brightest pixel of every image gets level
    ``levels - 1`` and empty pixels get level 0. Scaling per image (rather than by a
    global maximum) makes the levels independent of how many support points an image
    has and of how concentrated its mass is, so that NMI compares the *pattern* of two
    images; an all-zero image is all level 0.

    Parameters
    ----------
    images : np.ndarray
        (P, bins, bins) or (P, B) float, non-negative intensities (e.g. spin images).
    levels : int, optional
        Number of intensity levels, 1 <= levels <= 256. Default 8.

    Returns
    -------
    np.ndarray
        (P, B) uint8 with values in ``[0, levels - 1]``; images are flattened row-major.
    """
    if not 1 <= levels <= 256:
        raise ValueError(f"levels must be in [1, 256]; got {levels}")
    images = np.asarray(images, dtype=np.float64)
    if images.ndim not in (2, 3):
        raise ValueError(f"images must be (P, bins, bins) or (P, B); got {images.shape}")
    flat = images.reshape(images.shape[0], -1)
    if flat.size and flat.min() < 0:
        raise ValueError("images must be non-negative")
    peak = flat.max(axis=1, keepdims=True) if flat.size else np.zeros((flat.shape[0], 1))
    scale = np.divide(levels, peak, out=np.zeros_like(peak), where=peak > 0)
    return np.minimum(np.floor(flat * scale), levels - 1).astype(np.uint8)


@njit(cache=True)
def _clogc_table(n_pixels: int) -> np.ndarray:
    """Table ``t[c] = c * log(c / B)`` for integer counts ``c`` in ``0..B`` (B,) + 1.

    The entropy of a histogram with counts ``c_i`` over ``B`` samples is then
    ``-sum_i t[c_i] / B`` (nats), exactly 0 for a single full bin.
    """
    table = np.zeros(n_pixels + 1, dtype=np.float64)
    for c in range(1, n_pixels + 1):
        table[c] = c * np.log(c / n_pixels)
    return table


@njit(cache=True, nogil=True)
def _entropies(lo: int, hi: int, q: np.ndarray, levels: int, table: np.ndarray, out: np.ndarray) -> None:
    """Entropy (nats) of the level histogram of rows ``lo:hi`` of ``q`` (N, B), into
    ``out`` (N,)."""
    n_pixels = q.shape[1]
    for i in range(lo, hi):
        hist = np.zeros(levels, dtype=np.int64)
        for k in range(n_pixels):
            hist[q[i, k]] += 1
        acc = 0.0
        for c in range(levels):
            acc += table[hist[c]]
        out[i] = -acc / n_pixels


def _entropy_rows(q: np.ndarray, levels: int, table: np.ndarray) -> np.ndarray:
    """:func:`_entropies` of every row of ``q`` (N, B) -> (N,) float64."""
    out = np.empty(len(q), dtype=np.float64)
    map_ranges(_entropies, len(q), q, levels, table, out)
    return out


@njit(cache=True, nogil=True)
def _nmi_kernel(
    lo: int,
    hi: int,
    qa: np.ndarray,
    qb: np.ndarray,
    ha: np.ndarray,
    hb: np.ndarray,
    table: np.ndarray,
    levels: int,
    out: np.ndarray,
) -> None:
    """Fill rows ``lo:hi`` of ``out`` (S, T) float32 with ``(H1 + H2 - H12) / H12``."""
    n_pixels = qa.shape[1]
    n_b = qb.shape[0]
    n_joint = levels * levels
    inv_pixels = 1.0 / n_pixels
    # Summing the table over the whole joint histogram costs levels^2 per pair; past
    # B cells it is cheaper to revisit only the (at most B) cells the pair touched.
    scan_cells = n_joint <= n_pixels
    for s in range(lo, hi):
        hist = np.zeros(n_joint, dtype=np.int32)
        row = np.empty(n_pixels, dtype=np.int32)
        for k in range(n_pixels):
            row[k] = qa[s, k] * levels
        for t in range(n_b):
            for k in range(n_pixels):
                hist[row[k] + qb[t, k]] += 1
            acc = 0.0
            if scan_cells:
                for c in range(n_joint):
                    acc += table[hist[c]]
                    hist[c] = 0
            else:
                for k in range(n_pixels):
                    idx = row[k] + qb[t, k]
                    acc += table[hist[idx]]
                    hist[idx] = 0
            h12 = -acc * inv_pixels
            if h12 <= 0.0:
                out[s, t] = 1.0
            else:
                value = (ha[s] + hb[t] - h12) / h12
                out[s, t] = min(max(value, 0.0), 1.0)


def nmi(qa: np.ndarray, qb: np.ndarray, levels: int = 8) -> np.ndarray:
    """Corrected normalised mutual information between all pairs of quantised images.

    ``NMI' = NMI - 1 = (H1 + H2 - H12) / H12`` (paper Eq. 2-4, shifted by -1), where
    ``H1``, ``H2`` are the entropies of the level histograms of the
    two images over their ``B`` pixels and ``H12`` the entropy of the joint
    (levels x levels) histogram of the ``B`` pixel pairs. ``NMI'`` lies in ``[0, 1]``:
    1 for images that determine each other (identical up to a relabelling of levels),
    about 0 for independent ones. When ``H12 == 0`` (both images constant) it is
    defined as 1; a constant image against a non-constant one gives 0.

    Parameters
    ----------
    qa : np.ndarray
        (S, B) uint8 quantised images (see :func:`quantize`), values < ``levels``.
    qb : np.ndarray
        (T, B) uint8 quantised images, values < ``levels``.
    levels : int, optional
        Number of intensity levels used in the quantisation, 1..256. Default 8.

    Returns
    -------
    np.ndarray
        (S, T) float32, ``NMI'`` of ``qa[s]`` and ``qb[t]`` (dimensionless).
    """
    if not 1 <= levels <= 256:
        raise ValueError(f"levels must be in [1, 256]; got {levels}")
    qa = np.ascontiguousarray(qa, dtype=np.uint8)
    qb = np.ascontiguousarray(qb, dtype=np.uint8)
    if qa.ndim != 2 or qb.ndim != 2 or qa.shape[1] != qb.shape[1]:
        raise ValueError(f"qa and qb must be (S, B) and (T, B); got {qa.shape}, {qb.shape}")
    out = np.empty((qa.shape[0], qb.shape[0]), dtype=np.float32)
    n_pixels = qa.shape[1]
    if out.size == 0 or n_pixels == 0:
        out.fill(1.0)
        return out
    if int(qa.max()) >= levels or int(qb.max()) >= levels:
        raise ValueError(f"quantised values must be < levels = {levels}")
    table = _clogc_table(n_pixels)
    ha, hb = _entropy_rows(qa, levels, table), _entropy_rows(qb, levels, table)
    map_ranges(_nmi_kernel, len(qa), qa, qb, ha, hb, table, int(levels), out)
    return out


def constant_modes(evals: np.ndarray) -> int:
    """The number of zero eigenvalues at the start of ``evals``, zero up to rounding
    (below 1e-8 of the largest): one per connected component (its constant function) in
    a spectrum that keeps them all; 1 for :func:`intrinsym.spectral.laplacian.eigenpairs`, which
    keeps one.

    Parameters
    ----------
    evals : (K,) float array
        Ascending eigenvalues.

    Returns
    -------
    int
        At least 1.

    Raises
    ------
    ParameterError
        When no eigenvalue is non-zero: the shape has at least as many connected
        components as eigenpairs.
    """
    c = max(int(np.count_nonzero(evals <= 1e-8 * evals[-1])), 1)
    if c >= len(evals):
        raise ParameterError(
            f"the shape has at least {len(evals)} connected components, as many as the Laplace-Beltrami "
            "eigenpairs: raise --eigenpairs above their number or use --unary spin"
        )
    return c


def wks_energies(evals: np.ndarray, n_energies: int = 100, variance: float = 6.0) -> tuple[np.ndarray, float]:
    """Log-energy grid and bandwidth of the wave-kernel signature (Aubry et al. 2011).

    The ``n_energies`` log-energies span ``[log lambda_1 + 2 sigma, log lambda_max -
    2 sigma]`` with ``sigma = variance * (log lambda_max - log lambda_1) / n_energies``,
    ``lambda_1`` the first non-zero eigenvalue.

    Parameters
    ----------
    evals : (K,) float array
        Ascending eigenvalues (1 / length^2), the first the constant modes (one per
        connected component, see :func:`constant_modes`).
    n_energies : int
    variance : float
        Bandwidth in grid steps (Aubry et al.: 6).

    Returns
    -------
    energies : (n_energies,) float64
        Log-energies, log(1 / length^2).
    sigma : float
        Gaussian bandwidth in log-energy.
    """
    lo, hi = np.log(evals[constant_modes(evals)]), np.log(evals[-1])
    sigma = variance * (hi - lo) / n_energies
    return np.linspace(lo + 2 * sigma, hi - 2 * sigma, n_energies), float(sigma)


def wave_kernel_signature(evals: np.ndarray, evecs: np.ndarray, energies: np.ndarray, sigma: float) -> np.ndarray:
    """Logarithm of the wave-kernel signature of points (Aubry, Schlickewei, Cremers 2011).

    ``WKS(x, e) = sum_k phi_k(x)^2 f_e(lambda_k)^2 / sum_k f_e(lambda_k)^2`` with
    ``f_e(lambda)^2 = exp(-(e - log lambda)^2 / (2 sigma^2))``, over the non-constant
    modes. The WKS is intrinsic (invariant to isometric bending and to reflection) and,
    being a ratio of sums over whole eigenspaces, independent of the eigenbasis chosen
    inside an eigenspace. The logarithm spreads its orders of magnitude evenly, so
    Euclidean distances weigh all energies alike.

    Parameters
    ----------
    evals : (K,) float array
        Ascending eigenvalues, the first the constant modes (skipped, see
        :func:`constant_modes`).
    evecs : (P, K) float array
        Eigenfunctions at the P points of interest (rows of :func:`intrinsym.spectral.laplacian.eigenpairs`' evecs).
    energies : (E,) float array
        Log-energies (see :func:`wks_energies`).
    sigma : float
        Bandwidth in log-energy.

    Returns
    -------
    (P, E) float64, ``log WKS``; for unit-area shapes scale-free.
    """
    c = constant_modes(evals)
    coef = np.exp(-((energies[:, None] - np.log(evals[c:])[None, :]) ** 2) / (2.0 * sigma**2))  # (E, K - c)
    wks = (evecs[:, c:] ** 2) @ coef.T / coef.sum(axis=1)
    return np.log(np.maximum(wks, np.finfo(np.float64).tiny))


def hks_times(evals: np.ndarray, n_times: int = 100) -> np.ndarray:
    """Diffusion times of the heat-kernel signature (Sun, Ovsjanikov, Guibas 2009).

    Log-spaced over ``[4 ln 10 / lambda_max, 4 ln 10 / lambda_1]``, the range in which
    the truncated spectrum still resolves the kernel.

    Returns
    -------
    (n_times,) float64, times in length^2.
    """
    c = 4.0 * np.log(10.0)
    return np.geomspace(c / evals[-1], c / evals[constant_modes(evals)], n_times)


def heat_kernel_signature(evals: np.ndarray, evecs: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Logarithm of the scaled heat-kernel signature of points.

    ``HKS(x, t) = sum_k exp(-lambda_k t) phi_k(x)^2 / sum_k exp(-lambda_k t)``: the
    heat kernel's diagonal divided by the heat trace (Sun et al. 2009), intrinsic and
    reflection-invariant like the WKS.

    Parameters
    ----------
    evals : (K,) float array
        Ascending eigenvalues.
    evecs : (P, K) float array
        Eigenfunctions at the points of interest.
    times : (E,) float array
        Diffusion times (see :func:`hks_times`).

    Returns
    -------
    (P, E) float64, ``log HKS``.
    """
    decay = np.exp(-np.outer(times, evals))
    hks = (evecs**2) @ decay.T / decay.sum(axis=1)
    return np.log(np.maximum(hks, np.finfo(np.float64).tiny))
