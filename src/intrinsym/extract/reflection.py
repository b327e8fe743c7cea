"""Does a self-map of the samples act as a reflection? The global/partial decision's test.

With the identity removed, BP's argmax on a shape with a global reflection is that
reflection where the marginals are right; on a shape without one it is a self-map BP
invents (on the generated partial shape: a smooth self-map of the asymmetric body).
Two properties of a reflection that nothing in the model gives an invented self-map:

- it is its own inverse: the round trip sample -> image -> (the source sample nearest
  that image) -> image ends where it started (:func:`returns`);
- it turns the surface's orientation around: the order in which a sample's neighbours
  lie around it (seen along the outward normal) is reversed around its image
  (:func:`reversed_turns`).

:func:`reflection` is the share of samples at which the map does both. A rotation of
order two returns but keeps the orientation, one of higher order neither; both are left
to the edge-length test of ``trivial_weight="auto"``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["MIN_SINE", "reflection", "returns", "reversed_turns"]

#: A pair of neighbour directions counts for :func:`reversed_turns` only where the sine of
#: its angle (signed by the normal) is at least this large on both sides of the map:
#: nearly parallel directions have no reliable turn.
MIN_SINE = 0.2


#: A round trip through BP's argmax "returns" within this distance (sqrt(area) units) of
#: its start, for ``reflection_threshold`` (:func:`intrinsym.extract.reflection.returns`).
RETURN_RADIUS = 0.1


def returns(image: np.ndarray, source_points: np.ndarray, target_points: np.ndarray, radius: float) -> np.ndarray:
    """Which source samples a map returns to: ``T(T(s))`` near ``s``.

    The trip goes from sample ``s`` to target ``image[s]``, then from the source sample
    nearest that target to its image.

    Parameters
    ----------
    image : (S,) int64
        Target sample of each source sample (self-matching: both sets on one surface).
    source_points, target_points : (S, 3), (T, 3) float arrays
        Positions (length units of ``radius``).
    radius : float
        A trip ending within this (Euclidean) distance of its start returns.

    Returns
    -------
    (S,) bool
    """
    image = np.asarray(image, dtype=np.int64)
    src = np.asarray(source_points, dtype=np.float64)
    tgt = np.asarray(target_points, dtype=np.float64)
    _, back = cKDTree(src).query(tgt[image])
    return np.linalg.norm(tgt[image[back]] - src, axis=1) < radius


def _sines(a: np.ndarray, b: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Signed sine of the angle from each row of ``a`` to the same row of ``b`` about
    ``normal`` (3,); 0 where either vector is zero."""
    length = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    turn = np.cross(a, b) @ normal
    return np.divide(turn, length, out=np.zeros_like(turn), where=length > 0)


def reversed_turns(
    image: np.ndarray,
    edges: np.ndarray,
    source_points: np.ndarray,
    target_points: np.ndarray,
    source_normals: np.ndarray,
    target_normals: np.ndarray,
) -> np.ndarray:
    """Which source samples a map turns around: their neighbours' order reversed.

    For every pair of source-graph neighbours ``u, v`` of sample ``s``, the turn from
    ``u - s`` to ``v - s`` about the normal at ``s`` is compared with the turn from
    ``T(u) - T(s)`` to ``T(v) - T(s)`` about the normal at ``T(s)``. A sample counts
    as turned around when more than half of its pairs with a clear turn on both sides
    (sine at least :data:`MIN_SINE`) turn the other way; a sample with no such pair does
    not count.

    Parameters
    ----------
    image : (S,) int64
        Target sample of each source sample.
    edges : (E, 2) int
        The source graph's edges (pairs of source samples).
    source_points, target_points : (S, 3), (T, 3) float arrays
    source_normals, target_normals : (S, 3), (T, 3) float arrays
        Unit normals, oriented consistently over the surface (outward).

    Returns
    -------
    (S,) bool
    """
    image = np.asarray(image, dtype=np.int64)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    src = np.asarray(source_points, dtype=np.float64)
    tgt = np.asarray(target_points, dtype=np.float64)[image]
    src_normal = np.asarray(source_normals, dtype=np.float64)
    tgt_normal = np.asarray(target_normals, dtype=np.float64)[image]
    both = np.concatenate([edges, edges[:, ::-1]])
    both = both[np.argsort(both[:, 0], kind="stable")]
    starts = np.searchsorted(both[:, 0], np.arange(len(src) + 1))
    turned = np.zeros(len(src), dtype=bool)
    for s in range(len(src)):
        near = both[starts[s] : starts[s + 1], 1]
        i, j = np.triu_indices(len(near), 1)
        before = _sines(src[near[i]] - src[s], src[near[j]] - src[s], src_normal[s])
        after = _sines(tgt[near[i]] - tgt[s], tgt[near[j]] - tgt[s], tgt_normal[s])
        clear = (np.abs(before) >= MIN_SINE) & (np.abs(after) >= MIN_SINE)
        turned[s] = 2 * np.count_nonzero(before[clear] * after[clear] < 0) > np.count_nonzero(clear)
    return turned


def reflection(
    image: np.ndarray,
    edges: np.ndarray,
    source_points: np.ndarray,
    target_points: np.ndarray,
    source_normals: np.ndarray,
    target_normals: np.ndarray,
    radius: float,
) -> float:
    """Share of the source samples at which a self-map acts as a reflection: it returns
    them (:func:`returns`, within ``radius``) and turns them around
    (:func:`reversed_turns`). Arguments as there.

    Returns
    -------
    float in [0, 1]
    """
    back = returns(image, source_points, target_points, radius)
    turned = reversed_turns(image, edges, source_points, target_points, source_normals, target_normals)
    return float(np.mean(back & turned))
