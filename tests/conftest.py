"""Shared fixtures: small generated shapes and the optional shared research data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def shared(relative: str) -> Path:
    """Path of a file of ../shared/data, skipping the test when it is absent."""
    path = DATA / relative
    if not path.exists():
        pytest.skip(f"research data not available: {path} (the shared data folder is absent)")
    return path


def mirror_shape() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A bent ellipsoid whose only symmetry is the mirror x -> -x, with its vertex map.

    Returns vertices (N,3), faces (F,3) and sym (N,) with vertex sym[i] the mirror of i.
    """
    sphere = trimesh.creation.icosphere(subdivisions=4)
    v = sphere.vertices * [0.6, 1.5, 0.5]
    v[:, 2] += 0.35 * v[:, 1] ** 2 + 0.25 * v[:, 1]
    v[:, 0] *= 1.0 + 0.3 * np.tanh(v[:, 1])
    reflected = v * [-1.0, 1.0, 1.0]
    dist, sym = cKDTree(v).query(reflected)
    assert dist.max() < 1e-9
    return v, np.asarray(sphere.faces), sym.astype(np.int64)


@pytest.fixture
def mirror():
    return mirror_shape()


def sphere_result(folder: Path) -> tuple[Path, np.ndarray]:
    """A saved self-matching result on a unit icosphere whose marginals are known.

    Every vertex is a target sample; every 16th vertex is a source sample, and its
    marginal is 1 at the target nearest its antipode and 1e-3 elsewhere. The mesh is
    written as ``folder/sphere.off`` and named in run.json.

    Returns the result directory and the (V, 3) vertices.
    """
    from intrinsym.pipeline import Params, Result

    sphere = trimesh.creation.icosphere(subdivisions=3)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    path = folder / "sphere.off"
    with open(path, "w") as fh:
        fh.write(f"OFF\n{len(v)} {len(f)} 0\n")
        np.savetxt(fh, v)
        np.savetxt(fh, np.column_stack([np.full(len(f), 3), f]), fmt="%d")
    sources = np.arange(0, len(v), 16)
    _, antipode = cKDTree(v).query(-v[sources])
    marginals = np.full((len(sources), len(v)), 1e-3, dtype=np.float32)
    marginals[np.arange(len(sources)), antipode] = 1.0
    _, nearest = cKDTree(v[sources]).query(v[sources], k=4)
    edges = np.unique(np.sort(np.column_stack([np.repeat(nearest[:, 0], 3), nearest[:, 1:].ravel()]), axis=1), axis=0)
    info = {
        "mode": "detect", "input": str(path), "preset": "default",
        "sizes": {"source": len(sources), "target": len(v), "edges": len(edges)},
        "seconds": {"bp": 0.0}, "resolved": {"scale": 1.0},
        "bp": {"iterations": 1, "converged": True, "max_change": 0.0},
    }
    out = folder / "out"
    Result(v[sources], v.copy(), sources, np.arange(len(v)), edges.astype(np.int64), marginals, marginals,
           Params(), info).save(out)
    return out, v
