"""Scores against a symmetry group (issue 50, item 2): a found map equal to any of a
shape's true maps scores as right, each found symmetry against its nearest true map."""

import json

import numpy as np
import pytest

from intrinsym.app import cli
from intrinsym.errors import InputError
from intrinsym.evaluation import symmetry_group
from intrinsym.geodesics import geodesics
from intrinsym.mesh import generated as shapes
from intrinsym.mesh.shape import Shape

SMALL = ["--source", "30", "--target", "300", "--spin-cloud", "5000", "--iterations", "5"]


def _shape(generated: shapes.GeneratedShape) -> Shape:
    return Shape(generated.vertices, generated.faces)


@pytest.fixture(scope="module")
def star(tmp_path_factory):
    """A generated star (its 19 true maps in star.maps.npy) and a result on it, whose
    symmetry map the tests replace (so the detect leaves out ZoomOut's, half its time)."""
    d = tmp_path_factory.mktemp("star")
    assert cli.main(["generate", "star", "--resolution", "4", "-o", str(d / "star.off")]) == 0
    assert cli.main(["detect", str(d / "star.off"), "-o", str(d / "out"), "-q", *SMALL, "--no-zoomout"]) == 0
    return d


def test_a_map_equal_to_any_true_map_scores_right(star, capsys):
    maps = np.load(star / "star.maps.npy")
    assert maps.shape[0] == 19
    np.save(star / "out" / "symmetry_map.npy", maps[3])  # right, but not the principal map
    assert cli.main(["evaluate", str(star / "out"), "--symmetry-map", str(star / "star.sym.npy"), "--json"]) == 0
    alone = json.loads((star / "out" / "scores.json").read_text())
    assert alone["group"]["maps"] == 1 and alone["map"]["within_0.10"] < 0.5
    assert cli.main(["evaluate", str(star / "out"), "--symmetry-map", str(star / "star.maps.npy")]) == 0
    group = json.loads((star / "out" / "scores.json").read_text())
    printed = capsys.readouterr().out
    assert "ground truth: 19 true maps; the scores above use map 3" in printed
    assert "within 0.05 sqrt(area) 1.000" in printed and "mean error 0.0000 sqrt(area)" in printed
    assert group["group"]["maps"] == 19 and group["group"]["nearest"] == 3
    assert group["map"]["within_0.10"] == 1.0 and group["map"]["mean_error"] == 0.0
    # several --symmetry-map: the maps of all files, in order
    np.save(star / "m3.npy", maps[3])
    args = ["evaluate", str(star / "out"), "--symmetry-map", str(star / "star.sym.npy"), "--symmetry-map"]
    assert cli.main([*args, str(star / "m3.npy")]) == 0
    both = json.loads((star / "out" / "scores.json").read_text())
    assert both["group"] == {**both["group"], "maps": 2, "nearest": 1} and both["map"]["within_0.10"] == 1.0


def test_each_found_symmetry_is_scored_against_its_nearest_true_map(star):
    shape = shapes.star(5, resolution=4)
    unit = geodesics.unit_area_graph(_shape(shape))
    maps = shape.symmetries
    vertices = np.arange(0, len(shape.vertices), 7)
    records = [{"pairs": np.column_stack([vertices, maps[k, vertices]]).tolist()} for k in (5, 0)]
    scores = symmetry_group.symmetry_scores(records, maps, unit)
    assert [s["truth"] for s in scores] == [5, 0]
    assert all(s["within_0.10"] == 1.0 and s["mean_error"] == 0.0 for s in scores)
    # a vertex left without an image counts as missed
    assert symmetry_group.nearest_map(np.where(np.arange(len(maps[0])) % 2, maps[7], -1), maps, unit) == 7


def test_group_files_are_checked(tmp_path, star):
    shape = _shape(shapes.star(5, resolution=4))
    n = len(shape.vertices)
    np.save(tmp_path / "wide.npy", np.zeros((2, n + 1), dtype=np.int64))
    np.save(tmp_path / "range.npy", np.full((2, n), n, dtype=np.int64))
    np.save(tmp_path / "float.npy", np.full((2, n), 0.5))
    for name, match in (
        ("wide", r"shape \(2, \d+\), expected \(K, \d+\)"),
        ("range", "out of range"),
        ("float", "non-integer"),
    ):
        with pytest.raises(InputError, match=match):
            symmetry_group.load_truths([tmp_path / f"{name}.npy"], shape)
