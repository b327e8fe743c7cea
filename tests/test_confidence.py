"""The calibrated per-vertex confidence: its table and interpolation."""

import numpy as np
import pytest

from intrinsym import confidence


def test_calibration_table_is_a_non_decreasing_probability():
    table = np.asarray(confidence.CALIBRATION)
    assert table.shape == (20,)
    assert 0 <= table.min() and table.max() <= 1
    assert np.all(np.diff(table) >= 0)


def test_calibrated_interpolates_between_bin_centres():
    table = np.asarray(confidence.CALIBRATION)
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
