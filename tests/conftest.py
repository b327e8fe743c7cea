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
