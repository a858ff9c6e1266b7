"""The command line end to end: real files in, results out, bad input -> exit 2."""

import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from modalmorph.apps import cli, runs
from modalmorph.apps.app import morph_options
from modalmorph.apps.cli import build_parser, main
from modalmorph.core.shape import resample
from modalmorph.datasets import load_hand
from modalmorph.options import OPTION_CLASSES, TrackOptions, flat_fields


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
    assert code in (0, 3)  # converged or not (exit 3): this test is about the options
    params = json.loads((out / "result.json").read_text())["parameters"]
    assert params["k"] == 80  # the command line wins over the file
    assert params["remove_rigid"] is True and params["damping"] == [1.0, 1.0]
    assert params["modes"] == round(2 / 3 * 160)


def test_morph_with_figures_gif_and_vtk(hand_csvs, tmp_path):
    out = tmp_path / "out"
    assert _run("morph", *hand_csvs, "--out", out, "--vtk", "--svg", "-q") == 0
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
    assert _run("morph", *hand_csvs, "--out", out, "--material", "steel") == 2
    assert ("material must be one of polyethylene, rubber, unit or three numbers E nu rho, "
            "got 'steel'") in capsys.readouterr().err  # it said 'must be a number'
    assert _run("morph", *hand_csvs, "--out", out, "--bogus") == 2
    assert not out.exists()


def test_bad_config_exits_2(hand_csvs, tmp_path, capsys):
    config = tmp_path / "c.toml"
    config.write_text("stiffness = 3\n")
    assert _run("morph", *hand_csvs, "--out", tmp_path / "o", "--config", config) == 2
    assert "unknown option 'stiffness'" in capsys.readouterr().err


@pytest.mark.parametrize(("line", "said"), [
    ('k = "abc"', "c.toml: k must be a number, got 'abc'"),
    ("match_modes = 0", "c.toml: match_modes must be a positive integer, got 0")])
def test_a_config_value_refused_names_the_file_and_the_option_as_written(
        hand_csvs, tmp_path, capsys, line, said):
    """Each refusal names the config file and the option by the name the user wrote
    (review17: 'k must be a number' came without the file; 'modes must ...' for
    match_modes, a name the user never wrote, beside the --modes option)."""
    config = tmp_path / "c.toml"
    config.write_text(line + "\n")
    assert _run("morph", *hand_csvs, "--out", tmp_path / "o", "--config", config) == 2
    assert said in capsys.readouterr().err


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


def _png_blob(path):
    from PIL import Image

    rows, cols = np.indices((120, 200))
    Image.fromarray((np.hypot((cols - 100) / 60, (rows - 60) / 40) <= 1).astype(np.uint8)
                    * 255).save(path)
    return path


def test_warnings_one_line_each_after_success_none_after_error(tmp_path, hand_csvs, capsys,
                                                               monkeypatch):
    from modalmorph.io import read_shape

    def read_and_warn(path, options):  # a reader's warning (as meshio's), on one line
        if Path(path).suffix == ".png":
            warnings.warn(f"{path}: a reader's warning\nover two lines", stacklevel=2)
        return read_shape(path, options)

    monkeypatch.setattr(runs, "read_shape", read_and_warn)
    svg = _png_blob(tmp_path / "two.png")
    out = tmp_path / "out"
    assert _run("morph", svg, hand_csvs[1], "--out", out, "--nodes", "70", "-q",
                "--tol", "0.5", "--no-figures", "--no-gif") == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith("modalmorph: warning: ") for e in err)
    assert "two.png" in err[0] and "y pointing up" in err[1]  # an image and a CSV: mirrored?
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


QUICK = ("--no-figures", "--no-gif")


def test_every_option_has_a_flag_a_config_key_a_form_entry_and_a_record(hand_csvs, tmp_path):
    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices  # argparse keeps them there
    flags = {name: {a.dest for a in p._actions} for name, p in commands.items()}
    every = runs.SEQUENCE_CLASSES
    assert set(OPTION_CLASSES) <= set(every)
    for name, cls, f in flat_fields(every):
        command = "track" if cls is TrackOptions else "morph"
        assert name in flags[command], name
        default = runs.default_text(f)  # as a config file or the form writes it
        settings = runs.Settings.from_flat({name: default} if default else {}, every)
        assert settings.record(every)[name] == cls().record()[f.name], name
    form = {o["name"] for o in morph_options()}
    assert form == {name for name, _, _ in flat_fields(runs.FORM_CLASSES)}
    assert {name for name, _, _ in flat_fields(every) if name in form} == form
    out = tmp_path / "out"
    assert _run("morph", *hand_csvs, "--out", out, "-q", *QUICK) in (0, 3)
    record = json.loads((out / "result.json").read_text())["options"]
    assert set(record) == {name for name, _, _ in flat_fields(runs.PAIR_CLASSES)}
    assert record["material"]["name"] == "polyethylene"


def test_result_json_records_inputs_and_options(hand_csvs, tmp_path):
    import hashlib

    out = tmp_path / "out"
    assert _run("morph", *hand_csvs, "--out", out, "-q", "--material", "1000", "0.3", "1",
                "--damping", "0.5", "1", "--cx", "0.1", *QUICK) in (0, 3)
    result = json.loads((out / "result.json").read_text())
    assert [i["sha256"] for i in result["inputs"]] == [
        hashlib.sha256(p.read_bytes()).hexdigest() for p in hand_csvs]
    assert result["inputs"][0]["path"] == str(hand_csvs[0].absolute())
    options = result["options"]
    assert options["material"] == {"name": "custom", "E": 1000.0, "nu": 0.3, "rho": 1.0}
    assert options["damping"] == [0.5, 1.0] and options["c_x"] == 0.1
    assert options["figures"] is False and options["gif"] is False


def test_quiet_run_short_of_the_tolerance_warns_and_exits_3(hand_csvs, tmp_path, capsys):
    out = tmp_path / "out"
    assert _run("morph", *hand_csvs, "--out", out, "-q", "--max-steps", "1", *QUICK) == 3
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("modalmorph: warning: the tolerance was not "
                                               "reached: ") and "(results written)" in err[0]
    assert captured.out == ""
    assert json.loads((out / "result.json").read_text())["converged"] is False


def test_help_documents_the_exit_codes(capsys):
    assert _run("morph", "--help") == 0
    text = capsys.readouterr().out
    for code in cli.EXIT_CODES:
        assert re.search(rf"^  {code}\s", text, re.M), code
    assert "tolerance was not reached" in text


def test_status_sentence_and_a_progress_bar_that_ends_at_100(hand_csvs, tmp_path,
                                                              monkeypatch):
    import io

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    err = Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    assert _run("morph", *hand_csvs, "--out", tmp_path / "out", *QUICK) == 0
    text = err.getvalue()
    assert re.search(r"morphing: step (\d+).*100%", text), text[-500:]
    status = [line for line in text.splitlines() if " matches; " in line]
    assert len(status) == 1
    assert re.search(r"80 -> 90 nodes, \d+ matches; converged after \d+ steps, [\d.]+ input "
                     r"units from the target \(tolerance [\d.]+ input units\); \d+\.\d s$",
                     status[0]), status


def test_mp4_without_ffmpeg_fails_before_any_computation(hand_csvs, tmp_path, capsys,
                                                         monkeypatch):
    import shutil

    def no_work(*args, **kwargs):
        raise AssertionError("computed before checking the tools")

    monkeypatch.setattr(shutil, "which", lambda *args, **kwargs: None)  # no ffmpeg anywhere
    monkeypatch.setattr(runs, "read_pair", no_work)
    out = tmp_path / "out"
    assert _run("morph", *hand_csvs, "--out", out, "--mp4") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mp4 needs ffmpeg" in err[0] and "AssertionError" not in err[0]
    assert not out.exists()


def test_no_figures_alone_still_writes_the_animation(hand_csvs, tmp_path):
    out = tmp_path / "out"
    assert _run("morph", *hand_csvs, "--out", out, "-q", "--no-figures", "--svg") == 0
    assert sorted(p.name for p in out.iterdir()) == ["final_shape.csv", "morph.gif",
                                                     "result.json", "shapes.npz"]


def test_track_json_records_the_frame_files_and_options(tmp_path):
    import hashlib

    h0, h3 = resample(load_hand(0), 60), resample(load_hand(3), 60)
    (tmp_path / "seq").mkdir()
    for i, t in enumerate((0.0, 0.5, 1.0)):
        _csv(tmp_path / "seq" / f"f{i}.csv", (1 - t) * h0 + t * h3)
    out = tmp_path / "out"
    assert _run("track", tmp_path / "seq" / "*.csv", "--out", out, "--reference", "first",
                "-q", *QUICK) in (0, 3)
    data = json.loads((out / "track.json").read_text())
    files = sorted((tmp_path / "seq").iterdir())
    assert data["input_files"] == [{"path": str(p), "sha256": hashlib.sha256(
        p.read_bytes()).hexdigest()} for p in files]
    assert data["options"]["reference"] == "first" and data["options"]["k"] == 100.0
    assert set(data["options"]) == {name for name, _, _ in flat_fields(runs.SEQUENCE_CLASSES)}


def test_ctrl_c_says_one_line_exits_130_and_leaves_nothing(tmp_path):
    """SIGINT while a morph computes: one line, exit 130, no output folder, no staging."""
    import signal
    import time

    a = np.linspace(0.0, 2.0 * np.pi, 3000, endpoint=False)
    np.savetxt(tmp_path / "a.csv", np.c_[np.cos(a), np.sin(a)], delimiter=",")
    np.savetxt(tmp_path / "b.csv", np.c_[2 * np.cos(a), np.sin(a) + 0.3 * np.cos(5 * a)],
               delimiter=",")
    proc = subprocess.Popen([sys.executable, "-m", "modalmorph", "morph", "a.csv", "b.csv",
                             "--out", "out", "--tol", "1e-9", "--max-steps", "500", "-q"],
                            cwd=tmp_path, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60.0
    while not list(tmp_path.glob(".out.modalmorph-tmp-*")) and time.monotonic() < deadline:
        time.sleep(0.05)  # the staging folder is made before any computation
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["modalmorph: interrupted"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv"]


def test_a_self_crossing_contour_is_refused_with_where(tmp_path, capsys):
    t = np.linspace(0.0, 2.0 * np.pi, 100, endpoint=False) + 0.01
    np.savetxt(tmp_path / "eight.csv", np.c_[np.sin(t), np.sin(2 * t)], delimiter=",")
    np.savetxt(tmp_path / "circle.csv", np.c_[np.cos(t), np.sin(t)], delimiter=",")
    assert main(["morph", str(tmp_path / "circle.csv"), str(tmp_path / "eight.csv"),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "eight.csv crosses itself: the segment from node" in err[0], err
    assert not (tmp_path / "out").exists()


def test_points_on_a_line_are_refused_by_file_name_not_resampled(tmp_path, capsys):
    # 20 nodes on one line, read closed: the closing edge makes them uneven, and resampled
    # they would double back on themselves; the error names the file, not "source"
    line = np.c_[np.linspace(0.0, 1.0, 20), np.linspace(0.0, 2.0, 20)]
    np.savetxt(tmp_path / "line.csv", line, delimiter=",")
    t = np.linspace(0.0, 2.0 * np.pi, 60, endpoint=False)
    np.savetxt(tmp_path / "circle.csv", np.c_[np.cos(t), np.sin(t)], delimiter=",")
    assert main(["morph", str(tmp_path / "line.csv"), str(tmp_path / "circle.csv"),
                 "-o", str(tmp_path / "out")]) == 2
    err = [x for x in capsys.readouterr().err.strip().splitlines() if "error" in x]
    assert len(err) == 1 and "line.csv: a closed contour with no area" in err[0], err
    assert not (tmp_path / "out").exists()


def test_a_ctrl_c_that_c_code_swallows_stops_the_next_step():
    """numba's compiler callbacks ignore a KeyboardInterrupt raised inside them (under load
    the run then went on to its end, 1 of 4 tries): within the command line's handler a
    SIGINT is remembered, and the next step of a progress bar, shown or not, raises it;
    the handler is the one before again afterwards."""
    import contextlib
    import signal

    from modalmorph.apps.progress import interruptible, progress_bar

    before = signal.getsignal(signal.SIGINT)  # Python's, or an earlier test's
    with interruptible():
        with contextlib.suppress(KeyboardInterrupt):  # swallowed, as a C callback does
            signal.raise_signal(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt), progress_bar(10, quiet=True) as step:
            step(1, None)
    assert signal.getsignal(signal.SIGINT) is before
    with progress_bar(10, quiet=True) as step:  # afterwards, nothing is left to raise
        step(1, None)
