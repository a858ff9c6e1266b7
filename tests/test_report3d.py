"""The 3D view of the report and the app (three.js, WebGL), in a real headless browser.

A surface is drawn shaded with its triangles where the result put its nodes, a point
cloud as points; dragging orbits the view; colouring and the time slider change the
picture. Screenshots go to ``tmp_path`` (or ``$MODALMORPH_SCREENSHOTS`` when set).
Skipped, with the reason, without Chromium, its driver or selenium (see test_app.py).
"""

import base64
import io
import os
import re
import threading
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

import modalmorph as mm
from modalmorph.apps.app import make_server
from modalmorph.apps.report import render_page, result_payload, write_html

from .test_app import _browser_or_skip, _ready, _wait

# The 3D view holds coordinates about the scene's centre in float32 (WebGL's precision):
# relative error 2**-24 of the scene's size (about 30 units here).
FLOAT32_ATOL = 1e-4
# Share of the canvas a shape drawn in it covers at least (the sphere covers ~8%).
MIN_DRAWN = 0.02
# Share of the drawn pixels that must change when the view orbits (measured: ~60%).
MIN_CHANGED = 0.2


def sphere_mesh(n, rng):
    """``n`` random points on the unit sphere and outward triangles (convex hull)."""
    from scipy.spatial import ConvexHull

    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    f = ConvexHull(p).simplices.copy()
    normal = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    inward = np.sum(normal * p[f].mean(axis=1), axis=1) < 0
    f[inward] = f[inward][:, ::-1]
    return p, f


@pytest.fixture(scope="module")
def surface_result():
    p, f = sphere_mesh(300, np.random.default_rng(3))
    return mm.morph(mm.Shape(10 * p, faces=f), mm.Shape(p * [14, 9, 7] + [3, 0, 1], faces=f))


@pytest.fixture(scope="module")
def cloud_result():
    p, _ = sphere_mesh(200, np.random.default_rng(4))
    return mm.morph(10 * p, p * [13, 10, 8], max_steps=3)


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    browser = _browser_or_skip(tmp_path_factory.mktemp("downloads"))
    yield browser
    browser.quit()


@pytest.fixture
def shots(tmp_path):
    folder = Path(os.environ.get("MODALMORPH_SCREENSHOTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def test_payload_sends_the_faces_of_surfaces(surface_result, cloud_result):
    data = result_payload(surface_result)
    assert data["faces"] == surface_result.source.faces.tolist()
    assert data["target_faces"] == surface_result.target.faces.tolist()
    cloud = result_payload(cloud_result)
    assert cloud["faces"] is None and cloud["target_faces"] is None


def test_the_page_carries_three_js_inline():
    """One file, no network: three.js is inside the page, for the report and the app."""
    for page in (render_page(None), render_page(result_payload(
            mm.morph(*_two_clouds(), max_steps=1)))):
        script = re.search(r'<script id="three-js">(.*?)</script>', page, re.S).group(1)
        assert "three.js r187" in script and "OrbitControls" in script
        assert not re.search(r"<script[^>]*\bsrc=", page)


def _two_clouds():
    p, _ = sphere_mesh(40, np.random.default_rng(5))
    return 10 * p, 11 * p


def _canvas(browser) -> np.ndarray:
    """The 3D view's pixels (H, W, 3) as drawn now."""
    from PIL import Image

    url = browser.execute_script("render3D(); return document.querySelector('#view3d')"
                                 ".toDataURL('image/png')")
    raw = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(raw)).convert("RGB")).astype(int)


def _drawn(pixels) -> np.ndarray:
    """Where the picture is not the white background."""
    return np.any(pixels < 250, axis=2)


def _open(browser, result, path):
    write_html(result, path, title=path.stem)
    browser.get(path.as_uri())
    _wait(browser, lambda b: _ready(b) == "result", "the embedded 3D result")
    assert browser.execute_script("return !!V3.renderer"), "no WebGL in this browser"


def _drag(browser, dx, dy):
    from selenium.webdriver.common.action_chains import ActionChains

    canvas = browser.find_element("id", "view3d")
    ActionChains(browser).move_to_element(canvas).click_and_hold().move_by_offset(dx, dy) \
        .release().perform()


def _positions(browser) -> np.ndarray:
    """The nodes of the shape drawn now, in the result's coordinates."""
    pos, centre = browser.execute_script(
        "return [Array.from(V3.shape.geometry.attributes.position.array), V3.centre]")
    return np.reshape(pos, (-1, 3)) + centre


def test_a_surface_is_shaded_and_orbits(browser, surface_result, tmp_path, shots):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import Select

    _open(browser, surface_result, tmp_path / "surface.html")
    assert browser.execute_script("return V3.shape.type") == "Mesh"  # triangles, shaded
    assert browser.execute_script("return V3.shape.geometry.index.count") == \
        3 * len(surface_result.source.faces)
    assert browser.find_element(By.ID, "view").get_attribute("hidden") is not None
    first = _canvas(browser)
    assert _drawn(first).mean() > MIN_DRAWN
    # shaded: the plain blue surface shows many tones of it, not one flat colour
    blue = first[_drawn(first) & (first[..., 2] > first[..., 0] + 40)]
    assert len(np.unique(blue // 8, axis=0)) > 10
    browser.save_screenshot(str(shots / "report3d-surface.png"))

    _drag(browser, 160, 60)  # orbit
    turned = _canvas(browser)
    changed = np.any(np.abs(turned - first) > 30, axis=2)
    assert changed.sum() > MIN_CHANGED * _drawn(first).sum()
    browser.save_screenshot(str(shots / "report3d-orbited.png"))

    slider = browser.find_element(By.ID, "slider")
    slider.send_keys(Keys.END)
    last = surface_result.steps
    assert browser.execute_script("return V.step") == last
    assert_allclose(_positions(browser), surface_result.shapes[-1], atol=FLOAT32_ATOL)
    Select(browser.find_element(By.ID, "color-by")).select_by_value("energy")
    coloured = _canvas(browser)
    warm = coloured[_drawn(coloured) & (coloured[..., 0] > coloured[..., 2] + 40)]
    assert len(warm) > 100  # the energy scale's warm colours
    browser.save_screenshot(str(shots / "report3d-energy-last-step.png"))
    severe = [e["message"] for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe


def test_a_point_cloud_is_drawn_as_points(browser, cloud_result, tmp_path, shots):
    _open(browser, cloud_result, tmp_path / "cloud.html")
    assert browser.execute_script("return V3.shape.type") == "Points"
    assert_allclose(_positions(browser), cloud_result.shapes[0], atol=FLOAT32_ATOL)
    pixels = _canvas(browser)
    assert 0.001 < _drawn(pixels).mean() < MIN_DRAWN * 4  # dots, not a filled surface
    browser.save_screenshot(str(shots / "report3d-cloud.png"))
    _drag(browser, -120, 0)
    assert np.any(np.abs(_canvas(browser) - pixels) > 30)


def test_app_previews_a_mesh_and_keeps_an_uploads_refusal(browser, tmp_path, shots):
    """A refused source file's message stays when the target is chosen; an OFF surface
    uploaded to the app is previewed shaded."""
    from selenium.webdriver.common.by import By

    server = make_server("127.0.0.1", 0)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        bad = tmp_path / "two.csv"
        bad.write_text("x,y\n0,0\n1,1\n")
        p, f = sphere_mesh(120, np.random.default_rng(6))
        mesh = tmp_path / "ball.off"
        mesh.write_text(f"OFF\n{len(p)} {len(f)} 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in p)
                        + "".join(f"3 {a} {b} {c}\n" for a, b, c in f))
        browser.get(f"http://127.0.0.1:{server.server_address[1]}/")
        _wait(browser, lambda b: b.execute_script("return !!App.schema"), "the app's form")
        msg = browser.find_element(By.ID, "input-msg")
        browser.find_element(By.ID, "file-source").send_keys(str(bad))
        _wait(browser, lambda b: msg.text.startswith("source: two.csv"), "the refusal")
        browser.find_element(By.ID, "file-target").send_keys(str(mesh))
        _wait(browser, lambda b: _ready(b) == "preview", "the mesh previewed")
        assert msg.text.startswith("source: two.csv") and "error" in msg.get_attribute("class")
        assert browser.execute_script("return V3.shape.type") == "Mesh"
        assert _drawn(_canvas(browser)).mean() > MIN_DRAWN
        browser.save_screenshot(str(shots / "app3d-preview.png"))
    finally:
        server.shutdown()
        server.server_close()


def test_3d_figures_keep_the_z_label_clear_of_the_colour_bar(surface_result):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    from modalmorph import figures

    for color_by in ("energy", "load"):
        ax = figures.plot_shapes(surface_result, color_by=color_by)
        fig = ax.figure
        renderer = fig.canvas.get_renderer()
        fig.canvas.draw()
        z = ax.zaxis.label.get_window_extent(renderer)
        bar = next(a for a in fig.axes if a is not ax).get_tightbbox(renderer)
        assert z.x1 < bar.x0, (color_by, z, bar)  # left of the bar and its ticks
        assert fig.bbox.contains(z.x0, z.y0) and fig.bbox.contains(z.x1, z.y1)
    plt.close("all")
