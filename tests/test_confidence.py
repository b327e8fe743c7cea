"""The calibrated per-vertex confidence: its table and interpolation."""

import numpy as np
import pytest

from intrinsym.globalmap import confidence


@pytest.mark.parametrize("group", range(len(confidence.DISTORTION_BINS) + 1))
def test_calibration_table_is_a_non_decreasing_probability(group):
    assert len(confidence.CALIBRATION) == len(confidence.DISTORTION_BINS) + 1
    table = np.asarray(confidence.CALIBRATION[group])
    assert table.shape == (20,)
    assert 0 <= table.min() and table.max() <= 1
    assert np.all(np.diff(table) >= 0)


def test_distortion_group_by_hand():
    lo, hi = confidence.DISTORTION_BINS
    d = np.array([0.0, lo / 2, lo, (lo + hi) / 2, hi, 2 * hi, np.nan])
    assert confidence.distortion_group(d, len(d)).tolist() == [0, 0, 1, 1, 2, 2, 2]
    assert confidence.distortion_group(None, 3).tolist() == [0, 0, 0]


def test_calibrated_takes_the_table_of_the_distortion_bin():
    centres = (np.arange(20) + 0.5) / 20
    lo, hi = confidence.DISTORTION_BINS
    d = np.array([lo / 2, (lo + hi) / 2, 2 * hi, np.nan] * 5)
    tables = np.asarray(confidence.CALIBRATION)
    want = tables[[0, 1, 2, 2] * 5, np.arange(20)]
    assert confidence.calibrated(centres, d) == pytest.approx(want, abs=1e-6)
    assert confidence.calibrated(centres, np.zeros(20)) == pytest.approx(confidence.calibrated(centres))


def test_calibrated_interpolates_between_bin_centres():
    table = np.asarray(confidence.CALIBRATION[0])
    centres = (np.arange(20) + 0.5) / 20
    assert confidence.calibrated(centres) == pytest.approx(table, abs=1e-6)
    mid = confidence.calibrated(np.array([0.05]))[0]  # halfway between the first two centres
    assert mid == pytest.approx((table[0] + table[1]) / 2, abs=1e-6)
    ends = confidence.calibrated(np.array([0.0, 1.0]))
    assert ends == pytest.approx([table[0], table[-1]], abs=1e-6)
    assert confidence.calibrated(np.zeros(3)).dtype == np.float32


def test_disagreement_by_hand():
    vertices = np.array([[0.0, 0, 0], [3, 0, 0], [0, 4, 0]])
    apart = confidence.disagreement(vertices, np.array([1, 2, 0, -1]), np.array([2, 2, -1, 0]), scale=2.0)
    assert apart[:2] == pytest.approx([2.5, 0.0])  # |(3,0,0) - (0,4,0)| / 2
    assert np.isnan(apart[2:]).all()  # no image under one of the maps


def test_score_weighs_the_mass_by_agreement():
    r = confidence.DISAGREEMENT_RANGE
    mass = np.array([0.8, 0.8, 0.8, 0.8, 0.5])
    apart = np.array([0.0, r / 4, r, 2 * r, np.nan])
    assert confidence.score(mass, apart) == pytest.approx([0.8, 0.6, 0.0, 0.0, 0.5])


def test_round_trip_by_hand():
    # four vertices on a line, the reflection x -> -x: every trip returns
    vertices = np.array([[-3.0, 0, 0], [-1, 0, 0], [1, 0, 0], [3, 0, 0]])
    mirror = np.array([3, 2, 1, 0])
    assert confidence.round_trip(vertices, mirror, scale=1.0) == pytest.approx(np.zeros(4))
    # vertex 0 sent to vertex 2 instead: its trip ends at vertex 1 (2 away), and the trip
    # of vertex 3, whose image is vertex 0, at vertex 2 (2 away)
    wrong = np.array([2, 2, 1, 0])
    trip = confidence.round_trip(vertices, wrong, scale=10.0)
    assert trip == pytest.approx([0.2, 0.0, 0.0, 0.2])
    # no image: no trip
    assert np.isnan(confidence.round_trip(vertices, np.array([-1, 2, 1, 0]), scale=1.0)[[0, 3]]).all()


def test_round_trip_ignores_a_rotation_of_order_three():
    angle = 2 * np.pi * np.arange(30) / 30
    vertices = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(30)])
    third = (np.arange(30) + 10) % 30  # twice: a rotation by 240 degrees, no vertex returns
    assert np.isnan(confidence.round_trip(vertices, third, scale=1.0)).all()
    # a reflection of the same vertices returns every one
    assert confidence.round_trip(vertices, (30 - np.arange(30)) % 30, scale=1.0) == pytest.approx(np.zeros(30))


def test_score_weighs_the_mass_by_the_round_trip():
    r = confidence.DISAGREEMENT_RANGE
    mass = np.full(4, 0.8)
    apart = np.array([0.0, r / 4, 0.0, np.nan])
    trip = np.array([r / 2, r / 4, np.nan, 2 * r])
    assert confidence.score(mass, apart, trip) == pytest.approx([0.4, 0.45, 0.8, 0.0])


def test_carried_confidence_is_that_of_the_nearest_vertex_in_a_cell():
    positions = np.array([[0.0, 0, 0], [1, 0, 0], [0.1, 0, 0], [0.9, 0, 0], [5, 0, 0]])
    conf = np.array([0.9, 0.4, 0.0, 0.0, 0.0], dtype=np.float32)
    owner = np.array([0, 1, -1, -1, -1])
    np.testing.assert_array_equal(
        confidence.carried_confidence(conf, owner, positions), np.array([0.9, 0.4, 0.9, 0.4, 0.4], dtype=np.float32)
    )
    # every vertex in a cell, or none: unchanged
    np.testing.assert_array_equal(confidence.carried_confidence(conf, np.zeros(5, int), positions), conf)
    np.testing.assert_array_equal(confidence.carried_confidence(conf, np.full(5, -1), positions), conf)


def test_calibration_by_hand():
    # bin 0.2-0.3: confidences 0.25, 0.25, right 1 of 2 (gap 0.25); bin 0.9-1.0: 0.9 and
    # 1.0 (the last bin holds 1), both right (gap 0.05); shares 1/2 each
    ece, bins = confidence.calibration(np.array([0.25, 0.25, 0.9, 1.0]), np.array([True, False, True, True]))
    assert ece == pytest.approx(0.5 * 0.25 + 0.5 * 0.05)
    assert len(bins) == 10 and bins[2].share == 0.5 and bins[2].accuracy == 0.5
    assert bins[9].confidence == pytest.approx(0.95) and bins[9].accuracy == 1.0
    assert np.isnan(bins[0].confidence) and bins[0].share == 0.0
    # a confidence that is the right share in each bin is calibrated
    assert confidence.calibration(np.full(4, 0.75), np.array([True, True, True, False]))[0] == pytest.approx(0.0)


def test_calibration_error_adds_the_gaps_of_over_and_under_confident_bins():
    """The ECE sums each bin's absolute gap, so that an over-confident bin cannot cancel
    an under-confident one. By hand: confidences 0.25, 0.25 both right (bin 0.2-0.3,
    accuracy 1, gap +0.75) and 0.75, 0.75 both wrong (bin 0.7-0.8, accuracy 0, gap
    -0.75), half of the items each: ECE = 0.5 x 0.75 + 0.5 x 0.75 = 0.75, where the
    signed gaps sum to 0 (and the mean confidence, 0.5, is the share right)."""
    conf = np.array([0.25, 0.25, 0.75, 0.75])
    ece, bins = confidence.calibration(conf, np.array([True, True, False, False]))
    assert (bins[2].accuracy, bins[7].accuracy) == (1.0, 0.0) and bins[2].share == bins[7].share == 0.5
    assert ece == pytest.approx(0.75)
    # the same through the report: errors within 0.05 right, beyond it (or none) wrong
    report = confidence.calibration_report(conf, np.array([0.0, 0.05, 0.2, np.inf]))
    assert report["expected_calibration_error"] == pytest.approx(0.75) and report["confidence"] == report["within"]


def test_calibration_report_by_hand():
    # right: errors within 0.05 (on the edge too); an unmapped vertex (inf) never is
    report = confidence.calibration_report(np.array([0.25, 0.25, 0.9, 1.0]), np.array([0.05, 0.2, 0.0, np.inf]))
    assert report["within"] == 0.5 and report["confidence"] == pytest.approx(0.6)
    # bin 0.2-0.3: 1 of 2 right (gap 0.25); bin 0.9-1.0: 1 of 2 (gap 0.45)
    assert report["expected_calibration_error"] == pytest.approx(0.5 * 0.25 + 0.5 * 0.45)
    assert report["threshold"] == confidence.WITHIN == 0.05
    assert report["bins"][0] == {"low": 0.0, "high": 0.1, "share": 0.0, "confidence": None, "accuracy": None}
    assert report["bins"][2]["accuracy"] == 0.5
    with pytest.raises(ValueError, match="3 confidences for 4 errors"):
        confidence.calibration_report(np.zeros(3), np.zeros(4))


@pytest.mark.parametrize("name", ["PARTIAL_CALIBRATION", "PART_CALIBRATION"])
def test_a_single_table_is_taken_whatever_the_distortion(name):
    """A partial symmetry's map and a part's map onto its whole each take one table."""
    table = np.asarray(getattr(confidence, name))
    assert table.shape == (20,) and 0 <= table.min() and table.max() <= 1 and np.all(np.diff(table) >= 0)
    centres = (np.arange(20) + 0.5) / 20
    d = np.array([0.0, 1.0, np.nan, 0.015] * 5)
    assert confidence.calibrated(centres, d, table=tuple(table)) == pytest.approx(table, abs=1e-6)
    one = confidence.calibrated(np.array([0.05]), table=tuple(table))[0]
    assert one == pytest.approx((table[0] + table[1]) / 2)
