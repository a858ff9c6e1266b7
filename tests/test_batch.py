"""Batches: pairs and a sequence on a Dask LocalCluster and on the process pool, one bad
item, resume after a finished run and after a SIGKILL midway."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from modalmorph.apps.batch import Engine, Item, read_manifest, run
from modalmorph.apps.cli import main
from modalmorph.datasets import load_hands, load_heart

SRC = Path(__file__).resolve().parents[1] / "src"
# What each kind of item writes with --figures none (as morph / track with no figures).
FILES = {"pair": ("result.json", "shapes.npz", "final_shape.csv"),
         "sequence": ("track.json", "track.npz", "strain_segments.csv")}
BAD_MESSAGE = "bad.csv: line 2: 'foo' in column 1 is not a number"


def _csv(path, points):
    np.savetxt(path, points, delimiter=",", header="x,y", comments="")
    return path


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """A manifest of two good pairs (heart ED->ES, two hands), one bad pair and a sequence
    of three frames, with what morph / track write for each good item alone."""
    d = tmp_path_factory.mktemp("batch-data")
    _csv(d / "ed.csv", load_heart("diastole"))
    _csv(d / "es.csv", load_heart("systole"))
    h0, h3 = load_hands((0, 3), n=60)
    _csv(d / "h0.csv", h0)
    _csv(d / "h3.csv", h3)
    (d / "seq").mkdir()
    for i, t in enumerate((0.0, 0.5, 1.0)):
        _csv(d / "seq" / f"f{i}.csv", (1 - t) * h0 + t * h3)
    (d / "bad.csv").write_text("x,y\nfoo,bar\n")
    (d / "m.csv").write_text("id,source,target,frames,k,reference\n"
                             "heart,ed.csv,es.csv,,,\n"
                             "hands,h0.csv,h3.csv,,60,\n"
                             "bad,bad.csv,es.csv,,,\n"
                             "seq,,,seq/*.csv,,first\n")
    ref = d / "ref"
    q = ["--no-figures", "--no-gif", "-q"]
    assert main(["morph", str(d / "ed.csv"), str(d / "es.csv"), "--out", str(ref / "heart"),
                 *q]) == 0
    assert main(["morph", str(d / "h0.csv"), str(d / "h3.csv"), "--out", str(ref / "hands"),
                 "--k", "60", *q]) == 0
    assert main(["track", str(d / "seq" / "*.csv"), "--out", str(ref / "seq"),
                 "--reference", "first", *q]) == 0
    return d


def _same_outputs(folder: Path, ref: Path, kind: str):
    """The batch's item folder holds what morph / track wrote for the item alone."""
    assert sorted(p.name for p in folder.iterdir()) == sorted(FILES[kind])
    name = FILES[kind][0]
    got, want = (json.loads((f / name).read_text()) for f in (folder, ref))
    for key in ("parameters", "steps", "converged", "matches", "inputs", "nodes"):
        assert got.get(key) == want.get(key), key
    archive = FILES[kind][1]
    with np.load(folder / archive) as a, np.load(ref / archive) as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:
            # one BLAS thread in the workers, maybe more here: equal to rounding
            np.testing.assert_allclose(a[key], b[key], rtol=1e-9, atol=1e-9, err_msg=key)


def _check_batch(data, out):
    """The summary and the item folders of a first run of the manifest."""
    rows = {row["id"]: row for row in _read_csv(out / "summary.csv")}
    assert {k: r["status"] for k, r in rows.items()} == {
        "heart": "ok", "hands": "ok", "bad": "failed", "seq": "ok"}
    assert BAD_MESSAGE in rows["bad"]["error"] and not (out / "bad").exists()
    for name, kind in (("heart", "pair"), ("hands", "pair"), ("seq", "sequence")):
        _same_outputs(out / name, data / "ref" / name, kind)
        assert rows[name]["converged"] == "True" and int(rows[name]["steps"]) > 0
    seq = rows["seq"]
    assert float(seq["strain_min"]) <= 0 <= float(seq["strain_max"])  # frame 0: strain 0
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no staging left


def _read_csv(path):
    import csv

    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_dask_local_cluster_and_resume(data, tmp_path):
    distributed = pytest.importorskip(
        "distributed", reason="Dask is an optional extra: pip install 'modalmorph[dask]'")
    items = read_manifest(data / "m.csv")
    out = tmp_path / "out"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        first = run(items, out, engine=Engine(client=client))
        _check_batch(data, out)
        assert not first.ok and first.engine.startswith("Dask client")
        stamp = (out / "heart" / "result.json").stat().st_mtime_ns
        second = run(items, out, engine=Engine(client=client))
    assert [r.status for r in second.results] == ["skipped", "skipped", "failed", "skipped"]
    assert (out / "heart" / "result.json").stat().st_mtime_ns == stamp  # not rewritten
    assert [r.steps for r in second.results] == [r.steps for r in first.results]
    pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    table = pq.read_table(out / "summary.parquet")
    assert table.column("status").to_pylist() == ["skipped", "skipped", "failed", "skipped"]


def test_process_pool_from_the_command_line(data, tmp_path):
    out = tmp_path / "out"
    argv = ["batch", str(data / "m.csv"), "--out", str(out), "--engine", "processes",
            "--workers", "2", "-q"]
    assert main(argv) == 1  # the bad item failed
    _check_batch(data, out)
    (data / "m-good.csv").write_text("\n".join(
        line for line in (data / "m.csv").read_text().splitlines() if "bad" not in line))
    assert main([*argv[:1], str(data / "m-good.csv"), *argv[2:]]) == 0  # all skipped
    assert [r["status"] for r in _read_csv(out / "summary.csv")] == ["skipped"] * 3


def test_sigkill_midway_leaves_items_complete_or_absent(tmp_path):
    ed, es = _csv(tmp_path / "ed.csv", load_heart("diastole")), \
        _csv(tmp_path / "es.csv", load_heart("systole"))
    n = 8  # heart pairs of ~0.4 s each on one worker: the kill comes after the first
    (tmp_path / "m.toml").write_text("".join(
        f'[[item]]\nid = "p{i}"\nsource = "{ed.name}"\ntarget = "{es.name}"\nk = {80 + i}\n'
        for i in range(n)))
    out = tmp_path / "out"
    argv = ["batch", str(tmp_path / "m.toml"), "--out", str(out), "--engine", "processes",
            "--workers", "1", "-q"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get(
        "PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "modalmorph", *argv], env=env,
                            start_new_session=True, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120  # generous: a loaded CI machine
        while not (out.is_dir() and any(not p.name.startswith(".") for p in out.iterdir())):
            assert proc.poll() is None and time.monotonic() < deadline, "no item finished"
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the batch and its worker processes
        proc.wait()
    done = [p.name for p in out.iterdir() if not p.name.startswith(".")]
    assert 1 <= len(done) < n
    for name in done:  # complete: every file there and readable
        assert sorted(p.name for p in (out / name).iterdir()) == sorted(FILES["pair"])
        with np.load(out / name / "shapes.npz") as npz:
            assert npz["shapes"].shape[1:] == (247, 2)
    assert main(argv) == 0
    statuses = {r["id"]: r["status"] for r in _read_csv(out / "summary.csv")}
    assert statuses == {f"p{i}": "skipped" if f"p{i}" in done else "ok" for i in range(n)}
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_manifest_errors(tmp_path):
    (tmp_path / "a.csv").write_text("id,source,target\nx,a.csv,b.csv\nx,c.csv,d.csv\n")
    with pytest.raises(ValueError, match=r"line 3: id 'x' already used"):
        read_manifest(tmp_path / "a.csv")
    (tmp_path / "b.csv").write_text("source,target,kk\na.csv,b.csv,3\n")
    with pytest.raises(ValueError, match=r"line 2: .*unknown option 'kk'"):
        read_manifest(tmp_path / "b.csv")
    (tmp_path / "c.csv").write_text("source,target,frames\na.csv,,f/*.csv\n")
    with pytest.raises(ValueError, match="either source and target"):
        read_manifest(tmp_path / "c.csv")
    with pytest.raises(ValueError, match="item id must be a plain folder name"):
        Item(id="../up", source="a", target="b")
    items = read_manifest(_toml(tmp_path / "m.toml", 'source = "s.csv"\ntarget = "t.csv"\n'
                                'modes = "2/3"\ndamping = [0.5, 1.0]\n'))
    assert items[0].id == "s-t" and items[0].source == str(tmp_path / "s.csv")
    assert items[0].options == {"modes": "2/3", "damping": [0.5, 1.0]}
    (tmp_path / "d.csv").write_text('frames,cycle,modes,damping\nseq/*.png,true,2/3,'
                                    '"[0.5, 1.0]"\n')
    (item,) = read_manifest(tmp_path / "d.csv")
    assert item.id == "seq" and item.kind == "sequence"
    assert item.options == {"cycle": True, "modes": "2/3", "damping": [0.5, 1.0]}
    with pytest.raises(ValueError, match="figures must be one of"):
        run([item], tmp_path / "out", figures="some")


def _toml(path, body):
    path.write_text("[[item]]\n" + body)
    return path


def test_figures_all_and_summary(data, tmp_path):
    """--figures all: an item's folder holds what morph writes with its figures and GIF;
    --figures summary: one figure of the batch."""
    from modalmorph.apps.batch import run_item, write_summary

    item = Item(id="hands", source=str(data / "h0.csv"), target=str(data / "h3.csv"))
    row = run_item(item, tmp_path / "out", figures="all")
    assert row.status == "ok", row.error
    assert main(["morph", item.source, item.target, "--out", str(tmp_path / "ref"), "-q"]) == 0
    assert sorted(p.name for p in (tmp_path / "out" / "hands").iterdir()) == \
        sorted(p.name for p in (tmp_path / "ref").iterdir())
    written = write_summary([row], tmp_path / "out", figure=True)
    assert (tmp_path / "out" / "summary.png") in written
    assert (tmp_path / "out" / "summary.png").stat().st_size > 0


def test_batch_options_reach_the_items_and_a_short_run_exits_3(data, tmp_path, capsys):
    (tmp_path / "m.toml").write_text(f'[[item]]\nid = "heart"\nsource = "{data / "ed.csv"}"\n'
                                     f'target = "{data / "es.csv"}"\n')
    out = tmp_path / "out"
    code = main(["batch", str(tmp_path / "m.toml"), "--out", str(out), "--engine",
                 "processes", "--workers", "1", "--max-steps", "1", "-q"])
    assert code == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["modalmorph: warning: 1 items did not reach the tolerance: heart"]
    result = json.loads((out / "heart" / "result.json").read_text())
    assert result["steps"] == 1 and result["options"]["max_steps"] == 1
