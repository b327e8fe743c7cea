"""The HTML viewer: its packed data, and the page itself in a real headless browser."""

import base64
import json
import shutil
import zlib
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread
from scipy.spatial import cKDTree

from conftest import sphere_result
from intrinsym import Result
from intrinsym.app import viewer, viz
from intrinsym.mesh.shape import surface_area


def unpack(text, dtype):
    return np.frombuffer(zlib.decompress(base64.b64decode(text)), dtype=dtype)


def test_pack_roundtrip_and_row_quantisation():
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert np.array_equal(unpack(viewer.pack(a), np.float32).reshape(3, 4), a)
    m = np.array([[0.0, 0.5, 2.0], [1e-9, 3e-9, 4e-9], [0.0, 0.0, 0.0]])
    q = viewer.quantize_rows(m)
    assert q.dtype == np.uint8 and q.tolist() == [[0, 64, 255], [64, 191, 255], [0, 0, 0]]


def test_part_masks_mark_source_and_image_bits():
    masks = viewer.part_masks(
        [
            {"source_vertex_index": [0, 1], "target_vertex_index": [1, 3]},
            {"source_vertices": [0, 1], "target_vertices": [1, 3]},
        ],
        5,
    )  # format version 1
    assert masks.tolist() == [[1, 3, 0, 2, 0]] * 2


def test_best_symmetry_is_the_global_one_else_the_self_map_else_the_best_scoring():
    assert viewer.best_symmetry([]) == -1
    assert viewer.best_symmetry([{"kind": "partial", "score": 0.9}, {"kind": "global", "score": 0.5}]) == 1
    ranked = [{"kind": "identity", "score": 1.0}, {"kind": "partial", "score": 0.2}, {"kind": "partial", "score": 0.3}]
    assert viewer.best_symmetry(ranked) == 2
    assert viewer.best_symmetry([*ranked, {"kind": "self map", "score": 0.1}]) == 3
    assert viewer.best_symmetry(ranked[:1]) == 0
    # The best takes the last listed place when it ranks below the listed ones.
    many = [{"kind": "partial", "score": 0.9 - 0.01 * i} for i in range(viewer.MAX_SYMMETRIES + 5)]
    many[-1]["kind"] = "global"
    indices, best = viewer.shown_symmetries(many)
    assert len(indices) == viewer.MAX_SYMMETRIES and indices[best] == len(many) - 1 and best == len(indices) - 1
    assert viewer.shown_symmetries(many[:3]) == ([0, 1, 2], 0)
    assert viewer.shown_symmetries([]) == ([], -1)


def test_pair_marks_spread_over_the_source_part():
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    record = {"pairs": [[0, 3], [1, 2], [2, 1], [3, 0]]}
    assert viewer.pair_marks(record, vertices, 2) == [[0, 3], [3, 0]]
    assert viewer.pair_marks(record, vertices, 3) == [[0, 3], [3, 0], [1, 2]]
    assert viewer.pair_marks(record, vertices) == viewer.pair_marks(record, vertices, 4)
    assert viewer.pair_marks({"pairs": []}, vertices) == []
    assert viewer.pair_marks({"pairs": [[1, 1]] * 3}, vertices) == [[1, 1]]


def _page_data(html: Path) -> dict:
    return json.loads(html.read_text().split('id="data">', 1)[1].split("</script>", 1)[0])


def test_payload_interpolates_the_marginal_like_the_figures(tmp_path):
    out, v = sphere_result(tmp_path)
    data = _page_data(viewer.write(out, tmp_path / "v.html"))
    assert data["n_source"] == len(range(0, len(v), 16)) and data["n_target"] == len(v)
    assert data["symmetries"] == [] and "absent" in data["symmetries_note"] and data["initial_symmetry"] == -1
    marg = unpack(data["marginals"], np.uint8).reshape(data["n_source"], data["n_target"])
    idx = unpack(data["weight_index"], np.uint16).reshape(len(v), data["k"])
    w = unpack(data["weight_value"], np.uint8).reshape(len(v), data["k"])
    # The browser's arithmetic for source 0: its heat peaks at the antipode of the sample.
    value = (marg[0][idx].astype(float) * w).sum(axis=1)
    assert np.linalg.norm(v[np.argmax(value)] + v[0]) < 0.2
    assert np.allclose(unpack(data["positions"], np.float32).reshape(-1, 3), v, atol=1e-6)


def _make_telling(out: Path, winner: int) -> None:
    """Give every source sample but ``winner`` its top marginal at itself (a trivial
    match), so that ``winner`` is the most telling sample (its top is at its antipode)."""
    result = Result.load(out)
    others = np.flatnonzero(np.arange(len(result.marginals)) != winner)
    result.marginals[others, result.source_point_vertex[others]] = 2.0
    result.save(out)


def _symmetries(out: Path, v: np.ndarray) -> None:
    """A better-scoring partial symmetry (y halves) ranked before the global one: the
    reflection x -> -x, its pairs every 8th vertex with x > 0.2 and its mirror image."""
    _, mirror = cKDTree(v).query(v * [-1, 1, 1])

    def record(kind, score, axis):
        part = np.flatnonzero(v[:, axis] > 0.2)
        return {
            "kind": kind,
            "score": score,
            "pairs": np.column_stack([part, mirror[part]])[::8].tolist(),
            "source_vertex_index": part.tolist(),
            "target_vertex_index": np.flatnonzero(v[:, axis] < -0.2).tolist(),
        }

    (out / "symmetries.json").write_text(json.dumps([record("partial", 0.9, 1), record("global", 0.5, 0)]))


def test_page_opens_on_the_best_symmetry_and_the_most_telling_sample(tmp_path):
    out, v = sphere_result(tmp_path)
    _make_telling(out, 5)
    _symmetries(out, v)
    data = _page_data(viewer.write(out))
    assert data["initial_source"] == viz.default_source(Result.load(out)) == 5
    assert data["initial_symmetry"] == 1 and data["symmetries"][1]["kind"] == "global"
    assert [s["rank"] for s in data["symmetries"]] == [1, 2]
    marks = np.array(data["symmetries"][1]["marks"])
    assert marks.shape == (viewer.MAX_MARKS, 2) and np.allclose(v[marks[:, 0]] * [-1, 1, 1], v[marks[:, 1]], atol=0.1)
    run = data["run"]
    assert list(run) == ["sizes", "seconds", "bp", "parameters", "more"]
    assert run["sizes"] == {
        "|Ps|": data["n_source"],
        "|Pt|": len(v),
        "edges": run["sizes"]["edges"],
        "mesh vertices": len(v),
    }
    assert run["bp"] == {"backend": "cpu", "iterations": 1, "converged": True}
    assert tuple(run["parameters"]) == viewer.MAIN_PARAMETERS and run["parameters"]["n_source"] == 250
    assert run["seconds"] == {"bp": 0.0, "total": 0.0}
    more = run["more"]
    assert more["mode"] == "detect" and "seed" in more and "resolved.scale" in more and "bp.max_change" in more
    assert not set(more) & set(viewer.MAIN_PARAMETERS) and not any("history" in key for key in more)


def _start_page(browser, html: Path, width: int = 900):
    """A page of the session's ``browser`` (conftest) on ``html``, loaded; and the list
    its console errors and page errors go to. Close it when done."""
    page = browser.new_page(viewport={"width": width, "height": 600})
    errors = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(html.as_uri())
    page.wait_for_function("window.intrinsym && window.intrinsym.ready", timeout=60000)
    return page, errors


def _red_centre(shot: np.ndarray, left: float, right: float) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the heat map's red pixels between the fractions ``left`` and
    ``right`` of the width, above the legend's colour bar."""
    h, w = shot.shape[:2]
    red = (shot[..., 0] > 0.6) & (shot[..., 2] < 0.35)
    red[int(0.8 * h) :] = False
    red[:, : int(left * w)] = False
    red[:, int(right * w) :] = False
    return np.nonzero(red)


def test_viewer_in_a_headless_browser(tmp_path, browser):
    out, v = sphere_result(tmp_path)
    sources = v[::16]
    winner = 1 + int(np.argmin(np.abs(sources[1:, 1])))  # its antipode lies at mid-height
    _make_telling(out, winner)
    _symmetries(out, v)
    data = _page_data(viewer.write(out))
    page, errors = _start_page(browser, out / "viewer.html", width=1200)
    try:
        # On load: the global symmetry (listed second, scored lower) on the left, the marginal
        # of the most telling sample on the right, its top (the antipode) turned to the camera.
        assert page.evaluate("window.intrinsym.views") == ["parts", "marginal"]
        assert page.evaluate("[...window.intrinsym.checked]") == [1]
        assert page.evaluate("window.intrinsym.source") == winner
        boxes = page.locator("#symmetries input")
        assert boxes.nth(1).is_checked() and not boxes.nth(0).is_checked()
        assert "global" in page.locator("#label-parts").inner_text()
        assert f"source sample {winner}" in page.locator("#label-marginal").inner_text()
        rotation = np.array(page.evaluate("window.intrinsym.rotation()")).reshape(3, 3)
        centre = v.mean(axis=0)
        q = rotation @ (-sources[winner] - centre)
        assert abs(q[0]) < 0.05 and abs(q[1]) < 0.05 and q[2] > 0.95
        # The discs of the first marked pair: one colour, around both ends of the pair.
        colors = np.array(page.evaluate("Array.from(window.intrinsym.colors.parts)")).reshape(-1, 3)
        marked = np.flatnonzero(np.abs(colors - [0.85, 0.1, 0.1]).max(axis=1) < 1e-6)
        ends = v[data["symmetries"][1]["marks"][0]]
        near = np.linalg.norm(v[marked, None] - ends[None], axis=2)
        assert (near.min(axis=0) < 1e-9).all() and (near.min(axis=1) < 0.1).all()
        canvas = page.locator("canvas")
        first = tmp_path / "first.png"
        canvas.screenshot(path=str(first))
        a = imread(first)[..., :3]
        h, w = a.shape[:2]
        left = a[:, : w // 2]
        assert (np.abs(left[..., 0] - left[..., 2]) > 0.15).sum() > 0.2 * left[..., 0].size  # the parts, not grey
        # Red appears where the antipode projects in the right view (orthographic, zoom 0.9 of the
        # bounding sphere; see viewer.html).
        ys, xs = _red_centre(a, 0.5, 1.0)
        px = 0.9 * min(w / 2, h) / (2 * np.linalg.norm(v - centre, axis=1).max())
        assert len(ys) > 50
        assert abs(xs.mean() - (0.75 * w + q[0] * px)) < 0.05 * w and abs(ys.mean() - (h / 2 - q[1] * px)) < 0.05 * h
        # A click on either view shows the marginal of the sample under the mouse.
        facing = int(np.argmin(np.linalg.norm(sources - rotation[2], axis=1)))
        box = canvas.bounding_box()
        for x in (0.25, 0.75):
            page.evaluate("window.intrinsym.select(0, -1)")
            page.mouse.click(box["x"] + x * box["width"], box["y"] + box["height"] / 2)
            page.wait_for_function(f"window.intrinsym.source === {facing}", timeout=10000)
        assert f"source sample {facing}" in page.locator("#label-marginal").inner_text()
        # Toggling the symmetries recolours the left view.
        boxes.nth(1).uncheck()
        assert page.locator("#label-parts").inner_text() == "No symmetry selected"
        grey = tmp_path / "grey.png"
        canvas.screenshot(path=str(grey))
        g = imread(grey)[..., :3][:, : w // 2]
        assert (np.abs(g[..., 0] - g[..., 2]) > 0.15).sum() < 10
        boxes.nth(0).check()
        assert "partial" in page.locator("#label-parts").inner_text()
        # Without symmetry_confidence.npy the page offers no confidence colouring.
        assert page.locator("#by-confidence").is_hidden()
        # The run panel: the groups shown, the rest folded.
        rows = {"sizes": "|Ps|", "seconds": "total", "bp": "converged", "parameters": "trivial_weight"}
        for group, row in rows.items():
            assert row in page.locator(f"#run-{group}").inner_text()
        assert page.eval_on_selector("#run-more", "e => e.tagName + ' ' + e.open") == "DETAILS false"
        assert "spin_bins" not in page.locator("#run").inner_text()
        page.locator("#run-more summary").click()
        assert "spin_bins" in page.locator("#run").inner_text()
        assert page.locator("#run").inner_text().count("detect") == 1
        assert errors == []
    finally:
        page.close()


def test_viewer_colours_the_symmetry_view_by_confidence(tmp_path, browser):
    out, v = sphere_result(tmp_path)
    _symmetries(out, v)
    conf = np.clip(v[:, 2], 0, 1).astype(np.float32)  # 0 on the lower half, up to 1 at the top
    np.save(out / "symmetry_confidence.npy", conf)
    data = _page_data(viewer.write(out))
    assert np.array_equal(unpack(data["confidence"], np.float32), conf)
    assert data["global_confidence"] == pytest.approx(float(conf.mean()))
    page, errors = _start_page(browser, out / "viewer.html")
    try:
        page.locator("#by-confidence input").check()
        assert "Confidence of the symmetry map" in page.locator("#label-parts").inner_text()
        colors = np.array(page.evaluate("Array.from(window.intrinsym.colors.parts)")).reshape(-1, 3)
        # the heat map's ends: blue at 0, red at 1
        assert np.allclose(colors[np.argmin(conf)], [0.125, 0.25, 0.816], atol=1e-6)
        assert np.allclose(colors[np.argmax(conf)], [0.816, 0.063, 0.063], atol=1e-2)
        page.locator("#by-confidence input").uncheck()
        assert "global" in page.locator("#label-parts").inner_text()
        assert errors == []
    finally:
        page.close()


def _hostile(tmp_path: Path) -> tuple[Path, Path]:
    """A result whose mesh name, symmetry kinds and scores would break a page that
    escapes only "</" and writes JSON's NaN: ``<!--<script>`` in the mesh's file name and
    a kind, NaN and Infinity in scores.json and a symmetry's score."""
    out, v = sphere_result(tmp_path)
    _symmetries(out, v)
    listed = json.loads((out / "symmetries.json").read_text())
    listed[0].update(kind="<!--<script>", score=float("nan"))
    listed[1]["kind"] = "global</script><script>window.hacked = 1</script>"
    (out / "symmetries.json").write_text(json.dumps(listed))
    (out / "scores.json").write_text(json.dumps({"mirror_hit": float("nan"), "map": {"mean_error": float("inf")}}))
    mesh = tmp_path / "a<!--<script>.off"
    shutil.copy(tmp_path / "sphere.off", mesh)
    return out, mesh


def test_page_data_is_strict_json_without_a_less_than_sign(tmp_path):
    out, mesh = _hostile(tmp_path)
    html = viewer.write(out, mesh_path=mesh)
    text = html.read_text().split('id="data">', 1)[1].split("</script>", 1)[0]
    assert "<" not in text

    def reject(name):
        raise ValueError(f"not JSON: {name}")

    data = json.loads(text, parse_constant=reject)
    assert data["name"] == mesh.name and data["symmetries"][0]["kind"] == "<!--<script>"
    assert data["scores"] == {"mirror_hit": "NaN", "map": {"mean_error": "Infinity"}}
    assert data["symmetries"][0]["score"] == "NaN"


def test_hostile_names_and_scores_do_not_blank_the_page(tmp_path, browser):
    out, mesh = _hostile(tmp_path)
    page, errors = _start_page(browser, viewer.write(out, mesh_path=mesh))
    try:
        assert page.locator("#title").inner_text() == f"intrinsym: {mesh.name}"
        assert page.evaluate("window.hacked") is None
        scores = page.locator("#scores").inner_text()
        assert "mirror_hit\tNaN" in scores and "map.mean_error\tInfinity" in scores
        assert "<!--<script>, score NaN" in page.locator("#symmetries").inner_text()
        page.locator("#symmetries input").nth(0).check()
        page.locator("#symmetries input").nth(1).uncheck()
        assert "<!--<script>, score NaN" in page.locator("#label-parts").inner_text()
        assert errors == []
    finally:
        page.close()


def test_a_matchs_page_shows_both_answers(turned_figure_match):
    """The figure matched to itself turned by 90 degrees (50 / 500, conftest's
    ``turned_figure_match``, also read by test_match_modes.py): the page's marginal
    of a sample is the mixture of the two modes' (:meth:`Result.mixed_marginals`), so it
    peaks near the sample's own point and near its mirror point (each within 0.1
    sqrt(area), at least a quarter of the row's top) on most samples whose two lie apart
    (measured at seeds 0 / 1 / 2: 1.000 / 0.968 / 0.938), where BP's first pass alone
    peaks at one of them (0.000 at each seed)."""
    a, b, mirror, result = turned_figure_match
    data = viewer.payload(result, b, [], None)
    marg = unpack(data["marginals"], np.uint8).reshape(data["n_source"], data["n_target"])
    src, tgt, unit = result.source_point_vertex, result.target_point_vertex, np.sqrt(surface_area(a))

    def peak(answer: np.ndarray, rows: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(a.vertices[tgt][None, :, :] - a.vertices[answer[src]][:, None, :], axis=2) / unit
        return np.where(d <= 0.1, rows, 0).max(axis=1)

    far = np.linalg.norm(a.vertices[src] - a.vertices[mirror[src]], axis=1) / unit > 0.2
    both = (peak(np.arange(len(a.vertices)), marg) >= 64) & (peak(mirror, marg) >= 64)
    assert far.sum() >= 20 and np.mean(both[far]) >= 0.85
    first = viewer.quantize_rows(result.marginals)
    alone = (peak(np.arange(len(a.vertices)), first) >= 64) & (peak(mirror, first) >= 64)
    assert np.mean(alone[far]) <= 0.1
