"""Speed of the viewer (issue 12): first paint and scrubbing of a large result.

A result of ``--nodes`` nodes and ``--steps`` steps (a circle deforming into a flower,
with synthetic loads and energies: the viewer's cost depends on the sizes alone) is
written as a self-contained report and opened in headless Chromium. Printed: the HTML
size, the time from navigation to the first contentful paint and to the result drawn
(``document.body.dataset.ready``), and the time per frame while scrubbing through every
step (each step drawn in its own animation frame, so layout and paint are included),
for each colouring.

Run from the repository root: ``PYTHONPATH=src python benchmarks/app_viewer.py``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.support.ui import WebDriverWait

from modalmorph import Morph, Shape
from modalmorph.apps.report import write_html

SCRUB = """
const done = arguments[arguments.length - 1];
const T = V.data.shapes.length - 1; let k = 0; const t0 = performance.now();
function next() { setStep(k); if (++k <= T) requestAnimationFrame(next);
                  else requestAnimationFrame(() => done((performance.now() - t0) / (T + 1))); }
requestAnimationFrame(next);
"""


def result(m: int, steps: int) -> Morph:
    t = np.linspace(0, 2 * np.pi, m, endpoint=False)
    circle = np.c_[np.cos(t), np.sin(t)] * 100 + 200
    flower = np.c_[np.cos(t), np.sin(t)] * (100 + 25 * np.cos(5 * t))[:, None] + 200
    s = (1 - np.exp(-np.arange(steps + 1) / 20))[:, None, None]
    shapes = circle + s * (flower - circle)
    loads = 100 * (flower - shapes)
    e_node = np.abs(loads[..., 0]) * 1e-3 - 0.01
    pairs = np.c_[np.arange(0, m, 5), np.arange(0, m, 5)]
    return Morph(shapes=shapes, loads=loads, energy=e_node.sum(axis=1), node_energy=e_node,
                 mean_distance=np.linalg.norm(flower - shapes, axis=2).mean(axis=1),
                 matching=type("M", (), {"pairs": pairs})(), similarity=None, converged=True,
                 stop_reason="synthetic", source=Shape(circle), target=Shape(flower))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=100)
    args = ap.parse_args()
    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1440,960"):
        options.add_argument(arg)
    b = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    b.set_script_timeout(120)
    with tempfile.TemporaryDirectory() as tmp:
        path = write_html(result(args.nodes, args.steps), Path(tmp) / "report.html")
        b.get(path.as_uri())
        WebDriverWait(b, 60).until(
            lambda b: b.execute_script("return document.body.dataset.ready") == "result")
        paint, ready = b.execute_script(
            "return [performance.getEntriesByName('first-contentful-paint')[0].startTime,"
            " performance.now()]")
        print(f"{args.nodes} nodes, {args.steps} steps: report {path.stat().st_size / 1e6:.1f} MB"
              f", first contentful paint {paint:.0f} ms, result drawn by {ready:.0f} ms")
        idle = b.execute_async_script(SCRUB.replace("setStep(k);", ""))
        print(f"  animation frames doing nothing: {idle:.1f} ms per frame")
        for by in ("plain", "load", "energy"):
            b.execute_script(f"setColouring('{by}')")
            ms = b.execute_async_script(SCRUB)
            js = b.execute_script("const t0 = performance.now(); for (let k = 0; k <= V.data."
                                  "steps; k++) setStep(k); return (performance.now() - t0) / "
                                  "(V.data.steps + 1)")
            print(f"  scrubbing, colour {by:6s}: {ms:.1f} ms per frame ({js:.1f} ms in the "
                  f"script)")
    b.quit()


if __name__ == "__main__":
    main()
