"""What a user takes home (issue 50, items 3 and 4): the symmetry as colours (two sides,
partners alike, confidence) in the viewer, the figures, a PLY, a trimesh object and a
polyscope view, and a short repr."""

import sys

import numpy as np
import pytest
import trimesh
from matplotlib.image import imread
from scipy.spatial import cKDTree

from conftest import cli_run, mirror_shape, sphere_result
from intrinsym.app import cli, viewer, viz
from intrinsym.mesh.shape import Shape
from intrinsym.result import coloring


def _mirror_map(v: np.ndarray) -> np.ndarray:
    return cKDTree(v).query(v * [-1.0, 1.0, 1.0])[1].astype(np.int64)


def test_sides_split_a_mirror_symmetry_at_its_plane():
    v, f, sym = mirror_shape()
    shape = Shape(v, f)
    m = sym.copy()
    m[v[:, 1] > 0.8] = -1  # the top without a partner
    side = coloring.sides(shape, m)
    plane = np.abs(v[:, 0]) < 1e-9
    assert (side[plane & (m >= 0)] == 2).all()  # fixed points: white
    assert (side[m < 0] == -1).all()  # no partner: grey
    left, right = (v[:, 0] < -0.2) & (m >= 0), (v[:, 0] > 0.2) & (m >= 0)
    assert len(set(side[left])) == 1 and len(set(side[right])) == 1 and side[left][0] != side[right][0]
    rgb = coloring.vertex_colors(shape, m, "side")
    assert np.allclose(rgb[plane & (m >= 0)], coloring.FIXED_COLOR) and np.allclose(rgb[m < 0], coloring.NONE_COLOR)
    partner = coloring.vertex_colors(shape, m, "partner")
    has = m >= 0
    assert np.allclose(partner[has], partner[m[has]])  # each point coloured like its partner
    assert np.ptp(partner[has], axis=0).max() > 0.3  # and the colours vary over the shape
    assert [label for label, _ in coloring.legend("side")][-1] == "no partner"


def test_alike_symmetries_are_merged_for_display():
    part = {"kind": "partial", "source_vertex_index": list(range(100)), "target_vertex_index": list(range(100, 200))}
    near = {"kind": "partial", "source_vertex_index": list(range(3, 100)), "target_vertex_index": list(range(100, 198))}
    other = {"kind": "partial", "source_vertex_index": list(range(50)), "target_vertex_index": list(range(100, 150))}
    assert viewer.merge_alike([part, near, other], 200) == [[0, 1], [2]]
    assert viewer.merge_alike([part, {**near, "kind": "global"}], 200) == [[0], [1]]


@pytest.fixture
def mapped(tmp_path):
    """The sphere result with a mirror map (the bottom cap without a partner) and a confidence."""
    out, v = sphere_result(tmp_path)
    m = _mirror_map(v)
    m[v[:, 1] < -0.9] = -1
    np.save(out / "symmetry_map.npy", m)
    np.save(out / "symmetry_confidence.npy", np.clip(v[:, 2], 0, 1).astype(np.float32))
    return out, v, m


def test_figures_show_the_global_map_with_a_legend(mapped):
    out, v, m = mapped
    paths = viz.render(out, params=viz.FigureParams(size=2, dpi=60))
    assert [p.name for p in paths] == ["marginal.png", "graph.png", "global_symmetry.png"]
    shot = imread(paths[2])[..., :3]
    orange = (np.abs(shot - coloring.SIDE_COLORS[0]).max(axis=2) < 0.12).sum()
    blue = (np.abs(shot - coloring.SIDE_COLORS[1]).max(axis=2) < 0.12).sum()
    assert orange > 100 and blue > 100


def test_viewer_opens_on_the_two_sides_with_a_legend(mapped, tmp_path, browser):
    from test_viewer import _start_page, _symmetries

    out, v, m = mapped
    _symmetries(out, v)
    viewer.write(out)
    page, errors = _start_page(browser, out / "viewer.html", width=1200)
    try:
        assert page.evaluate("window.intrinsym.mode") == "side"
        assert "its two sides" in page.locator("#label-parts").inner_text()
        assert "no partner" in page.locator("#map-legend").inner_text()
        colors = np.array(page.evaluate("Array.from(window.intrinsym.colors.parts)")).reshape(-1, 3)
        expected = coloring.vertex_colors(Shape(v, None), m, "side")
        assert np.abs(colors - expected).max() < 1 / 255 + 1e-6
        page.select_option("#colour-by", "partner")
        colors = np.array(page.evaluate("Array.from(window.intrinsym.colors.parts)")).reshape(-1, 3)
        has = m >= 0
        assert np.abs(colors[has] - colors[m[has]]).max() < 2 / 255
        page.locator("#by-confidence input").check()  # the confidence: a toggle over either colouring
        assert "Confidence" in page.locator("#label-parts").inner_text()
        assert "confidence 0" in page.locator("#map-legend").inner_text()
        page.locator("#by-confidence input").uncheck()
        page.locator("#symmetries input").first.check()  # a symmetry checked: its parts
        assert page.evaluate("window.intrinsym.mode") == "parts"
        assert errors == []
    finally:
        page.close()


def test_export_ply_opens_in_trimesh_in_the_input_order(mapped, tmp_path):
    out, v, m = mapped
    for color in ("side", "partner", "confidence"):
        ply = tmp_path / f"{color}.ply"
        assert cli.main(["export", str(out), "--ply", str(ply), "--color", color]) == 0
        mesh = trimesh.load(ply, process=False, maintain_order=True)
        assert len(mesh.vertices) == len(v) and np.allclose(mesh.vertices, v)
        rgb = coloring.vertex_colors(Shape(v, None), m, color, np.clip(v[:, 2], 0, 1))
        assert np.array_equal(mesh.visual.vertex_colors[:, :3], np.round(rgb * 255).astype(np.uint8))
    sides = trimesh.load(tmp_path / "side.ply", process=False).visual.vertex_colors[:, :3]
    assert (sides[m < 0] == np.round(np.array(coloring.NONE_COLOR) * 255)).all()


def test_export_errors_are_one_line(tmp_path, capsys):
    out, _ = sphere_result(tmp_path)  # no symmetry_map.npy
    p = cli_run(capsys, "export", out, "--ply", tmp_path / "a.ply")
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "no symmetry_map.npy" in p.stderr


def test_result_to_trimesh_and_a_short_repr(tmp_path):
    import intrinsym
    from intrinsym.mesh import generated as shapes

    made = shapes.figure(resolution=6)
    assert shapes.save(made, tmp_path / "figure.off")
    # the extraction's map, not ZoomOut's (half the detect): the mesh carries whichever it is
    params = intrinsym.Params(n_source=30, n_target=300, spin_cloud=5000, iterations=5, zoomout=False)
    result = intrinsym.detect(tmp_path / "figure.off", params)
    text = repr(result)
    assert len(text) < 200 and "detect of figure.off" in text and "symmetries" in text
    assert "<b>intrinsym.Result</b>" in result._repr_html_()
    mesh = result.to_trimesh("partner")
    assert isinstance(mesh, trimesh.Trimesh) and np.array_equal(mesh.vertices, made.vertices)
    m = result.symmetry_map()
    assert np.array_equal(mesh.metadata["symmetry_map"], m)
    rgb = coloring.vertex_colors(Shape(made.vertices, made.faces), m, "partner")
    assert np.array_equal(mesh.visual.vertex_colors[:, :3], np.round(rgb * 255).astype(np.uint8))


def test_show_without_polyscope_says_which_extra(mapped, monkeypatch):
    from intrinsym.errors import InputError
    from intrinsym.result import export

    out, _, _ = mapped
    monkeypatch.setitem(sys.modules, "polyscope", None)  # as if not installed
    with pytest.raises(InputError, match=r"pip install 'intrinsym\[polyscope\]'"):
        export.show(out)


def test_show_registers_the_colours_in_polyscope(mapped, monkeypatch):
    import os

    ps = pytest.importorskip("polyscope", reason="polyscope is not installed (pip install -e .[polyscope])")
    if not os.environ.get("DISPLAY"):
        pytest.skip("polyscope needs a display")
    from intrinsym.result import export

    out, _, _ = mapped
    monkeypatch.setattr(ps, "show", lambda: None)
    export.show(out)
    assert ps.has_surface_mesh("input")
