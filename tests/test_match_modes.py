"""Matching a part to its whole in one unit, and the two answers of a symmetric pair."""

from __future__ import annotations

import json

import numpy as np
import pytest

import intrinsym
from intrinsym import modes, pipeline, shapes
from intrinsym.shape import from_arrays, surface_area
from intrinsym.surface import prepare_pair, sample


def _cut(shape: shapes.GeneratedShape, z: float) -> tuple[intrinsym.Shape, np.ndarray]:
    """The faces of ``shape`` above height ``z``, and the original index of each kept vertex."""
    keep = shape.vertices[:, 2] > z
    faces = shape.faces[keep[shape.faces].all(axis=1)]
    used = np.unique(faces)
    new = np.full(len(shape.vertices), -1)
    new[used] = np.arange(len(used))
    return from_arrays(shape.vertices[used], new[faces]), used


@pytest.fixture(scope="module")
def half_and_whole() -> tuple[intrinsym.Shape, intrinsym.Shape, np.ndarray]:
    whole = shapes.partial(6)
    half, used = _cut(whole, -0.1)
    return half, from_arrays(whole.vertices, whole.faces), used


def test_larger_scale_keeps_the_parts_size(half_and_whole):
    half, whole, _ = half_and_whole
    ratio = surface_area(half) / surface_area(whole)
    a, b = prepare_pair(half, whole, 0, "larger")
    assert a.scale == pytest.approx(b.scale)
    assert surface_area(b.shape) == pytest.approx(1.0)
    assert surface_area(a.shape) == pytest.approx(ratio)
    assert a.graph.max() == pytest.approx(b.graph.max(), rel=0.5)  # edges of one mesh, one unit
    a, b = prepare_pair(half, whole, 0, "each")
    assert surface_area(a.shape) == pytest.approx(1.0) and surface_area(b.shape) == pytest.approx(1.0)


def test_a_half_finds_its_place_on_the_whole_only_in_a_common_unit(half_and_whole):
    """The unary of match(half, whole): each half sample's best target lies within 0.1
    of its own point on most samples in the common unit, on few when the half is blown
    up to unit area."""
    half, whole, used = half_and_whole
    unit = np.sqrt(surface_area(whole))
    right = {}
    for scale in ("larger", "each"):
        p = intrinsym.make_params(n_source=30, n_target=300, unary="spin", match_scale=scale)
        src, tgt = prepare_pair(half, whole, 0, scale)
        ps, pt = sample(src, p.n_source, None, 1), sample(tgt, p.n_target, None, 0)
        phi, *_ = pipeline.unary_model(src, tgt, ps, pt, p, False, 0.05)
        best = tgt.to_input(tgt.shape.vertices[pt[phi.argmax(axis=1)]])
        true = whole.vertices[used[src.nearest_input_vertex(src.shape.vertices[ps])]]
        right[scale] = np.mean(np.linalg.norm(best - true, axis=1) / unit <= 0.1)
    assert right["larger"] >= 0.6
    assert right["each"] <= 0.3


def test_a_symmetric_pair_reports_both_answers(tmp_path):
    figure = shapes.figure(6)
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    a, b = from_arrays(figure.vertices, figure.faces), from_arrays(figure.vertices @ turn.T, figure.faces)
    result = intrinsym.match(a, b, intrinsym.make_params(n_source=50, n_target=500))
    two = modes.two_modes(result)
    assert two.both
    assert 0.3 <= two.confidence[0] <= 0.7 and two.confidence.sum() == pytest.approx(1.0)
    unit = np.sqrt(surface_area(a))
    answers = [np.arange(len(figure.vertices)), *figure.symmetries]

    def right(vmap: np.ndarray) -> np.ndarray:
        return np.array(
            [np.mean(np.linalg.norm(a.vertices[vmap] - a.vertices[t], axis=1) / unit <= 0.1) for t in answers]
        )

    first, second = right(two.maps[0]), right(two.maps[1])
    assert first.max() >= 0.7 and second.max() >= 0.7
    assert first.argmax() != second.argmax()
    assert np.array_equal(two.maps[0], result.symmetry_map())
    out = result.save(tmp_path / "out")
    assert np.array_equal(np.load(out / "mode_maps.npy"), two.maps)
    assert json.loads((out / "modes.json").read_text()) == two.as_dict()
