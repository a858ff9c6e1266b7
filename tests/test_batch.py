"""Batches: pairs and a sequence on a Dask LocalCluster and on the process pool, one bad
item, resume after a finished run and after a SIGKILL midway; resume that redoes changed
items, Ctrl-C, workers that die with their batch, and a scheduler and two workers started
with Dask's own command line on 127.0.0.1 (one worker killed; the scheduler killed)."""

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
    for name in ("heart", "hands"):  # one distance: the stop test's, as result.json says
        record = json.loads((out / name / "result.json").read_text())
        assert float(rows[name]["distance"]) == record["distance"]
        assert float(rows[name]["tolerance"]) == record["tolerance"]
        assert float(rows[name]["distance"]) <= float(rows[name]["tolerance"])  # converged
        assert rows[name]["frame_distance"] == ""
    seq = rows["seq"]
    assert seq["distance"] == "" and float(seq["frame_distance"]) >= 0
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


def test_svg_whose_uses_multiply_fails_its_item_on_dask_threads(tmp_path, monkeypatch):
    """review17: Dask runs items on threads, where no alarm stops a read: a 1.6 kB SVG
    whose <use>s multiply drew to the end. Refused by its count before it is drawn."""
    distributed = pytest.importorskip(
        "distributed", reason="Dask is an optional extra: pip install 'modalmorph[dask]'")
    se = pytest.importorskip("svgelements")

    def drawn(*args, **kwargs):
        raise AssertionError("svgelements was asked to draw it")

    monkeypatch.setattr(se.SVG, "parse", drawn)  # the workers are this process's threads
    groups = "".join(f'<g id="p{i + 1}">' + f'<use href="#p{i}"/>' * 10 + "</g>"
                     for i in range(6))
    (tmp_path / "fanout.svg").write_text(
        f'<svg xmlns="http://www.w3.org/2000/svg"><defs><path id="p0" d="M0 0 L10 0 L10 '
        f'10 Z"/>{groups}</defs><use href="#p6"/></svg>')
    _csv(tmp_path / "es.csv", load_heart("systole"))
    (tmp_path / "m.csv").write_text("id,source,target\nbomb,fanout.svg,es.csv\n")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        done = run(read_manifest(tmp_path / "m.csv"), tmp_path / "out",
                   engine=Engine(client=client))
    [result] = done.results
    assert result.status == "failed"
    assert result.error.endswith("fanout.svg: 4691351 elements once each <use> is expanded, "
                                 "the limit (max_svg_elements) is 50000"), result.error


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


# ------------------------------------------------------------------------------ issue 26


def _env():
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get(
        "PYTHONPATH", "")])}


def _hearts(folder: Path, n: int) -> Path:
    """A TOML manifest of ``n`` heart pairs (~0.2-0.4 s each), k varied per item."""
    ed, es = (_csv(folder / f"{name}.csv", load_heart(phase))
              for name, phase in (("ed", "diastole"), ("es", "systole")))
    (folder / "m.toml").write_text("".join(
        f'[[item]]\nid = "p{i}"\nsource = "{ed.name}"\ntarget = "{es.name}"\nk = {80 + i}\n'
        for i in range(n)))
    return folder / "m.toml"


def _complete(out: Path) -> set:
    return {p.name for p in out.iterdir() if not p.name.startswith(".")
            and (p / "result.json").is_file()}


def _statuses(out: Path) -> dict:
    return {r["id"]: r["status"] for r in _read_csv(out / "summary.csv")}


def _wait(condition, what: str, proc=None, seconds: float = 120):
    """Poll ``condition`` every 20 ms; generous bound: a loaded CI machine."""
    deadline = time.monotonic() + seconds
    while not condition():
        assert proc is None or proc.poll() is None, f"the batch ended before {what}"
        assert time.monotonic() < deadline, f"no {what} in {seconds} s"
        time.sleep(0.02)


def test_changed_inputs_and_options_are_redone(data, tmp_path):
    """Resume compares each item's inputs' SHA-256 and options with its record."""
    for name in ("ed.csv", "es.csv", "h0.csv", "h3.csv"):
        (tmp_path / name).write_bytes((data / name).read_bytes())
    manifest = tmp_path / "m.csv"
    manifest.write_text("id,source,target,k\nheart,ed.csv,es.csv,\nhands,h0.csv,h3.csv,60\n")
    out, engine = tmp_path / "out", Engine("processes", workers=1)
    assert run(read_manifest(manifest), out, engine=engine).ok
    assert [r.status for r in run(read_manifest(manifest), out, engine=engine).results] == \
        ["skipped", "skipped"]
    manifest.write_text("id,source,target,k\nheart,ed.csv,es.csv,\nhands,h0.csv,h3.csv,50\n")
    stale = run(read_manifest(manifest), out, keep_stale=True, engine=engine)
    assert [r.status for r in stale.results] == ["skipped", "skipped"]  # opted out
    again = run(read_manifest(manifest), out, engine=engine).results
    assert [(r.status, r.note) for r in again] == [
        ("skipped", ""), ("ok", "redone: options changed (k 60 -> 50)")]
    assert json.loads((out / "hands" / "result.json").read_text())["options"]["k"] == 50
    (tmp_path / "es.csv").write_text((tmp_path / "es.csv").read_text() + "\n")  # same shape
    again = run(read_manifest(manifest), out, engine=engine).results
    assert [(r.status, r.note) for r in again] == [
        ("ok", "redone: inputs changed (es.csv)"), ("skipped", "")]
    forced = run(read_manifest(manifest), out, force=True, engine=engine).results
    assert {r.note for r in forced} == {"redone: --force"}


def test_stale_staging_removed_when_the_item_is_skipped(data, tmp_path):
    items = [Item(id="hands", source=str(data / "h0.csv"), target=str(data / "h3.csv"))]
    out = tmp_path / "out"
    run(items, out, engine=Engine("processes", workers=1))
    (out / ".hands.123-abc.partial" / "hands").mkdir(parents=True)  # a killed attempt
    assert [r.status for r in run(items, out, engine=Engine("processes")).results] == \
        ["skipped"]
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def _children(pid: int) -> list:
    psutil = pytest.importorskip("psutil")
    return psutil.Process(pid).children(recursive=True)


def _batch(argv, **kw):
    return subprocess.Popen([sys.executable, "-m", "modalmorph", *map(str, argv)],
                            env=_env(), start_new_session=True, stderr=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, text=True, **kw)


def test_ctrl_c_stops_at_once_and_the_summary_marks_the_unfinished(tmp_path):
    """SIGINT to the process group, as a terminal's Ctrl-C: one line, exit 130, no item
    started after it, no worker left, the summary marks exactly the unfinished items."""
    manifest = _hearts(tmp_path, 12)
    out = tmp_path / "out"
    proc = _batch(["batch", manifest, "--out", out, "--engine", "processes", "--workers",
                   "2", "-q"])
    try:
        _wait(lambda: out.is_dir() and _complete(out), "finished item", proc)
        workers = _children(proc.pid)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130
    assert err.strip().splitlines() == [l for l in err.strip().splitlines()
                                        if l.startswith("modalmorph: interrupted")]
    assert len(err.strip().splitlines()) == 1, err
    done = _complete(out)
    _wait(lambda: not any(w.is_running() and w.status() != "zombie" for w in workers),
          "end of the workers (and multiprocessing's resource tracker)", seconds=10)
    statuses = _statuses(out)
    assert {k for k, s in statuses.items() if s == "ok"} == done
    assert {k for k, s in statuses.items() if s == "interrupted"} == \
        {f"p{i}" for i in range(12)} - done
    assert 1 <= len(done) < 12
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
    time.sleep(1.0)
    assert _complete(out) == done  # nothing written after the batch ended


def test_workers_die_with_a_killed_batch(tmp_path):
    """SIGKILL of the batch's process alone: its worker processes end too."""
    manifest = _hearts(tmp_path, 12)
    out = tmp_path / "out"
    proc = _batch(["batch", manifest, "--out", out, "--engine", "processes", "--workers",
                   "2", "-q"])
    try:
        _wait(lambda: len(_children(proc.pid)) >= 2, "worker processes", proc)
        workers = _children(proc.pid)
        proc.kill()
        proc.wait()
        _wait(lambda: not any(w.is_running() and w.status() != "zombie" for w in workers),
              "end of the workers", seconds=10)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        proc.stderr.close()


def _dask(args, log):
    """``dask ...`` (Dask's own command line) in its own session, logging to ``log``."""
    return subprocess.Popen([sys.executable, "-m", "dask", *map(str, args)], env=_env(),
                            start_new_session=True, stdout=log, stderr=log)


@pytest.fixture
def cluster(tmp_path):
    """A scheduler and two single-threaded workers on 127.0.0.1, started apart from the
    batch as on a cluster; yields (address, scheduler process, worker processes)."""
    distributed = pytest.importorskip(
        "distributed", reason="Dask is an optional extra: pip install 'modalmorph[dask]'")
    file = tmp_path / "scheduler.json"
    procs = []
    with open(tmp_path / "dask.log", "w") as log:
        try:
            procs.append(_dask(["scheduler", "--host", "127.0.0.1", "--port", "0",
                                "--no-dashboard", "--scheduler-file", file], log))
            _wait(file.is_file, "scheduler file", procs[0])
            for _ in range(2):
                procs.append(_dask(["worker", "--scheduler-file", file, "--host",
                                    "127.0.0.1", "--nthreads", "1", "--no-nanny",
                                    "--no-dashboard"], log))
            address = json.loads(file.read_text())["address"]
            with distributed.Client(address, timeout="60s") as client:
                client.wait_for_workers(2, timeout=120)
            yield address, procs[0], procs[1:]
        finally:
            for proc in procs:
                if proc.poll() is None:
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def test_scheduler_and_workers_started_apart_one_worker_killed(cluster, tmp_path):
    """A batch on `dask scheduler` + two `dask worker`s: one worker is killed after the
    first item; its items are redone on the other, every item ok, summary = disk."""
    address, _, workers = cluster
    items = read_manifest(_hearts(tmp_path, 10))
    out = tmp_path / "out"
    killed = []

    def progress(row, n_done, total):
        if row is not None and not killed:
            workers[0].kill()  # SIGKILL mid-batch: it holds an item now
            killed.append(row.id)

    done = run(items, out, engine=Engine(scheduler=address), progress=progress)
    assert killed and workers[0].wait(timeout=10) == -signal.SIGKILL
    assert done.counts == {"ok": 10} and done.engine == f"Dask scheduler {address}"
    assert _complete(out) == {f"p{i}" for i in range(10)}
    assert set(_statuses(out).values()) == {"ok"}
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
    for i in (0, 9):
        result = json.loads((out / f"p{i}" / "result.json").read_text())
        assert result["options"]["k"] == 80 + i and result["converged"]


def test_scheduler_gone_one_line_and_exit_4(cluster, tmp_path):
    """The scheduler killed mid-batch: one line, exit code 4, the finished items kept."""
    address, scheduler, _ = cluster
    out = tmp_path / "out"
    proc = _batch(["batch", _hearts(tmp_path, 30), "--out", out, "--scheduler", address])
    try:
        _wait(lambda: out.is_dir() and _complete(out), "finished item", proc)
        os.killpg(scheduler.pid, signal.SIGKILL)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 4, err
    lines = err.strip().splitlines()  # quiet without -v: no Dask log line, no traceback
    assert lines[:2] == ["30 of 30 items to compute, 0 complete in " + str(out),
                         f"engine: Dask scheduler {address}"], err
    assert lines[2].startswith("30 items: ") and len(lines) == 4, err
    assert lines[3].startswith(f"modalmorph: error: the Dask scheduler {address}"), err
    done, statuses = _complete(out), _statuses(out)
    ok = {k for k, s in statuses.items() if s == "ok"}
    assert 1 <= len(ok) < 30 and set(statuses.values()) == {"ok", "interrupted"}
    # the workers may still finish the items they held, after the batch ended
    assert ok <= done and len(done - ok) <= 2
    assert not [p for p in out.iterdir() if p.name.startswith(".summary")]


def test_one_progress_bar_with_failed_rate_and_eta(data, tmp_path, monkeypatch):
    import io

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setattr(sys, "stderr", Terminal())
    (data / "m3.csv").write_text("\n".join((data / "m.csv").read_text().splitlines()[:4]))
    assert main(["batch", str(data / "m3.csv"), "--out", str(tmp_path / "out"),
                 "--engine", "processes", "--workers", "1"]) == 1
    text = sys.stderr.getvalue()
    assert "3/3" in text and "1 failed" in text and "items/min" in text and "ETA" in text
