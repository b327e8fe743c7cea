"""Marginal scores on hand-computed cases, and symmetry-map formats."""

import numpy as np
import pytest

from intrinsym.evaluate import load_symmetry_map, marginal_scores
from intrinsym.mesh import InputError


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


def test_symmetry_map_formats(tmp_path):
    truth = np.array([2, 1, 0, 3])
    (tmp_path / "a.sym").write_text("".join(f"{i + 1}\n" for i in truth))
    (tmp_path / "sym.txt").write_text("  ".join(f"{i + 1:e}" for i in truth))
    np.save(tmp_path / "c.npy", truth)
    for name in ("a.sym", "sym.txt", "c.npy"):
        assert load_symmetry_map(tmp_path / name, 4).tolist() == truth.tolist()


@pytest.mark.parametrize(
    "text,n,match",
    [("", None, "empty"), ("1\nx\n", None, "cannot read"), ("1.5\n2\n", None, "non-integer"),
     ("1\n5\n", None, "out of range"), ("1\n2\n", 3, "2 entries")],
)
def test_symmetry_map_errors(tmp_path, text, n, match):
    path = tmp_path / "bad.sym"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as err:
        load_symmetry_map(path, n)
    assert "bad.sym" in str(err.value) and "\n" not in str(err.value)
