"""The HTML viewer: its packed data, and the page itself in a real headless browser."""

import base64
import json
import shutil
import zlib
from pathlib import Path

import numpy as np
import pytest
from conftest import sphere_result
from matplotlib.image import imread

from intrinsym import viewer

CHROMIUM = Path("/usr/bin/chromium")


def unpack(text, dtype):
    return np.frombuffer(zlib.decompress(base64.b64decode(text)), dtype=dtype)


def test_pack_roundtrip_and_row_quantisation():
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert np.array_equal(unpack(viewer.pack(a), np.float32).reshape(3, 4), a)
    m = np.array([[0.0, 0.5, 2.0], [1e-9, 3e-9, 4e-9], [0.0, 0.0, 0.0]])
    q = viewer.quantize_rows(m)
    assert q.dtype == np.uint8 and q.tolist() == [[0, 64, 255], [64, 191, 255], [0, 0, 0]]


def test_part_masks_mark_source_and_image_bits():
    masks = viewer.part_masks([{"source_vertices": [0, 1], "target_vertices": [1, 3]}], 5)
    assert masks.tolist() == [[1, 3, 0, 2, 0]]


def test_payload_interpolates_the_marginal_like_the_figures(tmp_path):
    out, v = sphere_result(tmp_path)
    html = viewer.write(out, tmp_path / "v.html")
    text = html.read_text()
    data = json.loads(text.split('id="data">', 1)[1].split("</script>", 1)[0])
    assert data["n_source"] == len(range(0, len(v), 16)) and data["n_target"] == len(v)
    assert data["symmetries"] == [] and "absent" in data["symmetries_note"]
    marg = unpack(data["marginals"], np.uint8).reshape(data["n_source"], data["n_target"])
    idx = unpack(data["weight_index"], np.uint16).reshape(len(v), data["k"])
    w = unpack(data["weight_value"], np.uint8).reshape(len(v), data["k"])
    # The browser's arithmetic for source 0: its heat peaks at the antipode of the sample.
    value = (marg[0][idx].astype(float) * w).sum(axis=1)
    assert np.linalg.norm(v[np.argmax(value)] + v[0]) < 0.2
    assert np.allclose(unpack(data["positions"], np.float32).reshape(-1, 3), v, atol=1e-6)


def _start_page(html: Path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install -e .[test])")
    if not CHROMIUM.exists() and shutil.which("chromium") is None:
        pytest.skip("chromium is not installed (apt-get install -y chromium; CI installs it in .ci/run)")
    pw = sync_api.sync_playwright().start()
    # SwiftShader: WebGL on a machine without a GPU.
    browser = pw.chromium.launch(
        executable_path=str(CHROMIUM if CHROMIUM.exists() else shutil.which("chromium")),
        args=["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
    )
    page = browser.new_page(viewport={"width": 900, "height": 600})
    errors = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(html.as_uri())
    page.wait_for_function("window.intrinsym && window.intrinsym.ready", timeout=60000)
    return pw, browser, page, errors


def _rot(axis, t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) if axis == 0 else np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def test_viewer_in_a_headless_browser(tmp_path):
    out, v = sphere_result(tmp_path)
    record = {"kind": "partial", "score": 0.5, "pairs": [[0, 1]],
              "source_vertices": np.flatnonzero(v[:, 0] > 0.2).tolist(),
              "target_vertices": np.flatnonzero(v[:, 0] < -0.2).tolist()}
    (out / "symmetries.json").write_text(json.dumps([record]))
    html = viewer.write(out)
    pw, browser, page, errors = _start_page(html)
    try:
        canvas = page.locator("canvas")
        before = tmp_path / "before.png"
        canvas.screenshot(path=str(before))
        box = canvas.bounding_box()
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.wait_for_function("window.intrinsym.mode === 'marginal'", timeout=10000)
        after = tmp_path / "after.png"
        canvas.screenshot(path=str(after))
        # The centre pixel shows the sphere point facing the camera; the page's initial
        # rotation is rot_x(0.3) rot_y(0.6) (y up), so that point is R's third row.
        facing = (_rot(0, 0.3) @ _rot(1, 0.6))[2]
        sources = v[::16]
        assert page.evaluate("window.intrinsym.source") == int(np.argmin(np.linalg.norm(sources - facing, axis=1)))
        a, b = imread(before)[..., :3], imread(after)[..., :3]
        assert np.abs(a - b).mean() > 0.05  # the grey mesh turned into a heat map
        heat_blue = (b[..., 2] > 0.5) & (b[..., 0] < 0.3)
        assert heat_blue.sum() > 0.1 * b.shape[0] * b.shape[1]
        # A sample on the far side maps to the front: red appears where its image projects
        # (orthographic, zoom 0.9 of the bounding sphere; see viewer.html).
        back = int(np.argmin(np.linalg.norm(sources + facing, axis=1)))
        page.evaluate(f"window.intrinsym.select({back}, -1)")
        red_shot = tmp_path / "red.png"
        canvas.screenshot(path=str(red_shot))
        c = imread(red_shot)[..., :3]
        h, w = c.shape[:2]
        red = (c[..., 0] > 0.6) & (c[..., 2] < 0.35)
        red[int(0.8 * h):] = False  # the colour bar of the legend
        ys, xs = np.nonzero(red)
        centre = v.mean(axis=0)
        q = (_rot(0, 0.3) @ _rot(1, 0.6)) @ (-sources[back] - centre)
        px = 0.9 * min(w, h) / (2 * np.linalg.norm(v - centre, axis=1).max())
        assert len(ys) > 50
        assert abs(xs.mean() - (w / 2 + q[0] * px)) < 0.05 * w and abs(ys.mean() - (h / 2 - q[1] * px)) < 0.05 * h
        # Toggling the symmetry colours its parts.
        page.locator("#symmetries input").first.check()
        parts = tmp_path / "parts.png"
        canvas.screenshot(path=str(parts))
        p = imread(parts)[..., :3]
        assert ((p[..., 0] > 0.5) & (p[..., 2] < 0.2)).sum() > 1000  # orange source part
        assert page.locator("#run").inner_text().count("detect") == 1
        assert errors == []
    finally:
        browser.close()
        pw.stop()
