"""The command line end to end: real files in, results out, bad input -> exit 2."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from modalmorph.cli import main
from modalmorph.datasets import load_hand
from modalmorph.shape import resample


def _csv(path, points, header=True):
    np.savetxt(path, points, delimiter=",", header="x,y,z"[: 2 * points.shape[1] - 1]
               if header else "", comments="")
    return path


def _mask(path, centre, radii, size=(160, 200)):
    from PIL import Image

    yy, xx = np.mgrid[: size[0], : size[1]]
    inside = ((xx - centre[0]) / radii[0]) ** 2 + ((yy - centre[1]) / radii[1]) ** 2 <= 1
    inside |= (np.abs(xx - centre[0]) < radii[0] / 3) & (yy > centre[1])  # a "stem"
    inside &= yy < size[0] - 10
    Image.fromarray((inside * 255).astype(np.uint8)).save(path)
    return path


@pytest.fixture
def hand_csvs(tmp_path):
    a = _csv(tmp_path / "a.csv", resample(load_hand(0), 80))
    b = _csv(tmp_path / "b.csv", resample(load_hand(3), 90))
    return a, b


def _run(*argv):
    return main([str(a) for a in argv])


def test_version(capsys):
    assert _run("--version") == 0
    assert "modalmorph" in capsys.readouterr().out


def test_morph_csv_pair(hand_csvs, tmp_path, capsys):
    out = tmp_path / "out"
    assert _run("morph", *hand_csvs, "--out", out, "--no-figures", "--no-gif") == 0
    result = json.loads((out / "result.json").read_text())
    assert result["converged"] is True and result["steps"] == len(result["energy"]) - 1
    assert result["parameters"]["k"] == 100.0 and result["matches"] > 40
    with np.load(out / "shapes.npz") as npz:
        assert npz["shapes"].shape == (result["steps"] + 1, 80, 2)
    final = np.loadtxt(out / "final_shape.csv", delimiter=",", skiprows=1)
    assert final.shape == (80, 2)
    assert "wrote" in capsys.readouterr().out


def test_morph_options_and_config(hand_csvs, tmp_path):
    config = tmp_path / "opts.toml"
    config.write_text('k = 60\nremove_rigid = true\ndamping = [1.0, 1.0]\nmodes = "2/3"\n')
    out = tmp_path / "out"
    code = _run("morph", *hand_csvs, "--out", out, "--config", config, "--k", "80",
                "--no-figures", "--no-gif", "-q")
    assert code == 0
    params = json.loads((out / "result.json").read_text())["parameters"]
    assert params["k"] == 80  # the command line wins over the file
    assert params["remove_rigid"] is True and params["damping"] == [1.0, 1.0]
    assert params["modes"] == round(2 / 3 * 160)


def test_morph_with_figures_gif_and_vtk(hand_csvs, tmp_path):
    out = tmp_path / "out"
    assert _run("morph", *hand_csvs, "--out", out, "--vtk", "-q") == 0
    for name in ("matches.png", "shapes_energy.svg", "energy.png", "morph.gif",
                 "vtk/morph.pvd"):
        assert (out / name).stat().st_size > 0, name
    assert not list(tmp_path.glob(".out.*"))  # no temporary folder left behind


def test_match_command(hand_csvs, tmp_path):
    pairs = tmp_path / "pairs.csv"
    assert _run("match", *hand_csvs, "--out", pairs, "--method", "global", "-q") == 0
    table = np.loadtxt(pairs, delimiter=",", skiprows=1)
    assert table.shape[1] == 3 and len(table) > 40


def test_png_masks(tmp_path):
    a = _mask(tmp_path / "a.png", (90, 70), (50, 35))
    b = _mask(tmp_path / "b.png", (100, 75), (40, 45))
    out = tmp_path / "out"
    assert _run("morph", a, b, "--nodes", "80", "--out", out, "--no-figures", "--no-gif",
                "-q") == 0
    assert json.loads((out / "result.json").read_text())["source_nodes"] == 80


def test_grey_image_with_threshold(tmp_path):
    from PIL import Image

    a = _mask(tmp_path / "m.png", (90, 70), (50, 35))
    grey = np.asarray(Image.open(a), dtype=float) * 0.5 + 40  # object 167, background 40
    Image.fromarray(grey.astype(np.uint8)).save(tmp_path / "grey.png")
    out = tmp_path / "out"
    code = _run("morph", tmp_path / "grey.png", a, "--threshold", "100", "--nodes", "60",
                "--out", out, "--no-figures", "--no-gif", "-q")
    assert code == 0


def test_svg_pair(tmp_path):
    def svg(path, rx, ry):
        path.write_text(
            '<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">'
            f'<path d="M {100 - rx} 100 A {rx} {ry} 0 1 0 {100 + rx} 100 '
            f'C {100 + rx} 60, 130 {100 - ry}, 100 {100 - ry} '
            f'S {100 - rx} 60, {100 - rx} 100 Z"/></svg>')
        return path

    out = tmp_path / "out"
    code = _run("morph", svg(tmp_path / "a.svg", 60, 40), svg(tmp_path / "b.svg", 50, 55),
                "--nodes", "70", "--out", out, "--no-figures", "--no-gif", "-q")
    assert code == 0


def test_mesh_pair(tmp_path):
    meshio = pytest.importorskip("meshio")
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(5)
    u = rng.standard_normal((120, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    faces = ConvexHull(u).simplices
    # an egg with a bump: no symmetry, so the correspondence is well defined
    p = u * [1.6, 1.0, 0.6] + 0.4 * np.exp(-8 * np.sum((u - [0.6, 0.6, 0.5]) ** 2, axis=1,
                                                       keepdims=True))
    q = p * [1.1, 0.9, 1.0] + 0.05 * p**2
    meshio.write_points_cells(tmp_path / "a.ply", p, [("triangle", faces)])
    meshio.write_points_cells(tmp_path / "b.stl", q, [("triangle", faces)])
    out = tmp_path / "out"
    assert _run("morph", tmp_path / "a.ply", tmp_path / "b.stl", "--out", out,
                "--no-gif", "-q") == 0
    result = json.loads((out / "result.json").read_text())
    assert result["dim"] == 3 and result["converged"]


@pytest.mark.parametrize(
    "content, match",
    [
        (None, "no such file"),
        ("", "empty"),
        ("x,y\n1,2\n3,abc\n5,6\n", "line 3"),
        ("x,y\n1,2\nnan,4\n5,6\n", "NaN|non-finite"),
        ("x,y\n1,2\n", "at least 3 nodes|1 node"),
    ],
)
def test_bad_csv_exits_2(tmp_path, hand_csvs, capsys, content, match):
    bad = tmp_path / "bad.csv"
    if content is not None:
        bad.write_text(content)
    out = tmp_path / "out"
    assert _run("morph", bad, hand_csvs[1], "--out", out) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.csv" in err and "Traceback" not in err
    assert re.search(match, err), err
    assert not out.exists() and not list(tmp_path.glob(".out.*"))


def test_image_with_no_object(tmp_path, hand_csvs, capsys):
    from PIL import Image

    Image.fromarray(np.zeros((50, 60), np.uint8)).save(tmp_path / "empty.png")
    out = tmp_path / "out"
    assert _run("morph", tmp_path / "empty.png", hand_csvs[1], "--out", out) == 2
    err = capsys.readouterr().err
    assert "empty.png" in err and err.count("\n") == 1
    assert not out.exists()


def test_dimension_mismatch_exits_2(tmp_path, hand_csvs, capsys):
    c3 = _csv(tmp_path / "c3.csv", np.random.default_rng(1).standard_normal((30, 3)))
    out = tmp_path / "out"
    assert _run("morph", hand_csvs[0], c3, "--out", out) == 2
    err = capsys.readouterr().err
    assert "2D" in err and "3D" in err and "c3.csv" in err
    assert not out.exists()


def test_bad_option_exits_2(hand_csvs, tmp_path, capsys):
    out = tmp_path / "out"
    assert _run("morph", *hand_csvs, "--out", out, "--k", "-5") == 2
    assert "k must be a number in" in capsys.readouterr().err
    assert _run("morph", *hand_csvs, "--out", out, "--bogus") == 2
    assert not out.exists()


def test_bad_config_exits_2(hand_csvs, tmp_path, capsys):
    config = tmp_path / "c.toml"
    config.write_text("stiffness = 3\n")
    assert _run("morph", *hand_csvs, "--out", tmp_path / "o", "--config", config) == 2
    assert "unknown option 'stiffness'" in capsys.readouterr().err


def test_demo(tmp_path, capsys):
    out = tmp_path / "demo"
    assert _run("demo", "--out", out) == 0
    for case in ("heart", "hands"):
        result = json.loads((out / case / "result.json").read_text())
        assert result["converged"], case
        assert (out / case / "morph.gif").stat().st_size > 0
        assert (out / case / "shapes_energy.png").stat().st_size > 0
    assert "wrote" in capsys.readouterr().out


def test_entry_point_runs_as_module():
    done = subprocess.run([sys.executable, "-m", "modalmorph", "--version"],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0 and "modalmorph" in done.stdout


def _svg_two_subpaths(path):
    path.write_text('<svg xmlns="http://www.w3.org/2000/svg"><path d="M 40 100 '
                    'A 60 40 0 1 0 160 100 C 160 60, 130 60, 100 60 S 40 60, 40 100 Z '
                    'M 0 0 L 10 0 L 10 10 Z"/></svg>')
    return path


def test_warnings_one_line_each_after_success_none_after_error(tmp_path, hand_csvs, capsys):
    svg = _svg_two_subpaths(tmp_path / "two.svg")  # read_shape warns: uses the first subpath
    out = tmp_path / "out"
    assert _run("morph", svg, hand_csvs[1], "--out", out, "--nodes", "70", "-q",
                "--no-figures", "--no-gif") == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("modalmorph: warning: ") and "two.svg" in err[0]
    c3 = _csv(tmp_path / "c3.csv", np.random.default_rng(1).standard_normal((30, 3)))
    assert _run("morph", svg, c3, "--out", tmp_path / "o2") == 2  # warns, then fails
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("modalmorph: error: ")


def test_out_is_replaced_whole_and_foreign_folders_refused(tmp_path, hand_csvs, capsys,
                                                           monkeypatch):
    out = tmp_path / "out"
    quick = ("-q", "--no-figures", "--no-gif")
    assert _run("morph", *hand_csvs, "--out", out, "--vtk", *quick) == 0
    assert (out / "vtk").is_dir()
    assert _run("morph", *hand_csvs, "--out", out, *quick) == 0  # no file of the old run
    assert sorted(p.name for p in out.iterdir()) == ["final_shape.csv", "result.json",
                                                     "shapes.npz"]
    monkeypatch.chdir(tmp_path)  # "." holds the inputs: not an output folder
    assert _run("morph", *hand_csvs, "--out", ".", *quick) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("modalmorph: error: .: a folder with other")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv", "out"]


def test_failed_run_into_a_new_nested_path_leaves_nothing(tmp_path, hand_csvs, capsys):
    out = tmp_path / "new" / "nested" / "out"
    assert _run("morph", *hand_csvs, "--out", out, "--k", "-5") == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv"]
