"""The core needs numpy and scipy only: optional libraries are imported lazily."""

import subprocess
import sys

CODE = """
import sys
import modalmorph as mm
from modalmorph.datasets import load_heart
r = mm.morph(load_heart("diastole")[::3], load_heart("systole")[::3])
heavy = {"matplotlib", "skimage", "meshio", "PIL", "rich", "svgelements"} & set(sys.modules)
assert not heavy, heavy
print(r.steps)
"""


def test_core_imports_no_optional_library():
    done = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr
