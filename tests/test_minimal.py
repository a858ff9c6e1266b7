"""The plain install (``pip install .``, no extras): the core needs numpy and scipy only,
and the command line runs its main job with every reader, without the extras' libraries.

Each test runs a fresh interpreter in which the extras' modules cannot be imported (a
meta-path finder refuses them, as if they were not installed), so an import of one of
them anywhere in the path of a command fails the test.
"""

import subprocess
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
# The top-level modules of the extras (test, dask, bench): not there in a plain install.
EXTRAS = ("dask", "distributed", "pyarrow", "pytest", "hypothesis", "selenium", "pycpd")

BLOCK = f"""
import sys

class NotInstalled:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {EXTRAS!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, NotInstalled())
for name in list(sys.modules):
    if name.split(".")[0] in {EXTRAS!r}:
        del sys.modules[name]
"""


def _python(code: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCK + code], capture_output=True,
                          text=True, check=False, cwd=cwd,
                          env={"PYTHONPATH": str(SRC), "OPENBLAS_NUM_THREADS": "1",
                               "MPLBACKEND": "Agg", "PATH": "/usr/bin:/bin"})


CORE = """
import modalmorph as mm
from modalmorph.datasets import load_heart
r = mm.morph(load_heart("diastole")[::3], load_heart("systole")[::3])
heavy = {"matplotlib", "skimage", "meshio", "PIL", "rich", "svgelements"} & set(sys.modules)
assert not heavy, heavy
print(r.steps)
"""


def test_core_imports_no_optional_library(tmp_path):
    done = _python(CORE, tmp_path)
    assert done.returncode == 0, done.stderr


COMMANDS = """
import numpy as np
from PIL import Image
from modalmorph.apps.cli import main
from modalmorph.datasets import load_hand
from modalmorph.io import read_shape
from modalmorph.core.shape import resample

a, b = resample(load_hand(0), 60), resample(load_hand(3), 70)
np.savetxt("a.csv", a, delimiter=",", header="x,y", comments="")
np.savetxt("b.csv", b, delimiter=",", header="x,y", comments="")
assert main(["morph", "a.csv", "b.csv", "--out", "out", "-q"]) == 0
assert {"morph.gif", "shapes_energy.png", "result.json"} <= {p.name for p in
                                                               __import__("pathlib").Path("out").iterdir()}
np.save("a.npy", a)
open("a.json", "w").write(__import__("json").dumps(a.tolist()))
open("a.svg", "w").write('<svg xmlns="http://www.w3.org/2000/svg"><circle cx="50" cy="40" '
                         'r="20"/></svg>')
yy, xx = np.mgrid[:60, :80]
Image.fromarray((((xx - 40) / 25) ** 2 + ((yy - 30) / 15) ** 2 <= 1).astype(np.uint8)
                * 255).save("a.png")
t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
ring = np.c_[np.cos(t), np.sin(t), np.zeros_like(t)]
pts = np.vstack([ring, [[0, 0, 1], [0, 0, -1]]])
faces = [[i, (i + 1) % 12, 12] for i in range(12)] + [[(i + 1) % 12, i, 13] for i in range(12)]
open("a.ply", "w").write("ply\\nformat ascii 1.0\\nelement vertex 14\\nproperty float x\\n"
                         "property float y\\nproperty float z\\nelement face 24\\n"
                         "property list uchar int vertex_indices\\nend_header\\n"
                         + "".join(f"{x} {y} {z}\\n" for x, y, z in pts)
                         + "".join(f"3 {i} {j} {k}\\n" for i, j, k in faces))
for name in ("a.csv", "a.npy", "a.json", "a.svg", "a.png", "a.ply"):
    shape = read_shape(name)
    assert shape.m >= 14, (name, shape.m)
open("m.csv", "w").write("source,target\\na.csv,b.csv\\n")
assert main(["batch", "m.csv", "--out", "batch", "--workers", "1", "-q"]) == 0
extras = {name.split(".")[0] for name in sys.modules} & set({EXTRAS!r})
assert not extras, extras
""".replace("{EXTRAS!r}", repr(EXTRAS))


def test_command_line_and_every_reader_without_the_extras(tmp_path):
    done = _python(COMMANDS, tmp_path)
    assert done.returncode == 0, done.stderr
    # the batch ran on the local process pool (the default engine: needs no Dask)
    assert "Dask" not in done.stderr
