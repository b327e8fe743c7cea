"""Figures: camera, Eq. 9 interpolation, shading, visibility, and the PNGs themselves."""

import dataclasses
import json

import numpy as np
import pytest
import trimesh
from matplotlib.image import imread

from conftest import cli_run, sphere_result
from intrinsym import Result
from intrinsym.app import viz


@pytest.mark.parametrize("up", ["x", "y", "z"])
def test_view_rotation_is_a_rotation_with_the_up_axis_on_screen_y(up):
    for elev, azim in [(0, 0), (20, 35), (60, 215)]:
        r = viz.view_rotation(elev, azim, up)
        assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)
    axis = np.eye(3)["xyz".index(up)]
    assert np.allclose(viz.view_rotation(0, 0, up) @ axis, [0, 1, 0])
    assert np.allclose(viz.view_rotation(0, 123, up) @ axis, [0, 1, 0])
    assert np.allclose(viz.view_rotation(90, 0, up) @ axis, [0, 0, 1])  # looking down on it


def test_continuous_marginal_is_eq9_normalised_to_max_1():
    rng = np.random.default_rng(0)
    points, targets = rng.normal(size=(200, 3)), rng.normal(size=(40, 3))
    row, sigma = rng.random(40), 0.7
    dense = (row * np.exp(-((np.linalg.norm(points[:, None] - targets[None], axis=2) / sigma) ** 2))).sum(axis=1)
    index, weight = viz.gaussian_weights(points, targets, sigma, k=40)
    assert np.allclose(viz.continuous_marginal(index, weight, row), dense / dense.max())
    # Truncated to the 16 nearest targets: the dropped terms are tiny at this density.
    index, weight = viz.gaussian_weights(points, targets, 0.2, k=16)
    dense = (row * np.exp(-((np.linalg.norm(points[:, None] - targets[None], axis=2) / 0.2) ** 2))).sum(axis=1)
    assert np.abs(viz.continuous_marginal(index, weight, row) - dense / dense.max()).max() < 1e-3


def test_target_spacing_of_a_grid():
    g = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0), [0.0]), axis=-1).reshape(-1, 3) * 0.5
    assert viz.target_spacing(g) == pytest.approx(0.5)


def test_shade_faces_sorts_far_to_near_and_lights_by_lambert():
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    edge_on = np.array([[0, 0, 0], [0, 0, 1], [0, 1, 0.5]])  # normal along x
    v = np.vstack([tri + [0, 0, 1], tri + [0, 0, -1], edge_on])
    f = np.arange(9).reshape(3, 3)
    rgb = np.repeat(np.eye(3), 3, axis=0)  # near face red, far face green, edge-on blue
    polys, colors = viz.shade_faces(v, f, rgb, np.eye(3))
    facing = viz.AMBIENT + (1 - viz.AMBIENT) * viz.LIGHT[2]
    side = viz.AMBIENT + (1 - viz.AMBIENT) * abs(viz.LIGHT[0])
    # Far to near by mean depth: green (z -1), blue (z 0.5), red (z 1).
    assert np.allclose(colors, [[0, facing, 0], [0, 0, side], [facing, 0, 0]])
    assert np.allclose(polys[0], tri[:, :2] - v.mean(axis=0)[:2])


def test_visible_hides_the_far_side_of_a_sphere(tmp_path):
    _, v = sphere_result(tmp_path)
    rot = viz.view_rotation(0, 0, "y")
    seen = viz.visible(v, v, rot)
    assert seen[v[:, 2] > 0.2].all()
    assert not seen[v[:, 2] < -0.2].any()


def _red(img):
    return (img[..., 0] > 0.6) & (img[..., 2] < 0.35) & (img[..., 1] < 0.5)


def _blue(img):
    return (img[..., 2] > 0.5) & (img[..., 0] < 0.3)


def test_marginal_figure_is_red_where_the_marginal_peaks(tmp_path):
    out, v = sphere_result(tmp_path)
    result = Result.load(out)
    shape = viz.load_shapes(result)[0]
    # Source 0 maps to the antipode of its position; put the camera looking at that point.
    peak = -result.source_points[0]
    # view_rotation(e, a) looks from (-cos e sin a, sin e, cos e cos a)
    azim = np.degrees(np.arctan2(-peak[0], peak[2]))
    elev = np.degrees(np.arcsin(np.clip(peak[1], -1, 1)))
    params = viz.FigureParams(views=((elev, azim),), size=3, dpi=80, sigma=0.4)
    img = imread(viz.marginal_figure(shape, result, 0, tmp_path / "m.png", params))
    red, blue = _red(img), _blue(img)
    assert red.sum() > 20 and blue.sum() > 20 * red.sum() / 10
    body = img[..., :3].sum(axis=2) < 2.9  # not the white background
    ys, xs = np.nonzero(body)
    ry, rx = np.nonzero(red)
    # The red spot sits in the middle of the disc the camera looks at, the rim is blue.
    assert abs(rx.mean() - xs.mean()) < 0.1 * np.ptp(xs) and abs(ry.mean() - ys.mean()) < 0.15 * np.ptp(ys)
    assert not red[ys.min() : ys.min() + 5].any()


def test_default_source_prefers_a_far_peak(tmp_path):
    out, v = sphere_result(tmp_path)
    result = Result.load(out)
    m = np.full_like(result.marginals, 1e-3)
    # Every sample peaks at itself (identity), sample 3 also nearly as high far away.
    near = np.argmin(np.linalg.norm(result.target_points[None] - result.source_points[:, None], axis=2), axis=1)
    m[np.arange(len(m)), near] = 1.0
    far = np.argmax(np.linalg.norm(result.target_points - result.source_points[3], axis=1))
    m[3, far] = 0.9
    result.marginals = m
    assert viz.default_source(result) == 3


def test_render_writes_marginal_graph_and_one_png_per_symmetry(tmp_path):
    out, v = sphere_result(tmp_path)
    params = viz.FigureParams(size=2, dpi=60)
    paths = viz.render(out, params=params)
    assert [p.name for p in paths] == ["marginal.png", "graph.png"]  # no symmetries.json: none drawn
    assert all(p.parent == out / "figures" for p in paths)
    record = {
        "kind": "partial",
        "score": 0.5,
        "pairs": [[0, 1]],
        "source_vertices": np.flatnonzero(v[:, 0] > 0.3).tolist(),
        "target_vertices": np.flatnonzero(v[:, 0] < -0.3).tolist(),
    }
    (out / "symmetries.json").write_text(json.dumps([record, record, record]))
    paths = viz.render(out, source=2, params=params, max_symmetries=2)
    assert [p.name for p in paths] == ["marginal.png", "graph.png", "symmetry_1.png", "symmetry_2.png"]
    assert imread(paths[2]).shape[0] == pytest.approx(2 * imread(paths[0]).shape[0], abs=2)  # two rows
    graph = imread(paths[1])
    assert _red(graph).sum() > 10  # the source samples


def test_correspondence_colors_follow_the_point_map(tmp_path):
    from scipy.spatial import cKDTree

    _, v = sphere_result(tmp_path)
    mirror = cKDTree(v).query(v * [-1, 1, 1])[1]
    left, right = np.flatnonzero(v[:, 0] > 0.1), np.flatnonzero(v[:, 0] < -0.1)
    samples = left[::5]
    record = {
        "source_vertices": left.tolist(),
        "target_vertices": right.tolist(),
        "pairs": np.column_stack([samples, mirror[samples]]).tolist(),
    }
    src, tgt = viz.correspondence_colors(v, record)
    outside = np.setdiff1d(np.arange(len(v)), left)
    assert np.allclose(src[outside], viz.BASE) and np.allclose(tgt[left], viz.BASE)
    # An image vertex looks like the source vertex that mirrors onto it, up to the
    # spacing of the sample pairs; it does not look like itself.
    assert np.abs(tgt[right] - src[mirror[right]]).mean() < 0.06
    own_red = 0.15 + 0.8 * (v[right, 0] - v[:, 0].min()) / np.ptp(v[:, 0])
    assert np.abs(tgt[right, 0] - own_red).mean() > 0.3
    assert not np.allclose(src[left], viz.BASE)


def test_graph_figure_shows_only_visible_samples(tmp_path):
    out, v = sphere_result(tmp_path)
    result = Result.load(out)
    # Keep only source samples on the far side: nothing red may be drawn.
    back = result.source_points[:, 2] < -0.3
    result.source_points = result.source_points[back]
    result.edges = np.zeros((0, 2), dtype=np.int64)
    result.info = dataclasses.replace(result.info, mode="match")  # no target dots
    shape = viz.load_shapes(Result.load(out))[0]
    img = imread(viz.graph_figure(shape, result, tmp_path / "g.png", viz.FigureParams(views=((0, 0),), dpi=60)))
    assert _red(img).sum() == 0


def test_figure_params_reject_bad_values():
    with pytest.raises(ValueError, match="up"):
        viz.FigureParams(up="w")
    with pytest.raises(ValueError, match="view"):
        viz.FigureParams(views=())


def test_cli_render_and_view(tmp_path, capsys):
    out, _ = sphere_result(tmp_path)
    p = cli_run(capsys, "render", out, "--source-sample", "1")
    assert p.returncode == 0, p.stderr
    assert (out / "figures" / "marginal.png").is_file() and (out / "figures" / "graph.png").is_file()
    p = cli_run(capsys, "view", out, "-o", tmp_path / "v.html", "-q")
    assert p.returncode == 0 and p.stdout == "", p.stderr
    html = (tmp_path / "v.html").read_text()
    assert "http://" not in html and "https://" not in html and "<link" not in html  # self-contained


@pytest.mark.parametrize("command", ["render", "view"])
def test_cli_render_view_errors_are_one_line_exit_2(tmp_path, capsys, command):
    p = cli_run(capsys, command, tmp_path / "missing")
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and "missing" in p.stderr
    out, _ = sphere_result(tmp_path)
    (tmp_path / "sphere.off").write_text("OFF\n3 1 0\n0 0 0\n")
    p = cli_run(capsys, command, out)
    assert p.returncode == 2 and "sphere.off" in p.stderr and "Traceback" not in p.stderr
    assert not (out / "figures").exists() and not (out / "viewer.html").exists()


def test_cli_render_rejects_a_bad_source_sample(tmp_path, capsys):
    out, _ = sphere_result(tmp_path)
    p = cli_run(capsys, "render", out, "--source-sample", "10000")
    assert p.returncode == 2 and "source sample" in p.stderr
    assert not (out / "figures").exists()


def test_progress_keeps_stage_lines_and_shows_bp_iterations_transiently():
    from io import StringIO

    from rich.console import Console

    from intrinsym.app import cli
    from intrinsym.progress import BPIteration, StageDone

    sink = StringIO()
    progress = cli._Progress(Console(file=sink, force_terminal=True, color_system=None, width=100))
    with progress:
        progress(StageDone("load", 0.1))
        progress(BPIteration(3, 0.01, 7))
        assert "bp iteration 3" in progress.bar.tasks[0].description
        assert "(at most 7)" in progress.bar.tasks[0].description
        progress(StageDone("bp", 1.0))
    text = sink.getvalue()
    assert "done load: 0.10 s" in text and "done bp: 1.00 s" in text


def test_detect_with_figures_and_no_progress_when_stderr_is_not_a_terminal(tmp_path, capsys):
    # a 320-triangle ellipsoid: the figures draw the input mesh, each panel every triangle
    # (the example's 5,856 in 8 panels of 9 figures took most of this test's 10 s);
    # --no-zoomout: the same figures without ZoomOut's global map, a third of the detect
    path = tmp_path / "ellipsoid.off"
    sphere = trimesh.creation.icosphere(subdivisions=2)
    trimesh.Trimesh(sphere.vertices * [1.5, 1.0, 0.6], sphere.faces, process=False).export(path)
    p = cli_run(
        capsys,
        "detect",
        path,
        "-o",
        tmp_path / "o",
        "--source",
        "20",
        "--target",
        "200",
        "--spin-cloud",
        "3000",
        "--iterations",
        "2",
        "--no-zoomout",
        "--figures",
    )
    assert p.returncode == 0, p.stderr
    assert p.stderr == ""
    assert "symmetries:" in p.stdout and "figures: marginal.png, graph.png" in p.stdout
    assert (tmp_path / "o" / "figures" / "marginal.png").is_file()


def test_render_of_a_two_shape_match_adds_the_source_shape_panel(tmp_path):
    out, _ = sphere_result(tmp_path)
    params = viz.FigureParams(size=2, dpi=50)
    width_detect = imread(viz.render(out, params=params)[0]).shape[1]
    run_json = json.loads((out / "run.json").read_text())
    run_json.update(mode="match", target_input=run_json["input"])
    (out / "run.json").write_text(json.dumps(run_json))
    (out / "symmetries.json").write_text("[]")
    paths = viz.render(out, params=params)
    assert [p.name for p in paths] == ["marginal.png", "graph.png"]
    assert imread(paths[0]).shape[1] == pytest.approx(width_detect * 4 / 3, abs=2)
