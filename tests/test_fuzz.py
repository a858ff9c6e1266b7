"""Fuzzing: malformed files through every reader and the command line, killed runs, and
hypothesis over the public API.

The default hypothesis profile is small (CI: a few hundred API examples, a sample of the
file corpus through the command line). The long profile runs >= 10 000 API examples::

    PYTHONPATH=src python -m pytest tests/test_fuzz.py --hypothesis-profile=long
    MODALMORPH_FUZZ=long PYTHONPATH=src python -m pytest tests/test_fuzz.py
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from modalmorph.cli import main
from modalmorph.io import read_shape

from .fuzz_corpus import CONTOUR, write_corpus, write_good_csv

SRC = Path(__file__).parents[1] / "src"
LONG = os.environ.get("MODALMORPH_FUZZ") == "long"


def _env(**extra):
    """Environment for a child ``python -m modalmorph.cli``: this checkout's sources first
    (the package need not be installed), one BLAS thread, no display."""
    path = os.pathsep.join(p for p in (str(SRC), os.environ.get("PYTHONPATH")) if p)
    return dict(os.environ, PYTHONPATH=path, OPENBLAS_NUM_THREADS="1", MPLBACKEND="Agg",
                **extra)


# -- the corpus of malformed files ------------------------------------------------------


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return write_corpus(tmp_path_factory.mktemp("corpus"))


def test_corpus_covers_every_extension(corpus):
    from modalmorph.io import SUPPORTED_EXTENSIONS

    found = {p.suffix for p in corpus}
    assert found >= set(SUPPORTED_EXTENSIONS) - {".jpeg", ".tiff"}  # aliases of .jpg, .tif
    assert len(corpus) >= 500


def test_read_shape_on_the_corpus_raises_only_named_value_errors(corpus):
    outcomes = {"ok": 0, "refused": 0}
    for path in corpus:
        try:
            shape = read_shape(path)
        except ValueError as exc:
            assert str(exc).startswith(f"{path}: "), str(exc)
            assert "\n" not in str(exc)
            outcomes["refused"] += 1
        else:
            assert np.isfinite(shape.points).all()
            outcomes["ok"] += 1
    assert outcomes["refused"] > 400 and outcomes["ok"] > 50  # both kinds exercised


@pytest.mark.parametrize("name, message", [
    ("off_only.off", "not an OFF file"),
    ("ply_only.ply", "not a PLY file"),
    ("ansys_truncated.msh", "truncated ANSYS"),
    ("absurd_counts.off", "announces 999999999999 vertices"),
    ("absurd_count.ply", "announces 999999999999 elements"),
    ("scalar.npy", r"shape \(m, 2\) or \(m, 3\), got a scalar"),
    ("one_column.npy", r"got shape \(12, 1\)"),
    ("big_int.json", "an integer of 401 digits"),
    ("deep.json", "nested too deeply"),
    ("half.npz", "cannot read it as a .npz file"),
    ("html.svg", "not an SVG file"),
    ("float_nan.tif", "non-finite"),
    ("faces_2d.json", "has triangles but 2D points"),
    ("faces_2d_points.npz", "has triangles but 2D points"),
])
def test_named_problems(corpus, name, message):
    path = next(p for p in corpus if p.name == name)
    with pytest.raises(ValueError, match=f"^{path}: .*{message}"):
        read_shape(path)


@pytest.mark.parametrize("name", ["no_faces.off", "no_faces.ply", "points_only.vtk"])
def test_mesh_without_faces_is_a_point_cloud(corpus, name):
    shape = read_shape(next(p for p in corpus if p.name == name))
    assert shape.dim == 3 and shape.faces is None and not shape.ordered


def test_stuck_reader_is_stopped(tmp_path, monkeypatch):
    import modalmorph.io as io_module

    def spin(path, name, ext, threshold):
        while True:
            pass

    monkeypatch.setattr(io_module, "_read_file", spin)
    monkeypatch.setattr(io_module, "READ_SECONDS", 0.2)
    path = tmp_path / "a.csv"
    path.write_text("1,2\n")
    with pytest.raises(ValueError, match=f"^{path}: cannot read it: the reader did not "):
        read_shape(path)


# A sample of the corpus through the whole command line, in-process: every kind of file
# that reads (morphs run to the end) and a spread of those that do not.
_CLI_SAMPLE = ("base.csv", "tiny.csv", "huge_coords.npy", "no_faces.off", "faces_2d.json",
               "base.png", "base.svg", "off_only.off", "deep.json", "cut50.npz", "html.svg",
               "float_nan.tif", "ansys_truncated.msh", "random.ply", "scalar.npy")


@pytest.mark.parametrize("name", _CLI_SAMPLE)
def test_cli_on_corpus_files(corpus, tmp_path, capsys, monkeypatch, name):
    monkeypatch.chdir(tmp_path)
    good = write_good_csv(tmp_path / "good.csv")
    path = next(p for p in corpus if p.name == name)
    code = main(["morph", str(path), str(good), "--out", "X", "-q", "--no-gif"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code in (0, 2)
    if code == 2:
        assert len(err) == 1 and err[0].startswith("modalmorph: error: ")
        assert sorted(p.name for p in tmp_path.iterdir()) == ["good.csv"]
    else:
        assert sorted(p.name for p in tmp_path.iterdir()) == ["X", "good.csv"]
        assert (tmp_path / "X" / "result.json").is_file()


# -- killed runs ------------------------------------------------------------------------


def _check_output(folder: Path, ks: set) -> None:
    """The folder is one complete run's output, not a mixture of two."""
    names = sorted(p.name for p in folder.iterdir())
    assert names == ["final_shape.csv", "result.json", "shapes.npz"], names
    params = json.loads((folder / "result.json").read_text())["parameters"]
    assert params["k"] in ks
    with np.load(folder / "shapes.npz") as data:
        last = data["shapes"][-1]
    np.testing.assert_array_equal(np.loadtxt(folder / "final_shape.csv", delimiter=",",
                                             skiprows=1), last)


def test_killed_runs_leave_the_output_complete_or_absent(tmp_path):
    """SIGKILL a morph at ten moments; the output is always whole, and the next run removes
    the temporary folders killed runs left."""
    source = tmp_path / "source.csv"
    source.write_bytes(b"x,y\n" + b"".join(f"{x!r},{y!r}\n".encode() for x, y in CONTOUR.tolist()))
    write_good_csv(tmp_path / "target.csv")

    def start(k, out, **env):
        return subprocess.Popen(
            [sys.executable, "-m", "modalmorph.cli", "morph", "source.csv", "target.csv",
             "--out", out, "--k", str(k), "--no-figures", "--no-gif", "-q"],
            cwd=tmp_path, env=_env(**env), stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL)

    def temporaries():
        return [p for p in tmp_path.iterdir() if ".modalmorph-tmp-" in p.name]

    def wait_for_pause(proc):
        """Until the run is held just before its final rename (all files written)."""
        while proc.poll() is None:
            if any((t / "final_shape.csv").exists() for t in temporaries()):
                time.sleep(0.3)
                return
            time.sleep(0.02)

    assert start(50, "X").wait(timeout=120) == 0
    ks = {50}
    # Eight moments in time after the start (reading, matching, integrating, writing) and
    # two held just before the final rename: replacing X, and creating a new Y.
    moments = [0.05, 0.3, 0.6, 0.9, 1.2, 1.6, 2.0, 3.0, "X", "Y"]
    for i, moment in enumerate(moments):
        k = 60 + i
        ks.add(k)
        out = moment if isinstance(moment, str) else "X"
        held = isinstance(moment, str)
        proc = start(k, out, **({"MODALMORPH_TEST_RENAME_PAUSE": "60"} if held else {}))
        if held:
            wait_for_pause(proc)
        else:
            time.sleep(moment)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
        for folder in (tmp_path / "X", tmp_path / "Y"):
            if folder.exists():
                _check_output(folder, ks)
    assert (tmp_path / "X").exists() and not (tmp_path / "Y").exists()
    assert temporaries()  # at least the runs held before their rename left one

    assert start(99, "X").wait(timeout=120) == 0  # the next run cleans up
    _check_output(tmp_path / "X", {99})
    assert not temporaries()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["X", "source.csv", "target.csv"]


def test_unwritable_out_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    good = write_good_csv(tmp_path / "good.csv")
    (tmp_path / "file").write_text("")
    code = main(["morph", "missing.csv", str(good), "--out", "file/X"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    # named for --out, not the missing input: --out is checked before anything is read
    assert err[0].startswith("modalmorph: error: file/X: cannot create the folder")
