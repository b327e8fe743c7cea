"""The partial-symmetry protocol: truth from true and mirror points, its scores, the
SHREC'16 reader, checked by hand on small meshes and on the research data."""

import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import shared
from intrinsym.errors import InputError
from intrinsym.evaluation import partial_truth
from intrinsym.evaluation.partial_truth import NO_PARTNER, NOT_SCORED, PartialTruth
from intrinsym.mesh.shape import Shape

# A strip of unit squares along x, two triangles each: vertices (i, 0, 0) = i and (i, 1, 0) = 5 + i.
_XS = np.arange(5.0)
STRIP_V = np.concatenate(
    [np.column_stack([_XS, np.zeros(5), np.zeros(5)]), np.column_stack([_XS, np.ones(5), _XS * 0])]
)
STRIP_F = np.array([[i, i + 1, 6 + i] for i in range(4)] + [[i, 6 + i, 5 + i] for i in range(4)], dtype=np.int64)


def test_partner_truth_classifies_by_the_mirror_distance():
    points = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0]])
    # 0 <-> 3 mirror exactly; 1's mirror lies 0.01 from 2 (partnered, <= 0.02), 2's lies
    # 0.03 from 1 (between: not scored), 3's lies 0.5 from everything (no partner)
    mirror = np.array([[3.0, 0, 0], [2.01, 0, 0], [1.0, 0.03, 0], [3.5, 0.5, 0]])
    truth = partial_truth.partner_truth(points, mirror, unit=1.0)
    assert truth.partner.tolist() == [3, 2, NOT_SCORED, NO_PARTNER]
    np.testing.assert_allclose(truth.distance[:3], [0.0, 0.01, 0.03])
    # the unit scales every distance: 3's 0.707 is 0.035 at unit 20 (not scored), 0.007 at unit 100
    assert partial_truth.partner_truth(points, mirror, unit=20.0).partner.tolist() == [3, 2, 1, NOT_SCORED]
    assert partial_truth.partner_truth(points, mirror, unit=100.0).partner.tolist() == [3, 2, 1, 3]


def test_score_partial_by_hand_on_a_strip():
    shape = Shape(STRIP_V, STRIP_F)
    # truth: bottom row i <-> 4 - i (mirror about x = 2), top row no partner, 7 not scored
    partner = np.array([4, 3, 2, 1, 0, NO_PARTNER, NO_PARTNER, NOT_SCORED, NO_PARTNER, NO_PARTNER])
    truth = PartialTruth(partner, np.zeros(10), unit=10.0)  # lengths: edges 0.1, diagonals 0.1414
    predicted = np.array([4, 2, 2, 1, -1, -1, 5, 9, -1, 8])
    s = partial_truth.score_partial(predicted, shape, truth)
    # errors on the bottom row: 0, 0.1 (3 -> 2), 0, 0, inf (unmapped)
    np.testing.assert_allclose(s.errors, [0.0, 0.1, 0.0, 0.0, np.inf])
    assert s.partnered_within_005 == pytest.approx(3 / 5)
    assert s.partnered_within_010 == pytest.approx(4 / 5)
    assert s.unpartnered_unmapped == pytest.approx(2 / 4)  # 5 and 8 unmapped, 6 and 9 mapped; 7 not scored
    assert s.balanced == pytest.approx((3 / 5 + 2 / 4) / 2)
    assert s.mean_error == pytest.approx(0.1 / 4)
    assert (s.n_partnered, s.n_unpartnered) == (5, 4)
    # the truth itself scores 1; "no partner anywhere" scores the unpartnered share alone
    assert partial_truth.score_partial(np.where(partner >= 0, partner, -1), shape, truth).balanced == 1.0
    nothing = partial_truth.score_partial(np.full(10, -1), shape, truth)
    assert (nothing.partnered_within_005, nothing.unpartnered_unmapped, nothing.balanced) == (0.0, 1.0, 0.5)
    with pytest.raises(InputError, match="10"):
        partial_truth.score_partial(predicted[:5], shape, truth)


def test_part_iou_ignores_the_unscored_vertices():
    partner = np.array([1, 0, NO_PARTNER, NOT_SCORED, 5, 4])
    truth = PartialTruth(partner, np.zeros(6), 1.0)
    parts = np.array([True, True, True, True, False, False])
    assert partial_truth.part_iou(parts, truth) == pytest.approx(2 / 5)  # {0, 1} of {0, 1, 2, 4, 5}


def test_load_barycentric_places_points_on_the_reference(tmp_path):
    reference = Shape(STRIP_V, STRIP_F, "strip.off")
    path = tmp_path / "x.baryc_gt"
    path.write_text("1 1 0 0\n5 0.25 0.25 0.5\n")
    points = partial_truth.load_barycentric(path, reference, 2)
    # triangle 1 is (0, 1, 6): its first corner; triangle 5 is (0, 6, 5)
    np.testing.assert_allclose(points, [STRIP_V[0], 0.25 * STRIP_V[0] + 0.25 * STRIP_V[6] + 0.5 * STRIP_V[5]])
    with pytest.raises(InputError, match="expected 3 rows"):
        partial_truth.load_barycentric(path, reference, 3)
    path.write_text("9 1 0 0\n1 1 0 0\n")
    with pytest.raises(InputError, match="out of range"):
        partial_truth.load_barycentric(path, reference, 2)


def test_null_shape_path_and_bad_names(tmp_path):
    found = partial_truth.null_shape_path(tmp_path / "cuts" / "cuts_dog_shape_6.off")
    assert found == tmp_path / "null" / "dog.off"
    with pytest.raises(InputError, match="SHREC'16"):
        partial_truth.null_shape_path("dog.off")


def test_shrec16_truth_on_the_data():
    both = shared("shrec16_partial/cuts/cuts_dog_shape_2.off")
    shape, truth = partial_truth.load_shrec16(both)
    assert len(truth.partner) == len(shape.vertices) == 3875
    assert truth.partnered.mean() == 1.0  # this cut kept both sides
    # the mirror of the mirror is the point itself: nearest-vertex partners are mutual up
    # to the mesh's resolution (0.897 exactly mutual here)
    mutual = truth.partner[truth.partner] == np.arange(len(truth.partner))
    assert mutual.mean() > 0.85
    _, one_side = partial_truth.load_shrec16(shared("shrec16_partial/cuts/cuts_cat_shape_1.off"))
    assert 0.1 < one_side.partnered.mean() < 0.2 and one_side.unpartnered.mean() > 0.6
    assert one_side.unit == truth.unit or one_side.unit > 0


@pytest.mark.slow  # a detect of a real scan in its own process (CI: -m slow)
def test_evaluate_scores_a_shrec16_truth(tmp_path):
    mesh = shared("shrec16_partial/cuts/cuts_horse_shape_15.off")
    out = tmp_path / "out"
    run = [sys.executable, "-m", "intrinsym"]
    detect = [*run, "detect", str(mesh), "-o", str(out), "--source", "60", "--target", "600", "-q"]
    subprocess.run(detect, check=True, capture_output=True)
    truth = mesh.with_suffix(".baryc_gt_sym")
    done = subprocess.run([*run, "evaluate", str(out), "--symmetry-map", str(truth)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "partial symmetry" in done.stdout
    partial = json.loads((out / "scores.json").read_text())["partial"]
    shape, expected = partial_truth.load_shrec16(mesh)
    found = partial_truth.score_partial(np.load(out / "symmetry_map.npy"), shape, expected)
    assert partial["balanced"] == pytest.approx(found.balanced, nan_ok=True)
    assert partial["n_partnered"] == expected.partnered.sum()
    assert partial["unit"] == pytest.approx(expected.unit)
    bad = subprocess.run(
        [*run, "evaluate", str(out), "--symmetry-map", str(truth), "--reference", str(mesh.with_suffix(".baryc_gt"))],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
