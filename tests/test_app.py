"""The web app and the self-contained HTML report, driven in a real headless browser.

The browser tests need Chromium and its driver (Debian: ``apt-get install chromium
chromium-driver``) and selenium; they are skipped, with the reason, when one is missing.
``MODALMORPH_CHROMIUM`` and ``MODALMORPH_CHROMEDRIVER`` point to other binaries.
"""

import http.client
import io
import json
import os
import re
import shutil
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from modalmorph import morph
from modalmorph.apps.app import MAX_UPLOAD, make_server, morph_options, parse_options
from modalmorph.apps.policy import APP_LIMITS
from modalmorph.apps.report import result_payload, write_html
from modalmorph.apps.runs import FORM_CLASSES
from modalmorph.datasets import heart_shape
from modalmorph.options import flat_fields

# Coordinates travel as JSON doubles and SVG attributes (shortest round-trip text):
# exact; the margin covers a different BLAS summation order between two runs.
COORD_ATOL = 1e-9
# The heart run the browser test makes: k and remove_rigid changed from their defaults.
HEART_OPTIONS = dict(k=50.0, remove_rigid=True)
WAIT = 60  # seconds: the longest wait for the page (the heart morph takes ~2 s)


# ------------------------------------------------------------------- without a browser


def test_form_is_generated_from_the_option_fields():
    names = [o["name"] for o in morph_options()]
    assert names == [name for name, _, _ in flat_fields(FORM_CLASSES)]
    assert {"method", "match_sigma", "k", "material", "remove_rigid"} <= set(names)
    spec = {o["name"]: o for o in morph_options()}
    assert spec["k"]["default_text"] == "100" and spec["k"]["default"] == 100.0
    assert spec["scheme"]["choices"] == ["implicit", "explicit"]
    assert spec["remove_rigid"]["kind"] == "bool" and spec["remove_rigid"]["default"] is False
    assert spec["material"]["kind"] == "text"
    assert spec["material"]["default_text"] == "polyethylene"
    assert spec["match_sigma"]["group"] == "matching"
    assert all(o["summary"] for o in morph_options())  # every option explains itself
    json.dumps(morph_options(), allow_nan=False)  # the schema the page fetches


def test_parse_options_reads_the_form():
    settings = parse_options({"k": "50", "damping": "0.5, 1", "modes": "2/3", "sigma": "",
                              "remove_rigid": True, "scheme": "explicit",
                              "material": "1e5 0.3 1000", "match_sigma": "1.5"})
    assert settings.morph.k == 50 and settings.morph.damping == (0.5, 1.0)
    assert settings.morph.modes == pytest.approx(2 / 3) and settings.morph.sigma is None
    assert settings.morph.remove_rigid and settings.morph.scheme == "explicit"
    assert settings.morph.material.E == 1e5 and settings.match.sigma == 1.5
    with pytest.raises(ValueError, match="k must be a number, got 'abc'"):
        parse_options({"k": "abc"})
    with pytest.raises(ValueError, match="unknown option 'kk'"):
        parse_options({"kk": "1"})
    with pytest.raises(ValueError, match="dt has the wrong type"):
        parse_options({"dt": "1 2"})


@pytest.fixture(scope="module")
def server():  # room for a run that is stopped to be still running then (see below)
    srv = make_server("127.0.0.1", 0, limits=replace(APP_LIMITS, max_steps=100_000,
                                                      max_node_steps=4_000_000))
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    yield srv
    srv.shutdown()
    srv.server_close()


def _request(server, method, path, body=b"", headers=None):
    """One request; a POST carries the session's token, as the app's page sends it."""
    conn = http.client.HTTPConnection(*server.server_address, timeout=30)
    headers = {**({"X-Modalmorph-Token": server.token} if method == "POST" else {}),
               **(headers or {})}
    try:
        conn.request(method, path, body=body, headers=headers)
        response = conn.getresponse()
        return response.status, json.loads(response.read() or b"null")
    finally:
        conn.close()


def _png(array) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.asarray(array, dtype=np.uint8)).save(buffer, "PNG")
    return buffer.getvalue()


def test_bad_uploads_get_a_message_and_the_server_survives(server):
    blank = _png(np.zeros((40, 40)))
    cases = [  # (file name, body, headers, status, message)
        ("noise.png", os.urandom(2000), {}, 400, "cannot read the image"),
        ("blank.png", blank, {}, 400, "no object in the image"),
        ("wide.csv", b"1,2,3,4,5\n6,7,8,9,10\n1,1,1,1,1\n", {}, 400, "columns"),
        ("one.csv", b"1\n2\n3\n", {}, 400, "column"),
        ("shape.exe", b"MZ", {}, 400, "unsupported file type"),
        ("huge.csv", b"", {"Content-Length": str(MAX_UPLOAD + 1)}, 413, "too large"),
    ]
    for i in range(100):
        name, body, headers, status, message = cases[i % len(cases)]
        if name == "huge.csv":  # a body as large as announced: read, then refused
            body = b"0" * (MAX_UPLOAD + 1)
        got, answer = _request(server, "POST", f"/api/upload?name={name}", body, headers)
        assert got == status, (name, answer)
        assert message in answer["error"], (name, answer)
    assert _request(server, "GET", "/api/schema")[0] == 200
    assert not any(Path(server.tmp.name).iterdir())  # every upload deleted once read


def _finish(server, job):
    for _ in range(600):
        status, state = _request(server, "GET", f"/api/job/{job}")
        if state["state"] not in ("queued", "running"):
            return state
        time.sleep(0.05)
    raise AssertionError(f"the run did not end: {state}")


def _run(server, source, target, options):
    status, answer = _request(server, "POST", "/api/run", json.dumps(
        {"source": source, "target": target, "options": options}).encode())
    assert status == 200, answer
    return answer["job"]


def test_upload_run_stop_and_download_over_http(server):
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    ids = []
    for name, r in (("circle.csv", 1.0), ("flower.csv", 1 + 0.2 * np.cos(3 * t))):
        csv = "x,y\n" + "\n".join(f"{x:.6f},{y:.6f}" for x, y in np.c_[r * np.cos(t),
                                                                       r * np.sin(t)])
        status, shape = _request(server, "POST", f"/api/upload?name={name}", csv.encode())
        assert status == 200 and len(shape["points"]) == 40 and shape["closed"]
        ids.append(shape["id"])

    status, answer = _request(server, "POST", "/api/run", json.dumps(
        {"source": ids[0], "target": ids[1], "options": {"k": "-1"}}).encode())
    assert status == 400 and answer["field"] == "k"  # refused before any run
    assert answer["error"].startswith("options: k must be a number in [1e-06, 1e+06]")

    # Stop: a run that would take 100 000 steps ends at the next step (5000 steps of 40
    # nodes end in 0.3-0.6 s, before a loaded machine's test thread stopped them)
    job = _run(server, *ids, {"k": "0.01", "dt": "0.001", "max_steps": "100000",
                              "equilibrium_tol": "0"})
    for _ in range(600):
        if _request(server, "GET", f"/api/job/{job}")[1]["step"] > 0:
            break
        time.sleep(0.05)
    _request(server, "POST", f"/api/job/{job}/stop", b"{}")
    state = _finish(server, job)
    assert state["state"] == "error" and state["error"].startswith("stopped by the user")

    job = _run(server, *ids, {"remove_rigid": True})
    assert _finish(server, job)["state"] == "done"
    conn = http.client.HTTPConnection(*server.server_address, timeout=60)
    files = {}
    for name in ("result.json", "shapes.npz", "final_shape.csv", "report.html",
                 "matches.png"):
        conn.request("GET", f"/api/job/{job}/file/{name}")
        response = conn.getresponse()
        files[name] = response.read()
        assert response.status == 200, name
        assert name in response.getheader("Content-Disposition")
    conn.close()
    summary = json.loads(files["result.json"])
    shapes = np.load(io.BytesIO(files["shapes.npz"]))["shapes"]
    assert shapes.shape == (summary["steps"] + 1, 40, 2)
    assert files["matches.png"].startswith(b"\x89PNG")
    assert b'id="mm-data"' in files["report.html"]
    assert _request(server, "GET", f"/api/job/{job}/file/../../etc/passwd")[0] == 404


def test_foreign_host_is_refused(server):
    status, answer = _request(server, "GET", "/api/schema", headers={"Host": "evil.example"})
    assert status == 403 and "Host" in answer["error"]


def test_payload_of_a_morph_is_strict_json(hearts):
    result = morph(*hearts, max_steps=3)
    payload = result_payload(result)
    text = json.dumps(payload, allow_nan=False)
    back = json.loads(text)
    assert_allclose(back["shapes"], result.shapes, rtol=0, atol=0)  # doubles round-trip
    assert back["steps"] == result.steps and len(back["energy"]) == result.steps + 1
    # one distance: the stop test's, as result.json and the status line say
    assert (back["distance"], back["tolerance"]) == (result.distance, result.tolerance)


# ------------------------------------------------------------------------ in a browser


def _browser_or_skip(download_dir: Path):
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
    from selenium.webdriver.chrome.service import Service

    chromium = os.environ.get("MODALMORPH_CHROMIUM") or shutil.which("chromium") \
        or shutil.which("chromium-browser") or shutil.which("google-chrome")
    driver = os.environ.get("MODALMORPH_CHROMEDRIVER") or shutil.which("chromedriver")
    if not chromium or not driver:
        pytest.skip("no headless browser: install chromium and chromium-driver "
                    "(apt-get install chromium chromium-driver)")
    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    # WebGL (the 3D view) without a GPU: SwiftShader, which Chromium wants asked for
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1400,1000",
                "--disable-dev-shm-usage", "--enable-unsafe-swiftshader"):
        options.add_argument(arg)
    options.add_experimental_option("prefs", {"download.default_directory": str(download_dir),
                                              "download.prompt_for_download": False})
    browser = webdriver.Chrome(service=Service(driver), options=options)
    browser.execute_cdp_cmd("Page.setDownloadBehavior",
                            {"behavior": "allow", "downloadPath": str(download_dir)})
    return browser


@pytest.fixture(scope="module")
def downloads(tmp_path_factory):
    return tmp_path_factory.mktemp("downloads")


@pytest.fixture(scope="module")
def browser(downloads):
    browser = _browser_or_skip(downloads)
    yield browser
    browser.quit()


@pytest.fixture(scope="module")
def heart_result():
    return morph(heart_shape("diastole"), heart_shape("systole"), **HEART_OPTIONS)


def _wait(browser, condition, what: str):
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(browser, WAIT).until(lambda b: condition(b), message=what)


def _ready(browser):
    return browser.execute_script("return document.body.dataset.ready")


def _drawn_shape(browser, selector="#view .shape") -> np.ndarray:
    """The nodes of the shape drawn now (the path ``M x y L x y ... Z``, one ``M ... Z``
    per contour)."""
    return np.vstack(_drawn_loops(browser, selector))


def _drawn_loops(browser, selector) -> list:
    """The nodes of each subpath (contour) of a drawn path, in order."""
    d = browser.execute_script(f"return document.querySelector('{selector}').getAttribute('d')")
    return [np.array([[float(v) for v in p.split()] for p in re.split("[LZ]", sub) if p])
            for sub in d.split("M") if sub.strip()]


def _to_last_step(browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    slider = browser.find_element(By.ID, "slider")
    slider.send_keys(Keys.END)  # the keyboard, as a user scrubs
    last = int(slider.get_attribute("max"))
    assert browser.execute_script("return +document.querySelector('#view').dataset.step") == last
    return last


def _check_colouring(browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    def strokes():  # the colours of the paths drawn
        return set(browser.execute_script(
            "return [...document.querySelectorAll('#view .edges path')].filter(p => "
            "p.getAttribute('visibility') !== 'hidden' && p.getAttribute('d'))"
            ".map(p => p.getAttribute('stroke'))"))

    assert strokes() == {"#1f5fa8"}  # plain: one colour
    Select(browser.find_element(By.ID, "color-by")).select_by_value("energy")
    assert len(strokes()) > 2 and "#1f5fa8" not in strokes()  # by local energy: a scale
    assert "energy" in browser.find_element(By.CSS_SELECTOR, "#colorbar .title").text
    Select(browser.find_element(By.ID, "color-by")).select_by_value("load")
    assert "load" in browser.find_element(By.CSS_SELECTOR, "#colorbar .title").text
    assert len(strokes()) > 2 and "#1f5fa8" not in strokes()


def _download_json(browser, downloads: Path, name: str) -> dict:
    from selenium.webdriver.common.by import By

    target = downloads / name
    target.unlink(missing_ok=True)
    browser.find_element(By.CSS_SELECTOR, '#downloads [data-get="json"]').click()
    _wait(browser, lambda b: target.exists() and target.stat().st_size > 0, f"{name} download")
    time.sleep(0.2)  # Chrome renames the finished .crdownload onto the name
    return json.loads(target.read_text())


def _compare_with_library(data: dict, result):
    assert data["steps"] == result.steps
    assert_allclose(np.array(data["shapes"]), result.shapes, atol=COORD_ATOL, rtol=0)
    assert_allclose(data["energy"], result.energy, rtol=1e-9, atol=1e-12)
    assert_allclose(data["mean_distance"], result.mean_distance, rtol=1e-9)
    assert data["pairs"] == result.matching.pairs.tolist()
    assert data["stop_reason"] == result.message


def test_app_in_browser(server, browser, downloads, heart_result, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    url = f"http://127.0.0.1:{server.server_address[1]}/"
    browser.get(url)
    _wait(browser, lambda b: len(b.find_elements(By.CSS_SELECTOR, "#example option")) > 1,
          "the examples list")
    Select(browser.find_element(By.ID, "example")).select_by_value("heart")
    _wait(browser, lambda b: _ready(b) == "preview", "the heart drawn")

    # an invalid value: the library's own message, the field marked
    k = browser.find_element(By.ID, "opt-k")
    k.clear()
    k.send_keys("-3")
    browser.find_element(By.ID, "run").click()
    _wait(browser, lambda b: _ready(b) == "error", "the refusal")
    assert browser.find_element(By.ID, "run-msg").text.startswith(
        "options: k must be a number in [1e-06, 1e+06]")
    assert "invalid" in browser.find_element(
        By.CSS_SELECTOR, '.field[data-name="k"]').get_attribute("class")
    refused = browser.get_log("browser")  # the 400 answer is the only entry
    assert len(refused) == 1 and "api/run" in refused[0]["message"], refused

    k.clear()
    k.send_keys(str(HEART_OPTIONS["k"]))
    rigid = browser.find_element(By.ID, "opt-remove_rigid")
    browser.execute_script("arguments[0].scrollIntoView({block: 'center'})", rigid)
    rigid.click()
    browser.find_element(By.ID, "run").click()
    _wait(browser, lambda b: _ready(b) == "result", "the morph's result")
    assert browser.find_element(By.ID, "run-msg").text == heart_result.message

    last = _to_last_step(browser)
    assert last == heart_result.steps
    assert_allclose(_drawn_shape(browser), heart_result.shapes[-1], atol=COORD_ATOL, rtol=0)
    _check_colouring(browser)
    _compare_with_library(_download_json(browser, downloads, "morph.json"), heart_result)

    # a grey PNG needs a threshold; with one it is read and drawn over the image
    yy, xx = np.mgrid[:80, :100]
    grey = 40 + 150 * (((xx - 50) / 30) ** 2 + ((yy - 40) / 20) ** 2 < 1) + (xx % 7)
    path = tmp_path / "ellipse.png"
    path.write_bytes(_png(grey))
    browser.find_element(By.ID, "file-source").send_keys(str(path))
    _wait(browser, lambda b: "pass a threshold" in b.find_element(By.ID, "input-msg").text,
          "the threshold message")
    browser.find_element(By.ID, "threshold").send_keys("120\t")
    _wait(browser, lambda b: b.find_elements(By.CSS_SELECTOR, "#view .bg image"),
          "the image under the contour")
    assert "error" not in browser.find_element(By.ID, "input-msg").get_attribute("class"), \
        browser.find_element(By.ID, "input-msg").text
    outline = _drawn_shape(browser, "#view .source")
    assert_allclose(outline.mean(axis=0), [51, 39.5], atol=1.0)  # the ellipse's centre
    # no script error (the refused upload's 400 is logged as a network entry)
    assert not [e for e in browser.get_log("browser") if e["source"] != "network"]


def test_report_in_browser(browser, downloads, heart_result, tmp_path):
    path = write_html(heart_result, tmp_path / "report.html", title="heart")
    text = path.read_text().replace("http://www.w3.org/2000/svg", "").replace(
        "http://www.w3.org/1999/xhtml", "")  # names, not fetches
    assert "http://" not in text and "https://" not in text  # no network
    browser.get(path.as_uri())
    _wait(browser, lambda b: _ready(b) == "result", "the embedded result")
    assert _to_last_step(browser) == heart_result.steps
    assert_allclose(_drawn_shape(browser), heart_result.shapes[-1], atol=COORD_ATOL, rtol=0)
    _check_colouring(browser)
    _compare_with_library(_download_json(browser, downloads, "morph.json"), heart_result)
    assert not browser.get_log("browser")


def test_morph_html_flag_writes_the_report(tmp_path, hearts):
    from modalmorph.apps.cli import main

    for name, points in zip(("a.csv", "b.csv"), hearts, strict=True):
        np.savetxt(tmp_path / name, points, delimiter=",", header="x,y", comments="")
    out = tmp_path / "out"
    assert main(["morph", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "--out", str(out),
                 "--html", "--no-figures", "--no-gif", "--max-steps", "3", "-q"]) == 3
    text = (out / "report.html").read_text()
    data = json.loads(re.search(r'id="mm-data" type="application/json">(.*?)</script>',
                                text).group(1))
    assert data["steps"] == 3 and data["title"] == "a.csv → b.csv"


def test_track_report_plays_the_frames(browser, hearts, tmp_path):
    from modalmorph import track

    heart = hearts[0]
    centre = heart.mean(axis=0)
    frames = [centre + (heart - centre) * s for s in (1.0, 0.9, 0.8)]
    result = track(frames)
    path = write_html(result, tmp_path / "track.html")
    browser.get(path.as_uri())
    _wait(browser, lambda b: _ready(b) == "result", "the embedded track")
    assert _to_last_step(browser) == 2
    assert_allclose(_drawn_shape(browser), result.points[-1], atol=COORD_ATOL, rtol=0)
    drawn_target = _drawn_shape(browser, "#view .target")
    assert_allclose(drawn_target, result.frames[-1].points, atol=COORD_ATOL)  # frame 2
    assert "frame 2 / 2" in browser.find_element("id", "step-label").text


def test_report_draws_each_contour_as_its_own_loop(browser, tmp_path):
    from modalmorph.io.images import mask_shape

    rows, cols = np.indices((100, 100))
    r = np.hypot(cols - 50.0, rows - 45.0)
    source = mask_shape((r <= 30) & (r > 15), "ring", nodes=60)  # outline, then its hole
    centre = source.points.mean(axis=0)
    target = source.with_points(centre + (source.points - centre) * 1.1)
    pairs = np.c_[np.arange(source.m), np.arange(source.m)]
    result = morph(source, target, matching=pairs, max_steps=6)
    payload = result_payload(result)
    assert payload["source_contours"] == payload["target_contours"] == list(source.contours)
    browser.get(write_html(result, tmp_path / "ring.html").as_uri())
    _wait(browser, lambda b: _ready(b) == "result", "the embedded ring")
    _to_last_step(browser)
    for selector, points in (("#view .shape", result.shapes[-1]),
                             ("#view .source", source.points),
                             ("#view .target", target.points)):
        loops = _drawn_loops(browser, selector)  # one subpath per contour: no bridge
        assert [len(p) for p in loops] == list(source.contours), selector
        assert_allclose(np.vstack(loops), points, atol=COORD_ATOL, rtol=0)
    assert not browser.get_log("browser")


def test_payload_says_which_way_y_points(heart_result):
    """Shapes from images are drawn y down by the viewer; bare coordinates y up."""
    assert result_payload(heart_result)["y_up"] is False  # the bundled heart, in pixels
    bare = morph(np.asarray(heart_result.source.points), np.asarray(heart_result.target.points),
                 max_steps=1)
    assert result_payload(bare)["y_up"] is True


def test_report_with_hostile_names_renders(browser, heart_result, tmp_path):
    """A file named ``<!--<script>.csv`` blanked the report: the inlined JSON is escaped."""
    title = "<!--<script>.csv → <img src=x onerror=window.mmOwned=1>&amp;</script>.csv"
    path = write_html(heart_result, tmp_path / "hostile.html", title=title)
    browser.get(path.as_uri())
    _wait(browser, lambda b: _ready(b) == "result", "the report despite the names")
    assert browser.find_element("id", "title").text == title  # shown as text
    assert browser.execute_script("return window.mmOwned") is None  # nothing ran
    assert _to_last_step(browser) == heart_result.steps
