"""Marginal scores on hand-computed cases, and symmetry-map formats."""

import numpy as np
import pytest

from intrinsym.errors import InputError
from intrinsym.evaluation.evaluate import load_confidence, load_symmetry_map, marginal_scores, partial_scores


def test_marginal_scores_by_hand():
    # two scored sources (d(s,g) = 0.5), one on the symmetry plane (not scored)
    marg = np.array(
        [
            [0.50, 0.30, 0.15, 0.05],  # peak at its own target 0, best away: target 1 = mirror
            [0.10, 0.10, 0.10, 0.70],  # best away: target 3, but its mirror is near target 2
            [1.00, 0.00, 0.00, 0.00],
        ]
    )
    d_source = np.array([[0.0, 0.5, 0.6, 0.9], [0.6, 0.5, 0.5, 0.3], [0.0, 0.1, 0.2, 0.3]])
    d_mirror = np.array([[0.5, 0.01, 0.4, 0.7], [0.5, 0.3, 0.02, 0.3], [0.0, 0.1, 0.2, 0.3]])
    d_decoy = np.array([[0.9, 0.9, 0.04, 0.9], [0.9, 0.9, 0.9, 0.01], [0.0, 0.1, 0.2, 0.3]])
    s = marginal_scores(marg, d_source, d_mirror, d_decoy, np.array([0.5, 0.5, 0.0]))
    assert s.n_scored == 2
    assert s.mirror_hit == 0.5  # row 0 hits, row 1 misses
    # row 0: 0.30 >= 0.25 (half max) -> recalled; row 1: 0.10 < 0.35 -> not
    assert s.peak_recall == 0.5
    # decoys: row 0 target 2 = 0.15 < 0.25; row 1 target 3 = 0.70 >= 0.35
    assert s.decoy_recall == 0.5
    # breadth: row 0 two of four targets >= 0.25, row 1 one of four
    assert s.breadth == pytest.approx((0.5 + 0.25) / 2)


def test_partial_scores_by_hand():
    # a flat 4 x 1 strip (sqrt(area) = 2, so near = 0.1 is 0.2 input units) with parts at
    # both ends (x < 0.8 and x > 3.2) that the reflection x -> 4 - x swaps
    xs, ys = np.linspace(0, 4, 41), np.linspace(0, 1, 11)
    verts = np.array([[x, y, 0.0] for x in xs for y in ys])
    at = lambda x, y: int(round(x * 10)) * 11 + int(round(y * 10))  # noqa: E731
    quads = [(at(x, y), at(x + 0.1, y), at(x + 0.1, y + 0.1), at(x, y + 0.1)) for x in xs[:-1] for y in ys[:-1]]
    faces = np.array([f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))])
    labels = np.where(verts[:, 0] < 0.75, 1, np.where(verts[:, 0] > 3.25, 2, 0))
    mirror = np.array([at(4 - x, y) for x, y, _ in verts])
    sources = [at(0.3, 0.5), at(0.5, 0.5), at(2.0, 0.5), at(2.5, 0.5), at(0.9, 0.5)]
    marg = np.zeros((5, len(verts)))
    marg[0, at(3.7, 0.5)] = 1.0  # on its true image: hit, all mass there
    marg[1, at(1.5, 0.5)], marg[1, at(3.5, 0.5)] = 0.6, 0.4  # argmax on the body: miss
    marg[2, at(0.5, 0.2)] = 1.0  # off the parts, all mass on one place: an invented symmetry
    marg[3, at(1.0, 0.5)], marg[3, at(3.0, 0.5)] = 0.5, 0.5  # off, split between two places
    marg[4, at(3.1, 0.5)] = 1.0  # 0.1 input units from part 1: scored as neither
    p = partial_scores(verts, faces, labels, mirror, marg, np.array(sources), np.arange(len(verts)))
    assert p.limb_hit == 0.5
    assert p.limb_mass.tolist() == pytest.approx([1.0, 0.6])
    assert p.off_mass.tolist() == pytest.approx([1.0, 0.5])


def test_symmetry_map_formats(tmp_path):
    truth = np.array([2, 1, 0, 3])
    (tmp_path / "a.sym").write_text("".join(f"{i + 1}\n" for i in truth))
    (tmp_path / "sym.txt").write_text("  ".join(f"{i + 1:e}" for i in truth))
    np.save(tmp_path / "c.npy", truth)
    for name in ("a.sym", "sym.txt", "c.npy"):
        assert load_symmetry_map(tmp_path / name, 4).tolist() == truth.tolist()


@pytest.mark.parametrize(
    "text,n,match",
    [
        ("", None, "empty"),
        ("1\nx\n", None, "cannot read"),
        ("1.5\n2\n", None, "non-integer"),
        ("1\n5\n", None, "out of range"),
        ("1\n2\n", 3, "2 entries"),
    ],
)
def test_symmetry_map_errors(tmp_path, text, n, match):
    path = tmp_path / "bad.sym"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as err:
        load_symmetry_map(path, n)
    assert "bad.sym" in str(err.value) and "\n" not in str(err.value)


# --------------------------------------------------------------------------- map scores

import scipy.sparse as sp  # noqa: E402
import trimesh  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from intrinsym.evaluation.evaluate import (  # noqa: E402
    correspondence_curve,
    evaluation_report,
    load_labels,
    map_errors,
    plot_curve,
    score_map,
    segmentation_scores,
)
from intrinsym.mesh.shape import from_arrays  # noqa: E402


def path_graph(n=5, step=0.1):
    """Vertices 0..n-1 on a line, step apart: geodesic d(i, j) = step |i - j|."""
    i = np.arange(n - 1)
    g = sp.coo_matrix((np.full(n - 1, step), (i, i + 1)), shape=(n, n))
    return (g + g.T).tocsr()


def test_map_errors_and_curve_by_hand():
    g = path_graph()
    truth = np.array([4, 3, 2, 1, 0])
    err = map_errors(np.array([3, 3, -1, 0, 0]), truth, g)
    assert np.allclose(err[[0, 1, 3, 4]], [0.1, 0.0, 0.1, 0.0]) and np.isinf(err[2])
    # thresholds 0, 0.05, 0.1: two exact, none more within 0.05, two more within 0.1
    assert correspondence_curve(err, np.array([0.0, 0.05, 0.1 + 1e-12])).tolist() == [0.4, 0.4, 0.8]


def test_segmentation_score_by_hand():
    labels = np.array([1, 1, 0, 2, 2])
    truth = np.array([4, 3, 2, 1, 0])  # part 1 <-> part 2
    predicted = np.array([4, 2, -1, 1, 0])
    # part 1: R = {v : pred(v) in part 2} = {0}, G = {0, 1}: 1/2
    # part 2: R = {3, 4} = G: 1
    assert segmentation_scores(predicted, truth, labels) == {1: 0.5, 2: 1.0}
    # a map that sends all five vertices into part 2: R & G = {0, 1}, R | G = all five
    assert segmentation_scores(np.array([3, 4, 3, 4, 3]), truth, labels)[1] == 0.4


def test_score_map_on_the_mirror_shape(mirror, tmp_path):
    v, f, sym = mirror
    shape = from_arrays(v, f)
    sides = (v[:, 0] > 0.2).astype(int) + 2 * (v[:, 0] < -0.2)
    assert segmentation_scores(sym, sym, sides) == {1: 1.0, 2: 1.0}
    # the true map on every 10th vertex (one Dijkstra per distinct predicted vertex)
    exact = score_map(np.where(np.arange(len(v)) % 10 == 0, sym, -1), shape, sym, labels=sides)
    assert exact.fraction[0] == pytest.approx(exact.coverage) and exact.mean_error == 0.0
    assert exact.coverage == pytest.approx(0.1, abs=0.01)
    assert set(exact.segmentation) == {1, 2}
    # the identity is right only on the mirror plane; 9 in 10 vertices have no prediction
    some = np.where(np.arange(len(v)) % 10 == 0, np.arange(len(v)), -1)
    s = score_map(some, shape, sym)
    assert s.coverage == pytest.approx(0.1, abs=0.01)
    assert s.within(0.25) <= 0.1 and s.within(0.0) < 0.02
    assert s.mean_error > 0.1
    report = s.as_dict()
    assert set(report) >= {"within_0.05", "within_0.10", "mean_error", "curve"}
    plot_curve(s, tmp_path / "curve.png")
    assert (tmp_path / "curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_correspondence_curve_weighted_by_hand():
    errors = np.array([0.0, 0.02, 0.2, np.inf])
    assert correspondence_curve(errors, np.array([0.0, 0.05, 0.5])).tolist() == [0.25, 0.5, 0.75]
    weighted = correspondence_curve(errors, np.array([0.0, 0.05, 0.5]), np.array([1.0, 2.0, 3.0, 4.0]))
    np.testing.assert_allclose(weighted, [0.1, 0.3, 0.6])


def test_score_map_by_area_does_not_depend_on_where_the_mesh_is_dense(mirror):
    # right on the half x >= 0 only, the mirror image of the half x <= 0: a half of the
    # area; split every triangle of that half in four, and a larger share of the vertices
    v, f, sym = mirror
    right = np.where(v[:, 0] >= -1e-9, sym, np.arange(len(v)))
    coarse = score_map(right, from_arrays(v, f), sym)
    assert coarse.within(0.0, by_area=True) == pytest.approx(0.5, abs=0.02)
    mesh = trimesh.Trimesh(v, f, process=False)
    positive = np.flatnonzero(v[f].mean(axis=1)[:, 0] > 0)
    vs, fs, index = trimesh.remesh.subdivide(mesh.vertices, mesh.faces, face_index=positive, return_index=True)
    fine_v, fine_f = np.asarray(vs), np.asarray(fs)
    assert np.array_equal(fine_v[: len(v)], v)
    fine_sym = cKDTree(fine_v).query(fine_v * [-1.0, 1.0, 1.0])[1]
    # the new vertices lie on the half x > 0 (midpoints of its triangles' edges): mapped right
    fine_right = np.where(fine_v[:, 0] >= -1e-9, fine_sym, np.arange(len(fine_v)))
    fine_right[: len(v)] = right
    fine = score_map(fine_right, from_arrays(fine_v, fine_f), fine_sym)
    assert fine.within(0.0) > coarse.within(0.0) + 0.2
    assert fine.within(0.0, by_area=True) == pytest.approx(coarse.within(0.0, by_area=True), abs=0.02)
    assert set(fine.as_dict()) >= {"area_within_0.05", "area_within_0.10"}


def test_labels_and_missing_entries(tmp_path):
    (tmp_path / "l.txt").write_text("0\n1\n2\n")
    assert load_labels(tmp_path / "l.txt", 3).tolist() == [0, 1, 2]
    with pytest.raises(InputError, match="3 labels"):
        load_labels(tmp_path / "l.txt", 4)
    np.save(tmp_path / "m.npy", np.array([1, -1, 0]))
    assert load_symmetry_map(tmp_path / "m.npy", 3, allow_missing=True).tolist() == [1, -1, 0]
    with pytest.raises(InputError, match="out of range"):
        load_symmetry_map(tmp_path / "m.npy", 3)


def test_partial_ground_truth_scores_only_vertices_with_an_image(mirror):
    from intrinsym.evaluation.evaluate import score_marginals

    v, f, sym = mirror
    shape = from_arrays(v, f)
    part = np.abs(v[:, 0]) > 0.2
    partial = np.where(part, sym, -1)
    s = score_map(np.arange(len(v)), shape, partial)  # the identity: wrong wherever scored
    assert s.n_vertices == part.sum() and s.within(0.0) == 0.0
    assert score_map(sym, shape, partial).within(0.0) == 1.0
    src = np.flatnonzero(part)[:5]
    off = np.flatnonzero(~part)[:3]
    tgt = np.arange(0, len(v), 7)
    marg = np.full((8, len(tgt)), 1e-3)
    best = [np.argmin(np.linalg.norm(v[tgt] - v[sym[s]], axis=1)) for s in src]
    marg[np.arange(5), best] = 1.0
    scores = score_marginals(marg, np.concatenate([src, off]), tgt, shape, partial)
    assert scores.n_scored == 5 and scores.mirror_hit == 1.0


def test_extrinsic_mirror_finds_the_reflection_of_a_moved_shuffled_shape(mirror):
    from intrinsym.evaluation.evaluate import extrinsic_mirror

    v, f, sym = mirror
    rng = np.random.default_rng(5)
    order = rng.permutation(len(v))
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    moved = 1000.0 * v[order] @ rot.T + [3.0, -7.0, 2.0]  # millimetres, anywhere
    found, residual = extrinsic_mirror(moved)
    inverse = np.argsort(order)
    assert np.array_equal(found, inverse[sym[order]])
    assert residual.max() < 1e-6 * 1000.0


def test_load_confidence(tmp_path):
    np.save(tmp_path / "ok.npy", np.array([0.0, 0.5, 1.0], dtype=np.float32))
    assert load_confidence(tmp_path / "ok.npy", 3).tolist() == [0.0, 0.5, 1.0]
    np.save(tmp_path / "big.npy", np.array([0.0, 1.5, 1.0]))
    np.save(tmp_path / "nan.npy", np.array([0.0, np.nan, 1.0]))
    (tmp_path / "junk.npy").write_text("junk")
    for name, n, match in [
        ("ok.npy", 4, "3 confidences, the mesh has 4 vertices"),
        ("big.npy", 3, r"must lie in \[0, 1\]"),
        ("nan.npy", 3, r"must lie in \[0, 1\]"),
        ("junk.npy", 3, "cannot read a confidence"),
        ("missing.npy", 3, "cannot read a confidence"),
    ]:
        with pytest.raises(InputError, match=match) as err:
            load_confidence(tmp_path / name, n)
        assert name in str(err.value)


def test_evaluation_report_scores_the_confidence_on_the_vertices_with_a_true_image():
    # the bent ellipsoid at 642 vertices: the report solves the map's distortion and errors
    # twice, 1.5 s on the fixture's 2,562; here the identity's share within 0.05 on the
    # plane side is 0.18, not 0.150 (next to its confidence 0.15: an error near 0)
    from conftest import mirror_shape

    v, f, sym = mirror_shape(subdivisions=3)
    shape = from_arrays(v, f)
    # the true map on the vertices x > 0 and the identity elsewhere (right only on the
    # mirror plane); a vertex without a true image is not scored
    right = v[:, 0] > 0
    predicted = np.where(right, sym, np.arange(len(v)))
    truth = sym.copy()
    truth[0] = -1
    conf = np.where(right, 0.95, 0.15)
    args = (np.ones((3, len(v))), np.arange(3), np.arange(len(v)), predicted, shape, truth)
    report, scores = evaluation_report(*args, confidence=conf)
    c = report["confidence"]
    assert c["confidence"] == pytest.approx(conf[1:].mean())
    assert c["within"] == pytest.approx(report["map"]["within_0.05"])
    low = scores.errors[~right[1:]] <= 0.05  # the identity's hits on the plane
    expected = right[1:].mean() * 0.05 + (~right[1:]).mean() * abs(low.mean() - 0.15)
    assert c["expected_calibration_error"] == pytest.approx(expected)
    assert 0 < low.mean() < 0.5 and "confidence" not in evaluation_report(*args)[0]
