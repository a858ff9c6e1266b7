"""Wall time of ``modalmorph morph`` on the command line against the library call.

For hands pairs (bundled hand 0 -> hand 3, resampled) of 70, 250 and 1000 nodes, prints
the best of ``--repeat`` runs of: the library call (``match`` then ``morph``, in this
process), the command line with its default outputs (results, figures, GIF) and with
``--no-figures`` (results and GIF), each a fresh ``python -m modalmorph`` process
(interpreter start and imports included), and their ratios to the library call. Then one
in-process run's split of the command line's time: computing, the results, the figures
(PNG, the default), the GIF.

    PYTHONPATH=src python benchmarks/cli.py [--repeat 3] [--nodes 70 250 1000]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from modalmorph import figures
from modalmorph.apps.runs import Settings, compute_morph
from modalmorph.core.shape import Shape, resample
from modalmorph.datasets import load_hand
from modalmorph.io import save_result

SRC = Path(__file__).resolve().parents[1] / "src"


def pair(n: int):
    return Shape(resample(load_hand(0), n)), Shape(resample(load_hand(3), n))


def best(run, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def command(files, out, *flags):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get(
        "PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-m", "modalmorph", "morph", *map(str, files),
                           "--out", str(out), "-q", *flags], env=env, capture_output=True,
                          text=True, check=False)
    if done.returncode not in (0, 3):  # 3: written, tolerance not reached
        raise RuntimeError(done.stderr)


def split(source, target, folder: Path) -> dict:
    """Seconds of each part of one in-process run with the default outputs."""
    settings = Settings()
    parts, start = {}, time.perf_counter()
    result = compute_morph(source, target, settings)
    parts["compute"], start = time.perf_counter() - start, time.perf_counter()
    save_result(result, folder, options=settings.record())
    parts["results"], start = time.perf_counter() - start, time.perf_counter()
    figures.save_figures(result, folder, formats=("png",))  # the command line's default
    parts["figures"], start = time.perf_counter() - start, time.perf_counter()
    figures.animate(result, folder / "morph.gif")
    parts["gif"] = time.perf_counter() - start
    parts["steps"] = result.steps
    return parts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--nodes", type=int, nargs="+", default=[70, 250, 1000])
    args = parser.parse_args()
    print(f"{'nodes':>6} {'steps':>5} {'library s':>10} {'default s':>10} {'ratio':>6} "
          f"{'no-figures s':>13} {'ratio':>6} | in-process: compute results figures gif")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for n in args.nodes:
            source, target = pair(n)
            files = []
            for name, shape in (("a.csv", source), ("b.csv", target)):
                np.savetxt(tmp / name, shape.points, delimiter=",", header="x,y",
                           comments="")
                files.append(tmp / name)
            library = best(lambda s=source, t=target: compute_morph(s, t, Settings()),
                           args.repeat)
            default = best(lambda f=files: command(f, tmp / "out"), args.repeat)
            plain = best(lambda f=files: command(f, tmp / "out", "--no-figures"),
                         args.repeat)
            parts = split(source, target, tmp / f"split{n}")
            print(f"{n:>6} {parts['steps']:>5} {library:>10.2f} {default:>10.2f} "
                  f"{default / library:>6.1f} {plain:>13.2f} {plain / library:>6.1f} | "
                  f"{parts['compute']:.2f} {parts['results']:.2f} {parts['figures']:.2f} "
                  f"{parts['gif']:.2f}", flush=True)


if __name__ == "__main__":
    main()
