"""The development benchmark scripts of benchmarks/: their tables and error handling."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

import intrinsym
from conftest import shared
from intrinsym.result.modes import Modes

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import compare  # noqa: E402
import partial  # noqa: E402
import partial_targets  # noqa: E402
import scores  # noqa: E402
import shrec16_match  # noqa: E402
import tosca  # noqa: E402


def test_score_table_markdown():
    row = {
        "shape": "cat1",
        "config": "wks",
        "iterations": 4,
        "unary": dict(mirror_hit=0.5, peak_recall=0.25, decoy_recall=0.0, breadth=0.125, n_scored=3),
        "bp": dict(mirror_hit=1.0, peak_recall=1.0, decoy_recall=0.0, breadth=0.0625, n_scored=3),
        "map": {"within_0.05": 0.5, "within_0.10": 0.75, "mean_error": 0.03125},
    }
    mirrored = dict(row, shape="cow", mirror_residual=0.0001)
    lines = scores.markdown([row, mirrored]).splitlines()
    assert lines[0].startswith("| shape | config | unary mirror_hit | bp mirror_hit |")
    assert lines[0].endswith("| BP iterations | map within 0.05 | map within 0.10 | map mean error |")
    assert lines[2] == (
        "| cat1 | `wks` | 0.500 | 1.000 | 0.250 | 1.000 | 0.000 | 0.000 | 0.125 | 0.062 | 4 | 0.500 | 0.750 | 0.031 |"
    )
    assert lines[3].startswith("| cow (reflection, residual 0.0001) | `wks` |")
    assert scores.config_params("paper") == ("paper", {})
    assert scores.config_params("wks*spin") == ("default", {"unary": "wks*spin"})


def test_score_table_bad_data_is_one_line_exit_2(tmp_path, capsys):
    assert scores.main(["--data", str(tmp_path), "--shapes", "cat1", "--config", "wks"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cat1.off" in err[0]


@pytest.mark.slow
def test_wks_spin_scores_on_tosca_wolf(tmp_path):
    data = shared("tosca_sym/wolf1.off").parent
    out = tmp_path / "table.md"
    assert (
        scores.main(
            [
                "--data",
                str(data),
                "--shapes",
                "wolf1",
                "--config",
                "wks*spin",
                "--source",
                "100",
                "--target",
                "1000",
                "--iterations",
                "5",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    row = json.loads(out.with_suffix(".json").read_text())[0]
    assert row["unary"]["mirror_hit"] >= 0.9 and row["bp"]["mirror_hit"] >= 0.9
    assert row["bp"]["decoy_recall"] <= 0.05
    assert row["map"]["within_0.10"] >= 0.9


def test_tosca_parameters_other_than_the_defaults(tmp_path, capsys):
    import intrinsym

    assert tosca._overrides(["rho=0.3", "remove_trivial=no"]) == {"rho": 0.3, "remove_trivial": False}
    for bad in ("rho", "radius=2", "rho=high", "rho=2"):
        with pytest.raises(intrinsym.ParameterError):
            tosca._overrides([bad])
    with pytest.raises(SystemExit) as exit_:
        tosca.main(["--data", str(tmp_path), "--param", "rho=high"])
    err = capsys.readouterr().err.strip().splitlines()
    assert exit_.value.code == 2 and "--param rho: 'high' is not a float" in err[-1]


def test_score_table_against_a_reflection(tmp_path):
    # the generated mirror shape has no symmetry file: its ground truth is its reflection
    from conftest import mirror_shape

    v, f, _ = mirror_shape()
    path = tmp_path / "bent.off"
    trimesh.Trimesh(v, f, process=False).export(path)
    out = tmp_path / "table.md"
    assert (
        scores.main(
            [
                "--mirror",
                str(path),
                "--config",
                "default",
                "--source",
                "60",
                "--target",
                "600",
                "--iterations",
                "10",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    row = json.loads(out.with_suffix(".json").read_text())[0]
    assert row["shape"] == "bent" and row["mirror_residual"] < 1e-6
    assert row["bp"]["mirror_hit"] >= 0.9 and row["map"]["within_0.10"] >= 0.9


def _row(cls, count, within, shape="s"):
    return {"shape": shape, "class": cls, "reliability": {"count": count, "within_0.05": within}}


def test_calibration_fit_is_the_weighted_isotonic_regression_by_hand():
    import calibration

    # 4 mass bins; shares 0.5, 0.2, 0.9, 1.0 with counts 10, 30, 10, 10: the first two
    # violate monotony and pool to (5 + 6) / 40 = 0.275; the empty bin takes a neighbour's.
    rows = [_row("a", [10, 30, 0, 10], [5, 6, 0, 9]), _row("b", [0, 0, 10, 0], [0, 0, 10, 0])]
    fitted = calibration.fit(rows)
    assert fitted == pytest.approx([0.275, 0.275, 0.95, 0.95])


def test_calibration_fits_each_group_of_bins_on_its_own():
    import calibration

    # 2 groups of 2 bins: (0.8, 0.6) pools to 0.7 alone; (0.2, 0.4) is already monotone,
    # though it lies below the first group
    row = {"shape": "s", "class": "a", "reliability": {"bins": 2, "count": [10, 10, 5, 5], "within_0.05": [8, 6, 1, 2]}}
    assert calibration.fit([row]) == pytest.approx([0.7, 0.7, 0.2, 0.4])
    assert calibration.bin_centres([row]) == pytest.approx([0.25, 0.75, 0.25, 0.75])


def test_calibration_ece_by_hand():
    import calibration

    # two bins of confidence 0.25 and 0.95 holding 3 and 1 items, 1 and 1 right:
    # ECE = 3/4 |1/3 - 0.25| + 1/4 |1 - 0.95|
    ece = calibration.ece(np.array([0.25, 0.95]), np.array([3.0, 1.0]), np.array([1.0, 1.0]))
    assert ece == pytest.approx(0.75 * (1 / 3 - 0.25) + 0.25 * 0.05)
    # a perfectly calibrated confidence
    assert calibration.ece(np.array([0.5]), np.array([4.0]), np.array([2.0])) == pytest.approx(0.0)


def test_calibration_leaves_each_class_out():
    import calibration

    # class a: every vertex right, class b: every vertex wrong; held out, each class gets
    # the other's fit, so the calibrated ECE is 1 for both.
    rows = [_row("a", [0, 5], [0, 5], "a0"), _row("b", [0, 5], [0, 0], "b0")]
    per_class, conf, count, within = calibration.leave_one_class_out(rows)
    assert [c["ece_calibrated"] for c in per_class] == pytest.approx([1.0, 1.0])
    assert per_class[0]["global"] == [("a0", pytest.approx(0.0), pytest.approx(1.0))]


def test_calibration_table_fit_by_hand():
    import calibration

    # a table of 0.5 / 1.0 on two bins; class a: 2 of 4 right in bin 0 (exact), class b:
    # 1 of 2 right in bin 1 (off by 0.5). Pooled ECE: 2/6 * 0.5; b's global gap 0.5, a's 0.
    rows = [_row("a", [4, 0], [2, 0], "a0"), _row("b", [0, 2], [0, 1], "b0"), _row("b", [0, 0], [0, 0], "b1")]
    fit = calibration.table_fit(rows, np.array([0.5, 1.0]))
    assert fit["ece"] == pytest.approx(2 / 6 * 0.5)
    assert fit["per_class"] == {"a": pytest.approx(0.0), "b": pytest.approx(0.5)}
    assert fit["global_gap"] == pytest.approx(0.25)  # b1 scores no vertex: left out


def test_refine_table_by_hand(tmp_path, capsys):
    import refine

    settings = [(20, 2.0), (15, 2.0)]
    rows = [
        {"shape": "a", "before": (0.5, 0.9, 0.04), (20, 2.0): (0.75, 1.0, 0.02), (15, 2.0): (0.25, 0.9, 0.05)},
        {"shape": "b", "before": (1.0, 1.0, 0.01), (20, 2.0): (1.0, 1.0, 0.01), (15, 2.0): (1.0, 1.0, 0.01)},
    ]
    rows[0]["moved"], rows[1]["moved"] = 0.5, 0.0
    lines = refine.markdown(rows, settings).splitlines()
    assert lines[0] == (
        "| shape | before: within 0.05 / 0.10 / mean error | 20 anchors, 2 spacings | 15 anchors, 2 spacings "
        "| moved (first setting) |"
    )
    assert lines[2] == "| a | 0.500 / 0.900 / 0.0400 | 0.750 / 1.000 / 0.0200 | 0.250 / 0.900 / 0.0500 | 0.50 |"
    assert lines[5].startswith("- 20 anchors, 2 spacings: mean within 0.05 0.750 -> 0.875, within 0.10 0.950 -> 1.000")
    assert "within 0.05 >= 0.90: 1 -> 1" in lines[5] and "largest loss within 0.05 +0.000 (b)" in lines[5]
    assert "largest loss within 0.05 -0.250 (a), within 0.10 +0.000" in lines[6]
    assert refine.main(["--data", str(tmp_path / "absent"), "--saved", str(tmp_path)]) == 0
    assert "skipped" in capsys.readouterr().out


def test_local_isometry_table_by_hand(tmp_path, capsys):
    import local_isometry

    row = {"shape": "a", "miss": 0.125, ("map", "misses"): 0.02, ("truth", "misses"): 0.0}
    row |= {("map", "hits"): 0.004, ("truth", "hits"): 0.00125}
    lines = local_isometry.markdown([row]).splitlines()
    assert lines[0].startswith("| shape | misses (> 0.05) | map at the misses | truth at the misses |")
    assert lines[2] == "| a | 0.125 | 0.0200 | 0.0000 | 0.0040 | 0.0013 |"
    assert local_isometry.main(["--data", str(tmp_path / "absent"), "--saved", str(tmp_path)]) == 0
    assert "skipped" in capsys.readouterr().out


def test_unary_partner_tells_the_true_mirror_from_a_random_map(tmp_path, capsys):
    """On the bent ellipsoid, the default unary keeps the true mirror partner within a
    width of each sample's best target and never at the floor, and BP's argmax finds it;
    a random "partner" (an independent wrong truth) sits at the floor on half the samples."""
    import unary_partner
    from conftest import mirror_shape
    from intrinsym.geodesics import geodesics

    vertices, faces, sym = mirror_shape()
    shape = intrinsym.Shape(vertices, faces)
    _, vertex, graph = geodesics.unit_area_graph(shape)
    params = intrinsym.make_params(n_source=60, n_target=600)
    true = unary_partner.measure(unary_partner.Truth("m", shape, sym, graph, vertex), "wks*spin", params)
    wrong = np.random.default_rng(0).permutation(len(sym))
    rand = unary_partner.measure(unary_partner.Truth("r", shape, wrong, graph, vertex), "wks*spin", params)
    assert true["samples"] >= 45 and true["argmax ≤0.10"] >= 0.9
    assert true["partner at floor"] == 0.0 and true["partner z"] <= 1.5
    assert true["best z"] <= true["partner z"]
    assert true["BP argmax ≤0.10"] >= 0.9
    assert rand["partner at floor"] >= 0.4 and rand["argmax ≤0.10"] <= 0.2 and rand["BP argmax ≤0.10"] <= 0.2
    lines = unary_partner.markdown([true]).splitlines()
    assert lines[0].startswith("| shape | term | samples | argmax ≤0.05 |")
    assert lines[2].startswith(f"| m | wks*spin | {true['samples']} | ")
    # the rows --json writes are what partial_targets.py reads beside a shape that misses
    (tmp_path / "u.json").write_text(json.dumps([true, rand]))
    assert partial_targets.load_unary([tmp_path / "u.json"]) == {"m": true, "r": rand}
    assert unary_partner.main(["--data", str(tmp_path / "absent")]) == 0
    assert "skipped" in capsys.readouterr().out


def _partial_rows(tmp_path: Path) -> tuple[Path, Path]:
    """A data folder of four SHREC'16 names (empty files) and partial.py's cache for them,
    scores set by hand: cuts_cat meets every target; cuts_dog is below balanced 0.60 and
    maps its unpartnered side; holes_cat meets the balanced 0.60 but not the holes' 0.90
    within 0.10; holes_dog has no unpartnered vertex and an IoU of 0.5."""
    data, cache = tmp_path / "data", tmp_path / "cache"
    scores = {  # balanced, within 0.05, within 0.10, unpartnered unmapped, IoU, seconds
        "cuts_cat_shape_1": (0.90, 0.90, 0.95, 0.90, 0.85, 4.0),
        "cuts_dog_shape_1": (0.30, 0.40, 0.50, 0.20, 0.90, 8.0),
        "holes_cat_shape_1": (0.80, 0.70, 0.85, 0.90, 0.95, 6.0),
        "holes_dog_shape_1": (0.70, 0.70, 0.95, None, 0.50, 2.0),
    }
    for name, (bal, w05, w10, unmapped, iou, seconds) in scores.items():
        (data / "shrec16_partial" / name.split("_")[0]).mkdir(parents=True, exist_ok=True)
        (data / "shrec16_partial" / name.split("_")[0] / f"{name}.off").write_text("")
        path = data / "shrec16_partial" / name.split("_")[0] / f"{name}.off"
        own = {"balanced": bal, "partnered_within_005": w05, "partnered_within_010": w10}
        own |= {"unpartnered_unmapped": unmapped, "iou": iou, "seconds": seconds}
        own["self_map"] = {  # detect's record: None where it kept a global map
            "holes_cat_shape_1": {"source": "hypothesis 1", "trivial_global": None},
            "holes_dog_shape_1": {"source": "none", "trivial_global": 0.9},
        }.get(name)
        others = {"none": {"balanced": 0.5 if unmapped is not None else 0.0}, "pyfm": {"balanced": 0.25}}
        for method, row in {"intrinsym": own, **others}.items():
            partial._work(
                path, method, cache, partial._key(method, "t", {}), {}, lambda *_, r=row, n=name: {"shape": n, **r}
            )
    return data, cache


def test_partial_targets_by_hand(tmp_path, capsys):
    """Each target of the partial-symmetry issue on four hand-scored shapes: the means, the
    shapes below a per-shape bound, the kinds and classes that miss, the baselines' margin,
    and the shapes listed with the measures of the unary beside them."""
    data, cache = _partial_rows(tmp_path)
    unary = tmp_path / "unary.json"
    measures = ("partner at floor", "argmax ≤0.05", "BP argmax ≤0.05")
    unary_rows = [("cuts_dog_shape_1", "wks*spin", 0.8, 0.1, 0.05), ("cuts_cat_shape_1", "wks*spin", 0.1, 0.7, 0.9)]
    unary_rows.append(("cuts_cat_shape_1", "spin", 0.0, 0.0, 0.0))  # another term: not the default unary's
    unary.write_text(json.dumps([{"shape": n, "term": t, **dict(zip(measures, v))} for n, t, *v in unary_rows]))
    out = tmp_path / "targets.md"
    args = ["--data", str(data), "--cache", str(cache), "--tag", "t", "--unary", str(unary), "-o", str(out)]
    assert partial_targets.main(args) == 0
    text = capsys.readouterr().out
    assert out.read_text() == text
    cells = [[c.strip() for c in line.strip("| ").split(" | ")] for line in text.splitlines() if line.startswith("| ")]
    rows = {c[0]: c for c in cells}
    # the mean balanced: (0.9 + 0.3 + 0.8 + 0.7) / 4 = 0.675, short of 0.85 by 0.175; cuts
    # (0.600), holes (0.750), cat (0.850 meets it), dog (0.500)
    assert rows["balanced, mean (≥ 0.85)"][1:4] == [
        "0.675 over 4 shapes",
        "0.175",
        "cuts 0.600, holes 0.750, dog 0.500",
    ]
    assert rows["balanced, every shape (≥ 0.6)"][1:5] == [
        "1 of 4 short, lowest 0.300",
        "up to 0.300",
        "cuts 0.300, dog 0.300",
        "1: dog 1",
    ]
    # unpartnered unmapped: holes_dog has none, so the mean of three: (0.9 + 0.2 + 0.9) / 3
    assert rows["unpartnered left unmapped, mean (≥ 0.85)"][1:3] == ["0.667 over 3 shapes", "0.183"]
    # the holes' within 0.10: only holes_cat (0.85) is short, by 0.05; its class is cat
    assert rows["holes: partnered within 0.10, every shape (≥ 0.9)"][1:5] == [
        "1 of 2 short, lowest 0.850",
        "up to 0.050",
        "cat 0.850",
        "1: cat 1",
    ]
    # IoU 0.80 on 3 of 4 (75 %): 90 % asks for ceil(3.6) = 4, one shape short
    assert rows["IoU best 0.80 on 90 % of the shapes (≥ 0.8)"][1:4] == ["3 of 4 (75%)", "1 shape", "holes 50%, dog 50%"]
    assert rows["seconds per shape (≤ 5)"][1:3] == ["median 5.0, 2.0-8.0", "up to 1.6x"]
    # ahead of the better baseline (none: 0.5, or 0.0 on holes_dog) in the four groups,
    # by the least in cuts: 0.6 against none's 0.5
    baseline = rows["ahead of none and pyFM on the mean balanced score, every kind and class"]
    assert baseline[1:3] == ["ahead on 4 of 4; least margin 0.100 (cuts)", "met"]
    listed = [r for r in rows if r.endswith("_shape_1")]
    assert listed == ["cuts_dog_shape_1", "holes_cat_shape_1", "holes_dog_shape_1"]
    assert rows["cuts_dog_shape_1"][1:] == [
        "balanced",
        "0.300",
        "0.400",
        "0.500",
        "0.200",
        "0.900",
        "global",
        "0.80",
        "0.10",
        "0.05",
    ]
    assert rows["holes_cat_shape_1"][1] == "holes ≤0.10" and rows["holes_cat_shape_1"][-4:] == [
        "partial: hypothesis 1",
        "–",
        "–",
        "–",
    ]
    assert rows["holes_dog_shape_1"][1] == "IoU" and rows["holes_dog_shape_1"][5] == "–"
    assert rows["holes_dog_shape_1"][7] == "nothing, global was trivial"
    assert (
        "- partner at floor: median 0.80 over the 1 shape below balanced 0.60, 0.10 over the 1 shape at or above"
        in text
    )
    # a shape without its cached row, a tag not cached and an unreadable unary file: one line, exit 2
    assert partial_targets.main([*args[:5], "other"]) == 2
    assert (
        capsys.readouterr()
        .err.strip()
        .endswith("cuts_cat_shape_1.intrinsym.json: no row of tag 'other' (run partial.py)")
    )
    (cache / "holes_dog_shape_1.pyfm.json").unlink()
    assert partial_targets.main(args) == 2
    assert capsys.readouterr().err.strip().endswith("holes_dog_shape_1.pyfm.json: no row of tag 't' (run partial.py)")
    unary.write_text("{")
    _partial_rows(tmp_path)
    assert partial_targets.main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"partial_targets.py: {unary}: not unary_partner.py's --json rows") and "\n" not in err
    assert partial_targets.main(["--data", str(tmp_path / "absent"), "--cache", str(cache)]) == 0
    assert "skipped" in capsys.readouterr().out


def test_shrec16_match_tells_which_answer_mode_0_is():
    """``true_answer`` by hand on a path of six vertices one unit apart, whose true and
    mirror answers are i and 5 - i: mode 0 on the true answers, on the mirror ones, on
    half of each (a tie), and with no far-apart vertex."""
    graph = sp.diags([np.ones(5), np.ones(5)], [1, -1], format="csr")
    true, mirror = np.arange(6), 5 - np.arange(6)
    far = np.ones(6, dtype=bool)

    def answer(first: np.ndarray, where: np.ndarray = far) -> float | None:
        two = Modes(np.stack([first, mirror]), np.zeros((2, 1), np.int64), np.ones(2), np.full(2, 0.5))
        return shrec16_match.true_answer(shrec16_match.mode_errors(two, true, mirror, graph, where))

    assert answer(true) == 1.0
    assert answer(mirror) == 0.0
    assert answer(np.array([0, 1, 2, 2, 1, 0])) == 0.5
    assert answer(np.array([0, 1, 2, 2, 1, 0]), np.array([1, 1, 0, 0, 0, 0], bool)) == 1.0
    assert answer(true, np.zeros(6, bool)) is None


def test_shrec16_match_tells_search_from_test():
    """``search_or_test`` by hand: of three wrong pairs, the true map changes fewer
    distances than the kept map by more than the margin on one (the search), by less on
    one and more on one (the test); a right pair, one without a truth row and one whose
    truth run failed are left out."""

    def mine(within: float, changed: float) -> dict:
        return {"within_010": within, "part_map_final": "polished", "part_map_distortion": {"polished": changed}}

    raw = {
        ("a", "intrinsym"): mine(0.2, 0.10),
        ("a", "truth"): {"truth_changed": 0.02},
        ("b", "intrinsym"): mine(0.5, 0.10),
        ("b", "truth"): {"truth_changed": 0.095},
        ("c", "intrinsym"): mine(0.7, 0.05),
        ("c", "truth"): {"truth_changed": 0.20},
        ("d", "intrinsym"): mine(0.9, 0.30),
        ("d", "truth"): {"truth_changed": 0.00},
        ("e", "intrinsym"): mine(0.1, 0.30),
        ("f", "intrinsym"): mine(0.1, 0.30),
        ("f", "truth"): {"error": "a failed run"},
    }
    rows = {k: {**r, **shrec16_match._kept(r)} for k, r in raw.items()}
    assert rows["a", "intrinsym"]["kept_changed"] == 0.10 and "kept_changed" not in rows["a", "truth"]
    line = shrec16_match.search_or_test(rows, ["a", "b", "c", "d", "e", "f"])
    assert "vertices: 3." in line
    assert "on 1: the search never offered it (a);" in line
    assert "not on 2: the test would not keep it (b, c)." in line


def _results(folder: Path, scores: dict, metric: str = "balanced") -> Path:
    folder.mkdir()
    for shape, value in scores.items():
        (folder / f"{shape}.intrinsym.json").write_text(
            json.dumps({"shape": shape, "method": "intrinsym", metric: value})
        )
    return folder


def test_compare_by_hand(tmp_path, capsys):
    """Two runs and a seed pair of four shapes, every number of the table by hand: the
    means, the change of the mean, the shapes past --within each way and the mean
    absolute change, per kind and over all; a shape one run lacks is left out."""
    before = _results(tmp_path / "a", {"cuts_x_1": 0.5, "cuts_x_2": 0.9, "holes_x_1": 0.2, "holes_x_2": 0.4})
    after = _results(tmp_path / "b", {"cuts_x_1": 0.8, "cuts_x_2": 0.9, "holes_x_1": 0.1, "holes_x_2": 0.404, "z": 1})
    seed = _results(tmp_path / "s", {"cuts_x_1": 0.6, "cuts_x_2": 0.9, "holes_x_1": 0.2, "holes_x_2": 0.4})
    assert compare.main([str(before), str(after), "--spread", str(before), str(seed)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[2] == "| cuts (2) | 0.700 | 0.850 | +0.150 | 1 | 0 | 0.150 |"
    assert lines[3] == "| holes (2) | 0.300 | 0.252 | -0.048 | 0 | 1 | 0.052 |"
    assert lines[4] == "| **all** (4) | 0.500 | 0.551 | +0.051 | 1 | 1 | 0.101 |"
    assert lines[5] == "| seed only (4) | 0.500 | 0.525 | +0.025 | 1 | 0 | 0.025 |"
    assert lines[7] == "Largest moves down: holes_x_1 0.200 -> 0.100"
    assert lines[8] == "Largest moves up: cuts_x_1 0.500 -> 0.800"
    assert lines[9].startswith("The change of the mean is 2.0 times the seed's (+0.051 against +0.025)")
    assert lines[9].endswith("shapes moved by more than 0.01: 2 against the seed's 1.")


def test_compare_reads_the_match_folder_and_its_metric(tmp_path, capsys):
    for name, value in (("a", 0.5), ("b", 0.75)):
        (tmp_path / name).mkdir()
        _results(tmp_path / name / "match", {"cuts_x_1": value}, metric="within_010")
    assert compare.main([str(tmp_path / "a"), str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("| within_010 |") and "| **all** (1) | 0.500 | 0.750 | +0.250 | 1 | 0 | 0.250 |" in out


@pytest.mark.parametrize(
    "args, named",
    [
        (["MISSING", "A"], "MISSING: not a folder"),
        (["EMPTY", "A"], "EMPTY: no results of intrinsym"),
        (["A", "B", "--metric", "seconds"], "--metric seconds: not in the results"),
        (["A", "C"], "no shape in both runs"),
        (["A", "B", "--shapes", "holes"], "no shape in both runs among --shapes"),
        (["A", "B", "--within", "-1"], "--within -1.0: must be at least 0"),
    ],
)
def test_compare_bad_input_is_one_line_exit_2(tmp_path, capsys, args, named):
    _results(tmp_path / "A", {"cuts_x_1": 0.5})
    _results(tmp_path / "B", {"cuts_x_1": 0.6})
    _results(tmp_path / "C", {"cuts_x_2": 0.6})
    (tmp_path / "EMPTY").mkdir()
    folders = {name: str(tmp_path / name) for name in ("A", "B", "C", "EMPTY", "MISSING")}
    assert compare.main([folders.get(a, a) for a in args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("compare.py: ") and named in err[0]
