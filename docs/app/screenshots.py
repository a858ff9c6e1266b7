"""Screenshots of every view of the app and the report, taken in headless Chromium.

Run from the repository root: ``PYTHONPATH=src python docs/app/screenshots.py``. Needs
selenium, chromium and chromium-driver. Writes docs/app/*.png.
"""

import tempfile
import threading
from pathlib import Path

import numpy as np
from PIL import Image
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import Select, WebDriverWait

from modalmorph import morph
from modalmorph.apps.app import make_server
from modalmorph.apps.report import write_html
from modalmorph.datasets import hand_shape

OUT = Path(__file__).parent

server = make_server("127.0.0.1", 0)
threading.Thread(target=server.serve_forever, daemon=True).start()
options = webdriver.ChromeOptions()
options.binary_location = "/usr/bin/chromium"
for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1440,960"):
    options.add_argument(arg)
b = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
wait = WebDriverWait(b, 120)


def ready(state):
    wait.until(lambda b: b.execute_script("return document.body.dataset.ready") == state)


def shot(name):
    b.save_screenshot(str(OUT / f"{name}.png"))
    print("wrote", OUT / f"{name}.png")


b.get(f"http://127.0.0.1:{server.server_address[1]}/")
wait.until(lambda b: len(b.find_elements(By.CSS_SELECTOR, "#example option")) > 1)
shot("01-start")
Select(b.find_element(By.ID, "example")).select_by_value("heart")
ready("preview")
shot("02-heart-inputs")
k = b.find_element(By.ID, "opt-k")
k.clear()
k.send_keys("-3")
b.find_element(By.ID, "run").click()
ready("error")
shot("03-invalid-value")
k.clear()
k.send_keys("100")
b.find_element(By.ID, "run").click()
ready("result")
b.find_element(By.ID, "slider").send_keys(Keys.END)
shot("04-result-plain")
Select(b.find_element(By.ID, "color-by")).select_by_value("energy")
b.find_element(By.ID, "slider").send_keys(Keys.HOME)
for _ in range(4):
    b.find_element(By.ID, "slider").send_keys(Keys.RIGHT)
b.find_element(By.ID, "show-matches").click()
shot("05-energy-matches")
b.find_element(By.ID, "show-matches").click()
Select(b.find_element(By.ID, "color-by")).select_by_value("load")
b.find_element(By.ID, "scale-step").click()
box = b.find_element(By.ID, "view").rect
hover = b.execute_script("const p = V.data.shapes[V.step][40], "
                         "m = document.querySelector('#view .scene').getScreenCTM(); "
                         "return [p[0] * m.a + m.e, p[1] * m.d + m.f]")
ActionChains(b).move_to_element_with_offset(b.find_element(By.ID, "view"),
                                            hover[0] - box["x"] - box["width"] / 2,
                                            hover[1] - box["y"] - box["height"] / 2).perform()
shot("06-load-hover")
b.find_element(By.ID, "scale-step").click()

with tempfile.TemporaryDirectory() as tmp:  # a grey image: threshold, then the overlay
    yy, xx = np.mgrid[:240, :320]
    blob = ((xx - 160) / 90) ** 2 + ((yy - 120) / (60 + 15 * np.sin(xx / 25))) ** 2 < 1
    grey = (60 + 140 * blob + 20 * np.random.default_rng(1).random(blob.shape)).astype(np.uint8)
    Image.fromarray(grey).save(Path(tmp) / "cell.png")
    Select(b.find_element(By.ID, "example")).select_by_value("")
    b.find_element(By.ID, "file-source").send_keys(str(Path(tmp) / "cell.png"))
    wait.until(lambda b: "threshold" in b.find_element(By.ID, "input-msg").text)
    shot("07-grey-image-needs-threshold")
    b.find_element(By.ID, "threshold").send_keys("140\t")
    wait.until(lambda b: b.find_elements(By.CSS_SELECTOR, "#view .bg image"))
    shot("08-image-with-threshold")

    hands = morph(hand_shape(0, 120), hand_shape(3, 140))
    report = write_html(hands, Path(tmp) / "report.html", title="hands: hand 0 -> hand 3")
    b.get(report.as_uri())
    ready("result")
    Select(b.find_element(By.ID, "color-by")).select_by_value("energy")
    b.find_element(By.ID, "slider").send_keys(Keys.END)
    shot("09-report-hands")
b.quit()
server.shutdown()
