"""Generated shapes: their ground-truth maps are exact symmetries, labels follow them."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from intrinsym.geodesics.geodesics import mesh_edges
from intrinsym.mesh import generated as shapes


def edge_change(vertices, faces, perm):
    """Largest relative change of a mesh edge's length under a vertex map."""
    e = mesh_edges(faces)
    before = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    after = np.linalg.norm(vertices[perm[e[:, 0]]] - vertices[perm[e[:, 1]]], axis=1)
    return np.max(np.abs(after - before) / before)


def label_permutation(labels, perm):
    """The label mapping induced by a vertex map, asserting it is well defined."""
    pairs = {(int(a), int(b)) for a, b in zip(labels, labels[perm], strict=True)}
    mapping = dict(pairs)
    assert len(mapping) == len(pairs), "a vertex map splits a labelled part"
    return mapping


def check_exact(g):
    n = len(g.vertices)
    assert g.faces.min() >= 0 and g.faces.max() < n
    for perm in g.symmetries:
        assert sorted(perm.tolist()) == list(range(n))  # a permutation
        assert not np.array_equal(perm, np.arange(n))  # not the identity
        assert edge_change(g.vertices, g.faces, perm) < 1e-9  # an isometry of the mesh
        label_permutation(g.labels, perm)


def test_cuboctahedron_vertices_are_all_equivalent():
    g = shapes.cuboctahedron(2)
    check_exact(g)
    assert len(g.symmetries) == 47  # the octahedral group, 48 elements
    corners = np.flatnonzero(np.isclose(np.sort(np.abs(g.vertices), axis=1), [0, 1, 1]).all(axis=1))
    assert len(corners) == 12
    for c in corners:
        assert set(g.symmetries[:, c].tolist()) | {c} == set(corners.tolist())
        assert np.sum(g.symmetries[:, c] == c) == 3  # stabiliser of a vertex: order 4
    assert sorted(np.unique(g.labels).tolist()) == list(range(13))


@pytest.mark.parametrize("arms", [3, 5])
def test_star_arms_are_permuted(arms):
    g = shapes.star(arms, resolution=4)
    check_exact(g)
    assert len(g.symmetries) == 4 * arms - 1
    step = label_permutation(g.labels, g.symmetries[0])
    assert {step[k] for k in range(1, arms + 1)} == set(range(1, arms + 1))
    assert all(step[k] != k for k in range(1, arms + 1))  # the first map rotates by one arm
    assert step[0] == 0


def test_lantern_frames_bend_arms_differently_and_stay_near_isometric():
    a, b = shapes.lantern(resolution=4)
    assert np.array_equal(a.faces, b.faces) and a.vertices.shape == b.vertices.shape
    arm = [(a.labels == k) for k in range(1, 5)]
    moved = [np.abs(a.vertices[m] - b.vertices[m]).max() for m in arm]
    assert min(moved) > 0.1  # every arm is posed differently in the two frames
    assert np.allclose(a.vertices[a.labels == 0][:, :2], b.vertices[a.labels == 0][:, :2], atol=0.05)
    assert len(b.symmetries) == 15
    for perm in b.symmetries:
        mapping = label_permutation(a.labels, perm)
        assert sorted(mapping[k] for k in range(1, 5)) == [1, 2, 3, 4]
        # vertex i of A -> perm[i] of B: edges keep their length to a few percent
        e = mesh_edges(a.faces)
        da = np.linalg.norm(a.vertices[e[:, 0]] - a.vertices[e[:, 1]], axis=1)
        db = np.linalg.norm(b.vertices[perm[e[:, 0]]] - b.vertices[perm[e[:, 1]]], axis=1)
        assert np.median(np.abs(db - da) / da) < 0.02


def test_figure_mirror_swaps_limbs_and_is_near_isometric():
    g = shapes.figure(resolution=5)
    mirror, flip, both = g.symmetries
    assert label_permutation(g.labels, mirror) == {0: 0, 1: 2, 2: 1, 3: 4, 4: 3, 5: 5}
    assert label_permutation(g.labels, flip) == {k: k for k in range(6)}
    assert label_permutation(g.labels, both) == label_permutation(g.labels, mirror)
    assert not np.allclose(g.vertices[mirror] * [-1, 1, 1], g.vertices, atol=1e-3)  # posed: not extrinsic
    e = mesh_edges(g.faces)
    d = np.linalg.norm(g.vertices[e[:, 0]] - g.vertices[e[:, 1]], axis=1)
    dm = np.linalg.norm(g.vertices[mirror[e[:, 0]]] - g.vertices[mirror[e[:, 1]]], axis=1)
    assert np.median(np.abs(dm - d) / d) < 0.02


def test_bend_is_isometric_on_the_mid_plane():
    s = np.linspace(0.0, 2.0, 201)
    line = np.column_stack([s, np.zeros_like(s), np.zeros_like(s)])
    bent = shapes.bend(line, 0.0, 1.0, np.pi / 2, 0.5)
    steps = np.linalg.norm(np.diff(bent, axis=0), axis=1)
    assert np.allclose(steps, 0.01, rtol=1e-3)  # arc length kept
    assert np.allclose(bent[-1], [1.0 + 0.5 / (np.pi / 2), 0.0, 0.5 / (np.pi / 2) + 0.5], atol=1e-9)
    assert np.array_equal(bent[s <= 1.0], line[s <= 1.0])


def test_unknown_shape():
    with pytest.raises(ValueError, match="unknown shape"):
        shapes.generate("teapot")


def test_generate_command_writes_mesh_and_ground_truth(tmp_path):
    from intrinsym import load
    from intrinsym.app import cli

    assert cli.main(["generate", "lantern", "-o", str(tmp_path / "lan.off"), "--resolution", "4"]) == 0
    a, b = load(tmp_path / "lan.off"), load(tmp_path / "lan_b.off")
    frame_a, frame_b = shapes.lantern(resolution=4)
    assert np.allclose(a.vertices, frame_a.vertices) and np.array_equal(a.faces, frame_a.faces)
    assert np.allclose(b.vertices, frame_b.vertices)
    assert np.array_equal(np.load(tmp_path / "lan.maps.npy"), frame_a.symmetries)
    assert np.array_equal(np.load(tmp_path / "lan.sym.npy"), frame_a.symmetries[0])
    assert np.array_equal(np.load(tmp_path / "lan_b.labels.npy"), frame_b.labels)
    before = sorted(p.name for p in tmp_path.iterdir())
    assert cli.main(["generate", "star", "-o", str(tmp_path / "s.obj")]) == 2
    assert cli.main(["generate", "cuboctahedron", "-o", str(tmp_path / "c.off"), "--arms", "3"]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_partial_limbs_are_exact_rotated_copies_and_the_body_has_no_symmetry():
    g = shapes.partial(resolution=6)
    (swap,) = g.symmetries
    limbs = np.flatnonzero(g.labels > 0)
    assert np.array_equal(np.flatnonzero(swap >= 0), limbs)  # -1 exactly off the limbs
    assert np.array_equal(swap[swap[limbs]], limbs)  # an involution
    assert label_permutation(g.labels[limbs], np.searchsorted(limbs, swap[limbs])) == {1: 2, 2: 1}
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # +90 degrees about z
    one, two = g.labels == 1, g.labels == 2
    assert np.abs(g.vertices[one] @ quarter.T - g.vertices[swap[one]]).max() < 1e-12
    assert np.abs(g.vertices[two] @ quarter - g.vertices[swap[two]]).max() < 1e-12
    # the swap maps every limb triangle onto a limb triangle: an exact isometry of the limbs
    inside = (g.labels[g.faces] > 0).all(axis=1)
    mapped = {tuple(sorted(t)) for t in swap[g.faces[inside]].tolist()}
    assert mapped == {tuple(sorted(t)) for t in g.faces[inside].tolist()}
    # the body is not an extrinsic copy of itself under the rotation, the flip or a mirror
    body = g.vertices[g.labels == 0]
    tree = cKDTree(g.vertices)
    for transform in (quarter, quarter.T, np.diag([1.0, 1.0, -1.0]), np.diag([-1.0, 1.0, 1.0])):
        assert np.median(tree.query(body @ transform.T)[0]) > 0.05


def test_generate_partial_writes_a_map_with_missing_entries(tmp_path):
    from intrinsym.app import cli
    from intrinsym.evaluation import evaluate

    assert cli.main(["generate", "partial", "-o", str(tmp_path / "p.off"), "--resolution", "4"]) == 0
    sym = evaluate.load_symmetry_map(tmp_path / "p.sym.npy", len(shapes.partial(4).vertices), allow_missing=True)
    assert np.array_equal(sym, shapes.partial(4).symmetries[0]) and sym.min() == -1
