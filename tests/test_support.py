"""The extraction support's arrays (``result.npz``) and the ``symmetries.json`` records."""

import dataclasses
import json

import numpy as np
import pytest

from intrinsym.extract.records import cut_to_map, part_vertices, records
from intrinsym.extract.support import SourceGraph, Support
from intrinsym.extract.symmetry import Symmetry
from intrinsym.geodesics.geodesics import SparseDistances


def line_support(self_match: bool = True) -> Support:
    """Four samples on a line 0.1 apart (a path graph), one input vertex per sample
    plus one outside every cell; all pairwise geodesics kept."""
    x = 0.1 * np.arange(4)
    d = np.abs(x[:, None] - x[None])
    rows = [np.argsort(d[i], kind="stable") for i in range(4)]
    dist = np.concatenate([d[i, r] for i, r in enumerate(rows)])
    targets = SparseDistances(np.arange(5) * 4, np.concatenate(rows), dist, 0.3)
    cells = np.array([0, 1, 2, 3, -1])
    vertices = np.column_stack([np.r_[x, 1.0], np.zeros(5), np.zeros(5)])
    return Support(
        np.full(3, 0.1), targets, cells, cells, self_match, vertices, vertices if self_match else 2.0 * vertices
    )


def assert_same(a: Support, b: Support) -> None:
    for name in ("edge_length", "vertex_source", "vertex_target"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    for name in ("indptr", "indices", "dist"):
        assert np.array_equal(getattr(a.targets, name), getattr(b.targets, name))
    assert a.targets.radius == b.targets.radius and a.self_match == b.self_match
    for name in ("source_mesh_vertices", "target_mesh_vertices"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None and y is None) or np.array_equal(x, y)


@pytest.mark.parametrize("self_match", [True, False])
def test_support_round_trip(self_match, tmp_path):
    support = line_support(self_match)
    arrays = support.to_arrays()
    assert set(arrays) == set(Support.KEYS) | ({"source_mesh_vertices"} if self_match else set(Support.OPTIONAL_KEYS))
    assert Support.stored_in(arrays) and not Support.stored_in({"edge_length": 0})
    assert_same(Support.from_arrays(arrays), support)
    # through a file, read straight from the open npz
    np.savez_compressed(tmp_path / "r.npz", other=np.zeros(2), **arrays)
    with np.load(tmp_path / "r.npz") as z:
        assert Support.stored_in(z.files)
        assert_same(Support.from_arrays(z), support)


def test_support_without_mesh_vertices():
    support = dataclasses.replace(line_support(), source_mesh_vertices=None, target_mesh_vertices=None)
    arrays = support.to_arrays()
    assert set(arrays) == set(Support.KEYS)
    back = Support.from_arrays(arrays)
    assert back.source_mesh_vertices is None and back.target_mesh_vertices is None


@pytest.mark.parametrize("self_match", [True, False])
def test_support_reads_the_version_1_keys(self_match):
    support = line_support(self_match)
    old = {Support.OLD_KEYS.get(k, k): v for k, v in support.to_arrays().items()}
    assert "source_vertices" in old and "source_mesh_vertices" not in old
    assert_same(Support.from_arrays(old), support)


def test_source_graph_from_edges():
    graph = SourceGraph.from_edges(np.array([[1, 2], [0, 1]]), np.array([0.2, 0.1]), 4)
    assert graph.ptr.tolist() == [0, 1, 3, 4, 4]
    assert graph.neighbour.tolist() == [1, 0, 2, 1]
    assert graph.length.tolist() == [0.1, 0.1, 0.2, 0.2]


def test_records_list_input_vertices():
    support = line_support()
    source_vertex = target_vertex = np.arange(4)
    sym = Symmetry(np.array([0, 1]), np.array([3, 2]), 0.25, 1.0, "partial")
    (record,) = records([sym], source_vertex, target_vertex, support)
    assert list(record) == ["kind", "score", "consistency", "source_vertex_index", "target_vertex_index", "pairs"]
    assert record["source_vertex_index"] == [0, 1]
    # image samples 2 and 3, dilated by half the median edge (0.05): no neighbour within
    assert record["target_vertex_index"] == [2, 3]
    assert record["pairs"] == [[0, 3], [1, 2]]
    assert record["kind"] == "partial" and record["score"] == 0.25 and record["consistency"] == 1.0
    json.dumps(record)


@pytest.mark.parametrize("one_mesh", [True, False])
def test_a_global_entry_cut_to_where_its_map_acts(one_mesh):
    """Vertices 1 and 4 have no image: they leave the source part, and on one mesh the
    image part too (there they are nobody's partner); the pairs stay."""
    record = {"source_vertex_index": [0, 1, 2, 4], "target_vertex_index": [1, 3, 4, 5], "pairs": [[0, 5]]}
    cut_to_map(record, np.array([5, -1, 3, 2, -1, 0]), one_mesh)
    assert record["source_vertex_index"] == [0, 2]
    assert record["target_vertex_index"] == ([3, 5] if one_mesh else [1, 3, 4, 5])
    assert record["pairs"] == [[0, 5]]
    json.dumps(record)


def test_part_vertices_reads_both_key_names():
    new = {"source_vertex_index": [0, 1], "target_vertex_index": [3]}
    old = {"source_vertices": [0, 1], "target_vertices": [3]}
    for record in (new, old):
        part, image = part_vertices(record)
        assert part.dtype == np.int64 and part.tolist() == [0, 1] and image.tolist() == [3]
    with pytest.raises(KeyError):
        part_vertices({"pairs": []})
