"""``modalmorph batch`` on pressure trials (issue 24): stance phases and peak images
registered to a template, from a file of many trials or manifest rows, on the batch's
engines, with the table per subject and walking speed. Small synthetic stacks (CI has no
jiku-data)."""

import csv
import json

import numpy as np
import pytest

from modalmorph.apps import batch
from modalmorph.apps.batch.pressure import GROUP_COLUMNS, pressure_items
from modalmorph.apps.cli import main
from modalmorph.apps.runs import Settings
from modalmorph.options import StanceOptions

from .test_stance import synthetic_stance

SUBJECTS = np.array([1, 1, 2, 2])
SPEEDS = np.array(["slow", "fast", "slow", "fast"])
LEVEL = Settings(stance=StanceOptions(threshold=5.0))
POOL = batch.Engine("processes", workers=2)


def rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def trials(tmp_path_factory):
    """Four stance phases of two subjects at two speeds, and their peak images."""
    s = synthetic_stance()
    stacks = np.array([s, s * 1.2, s * 0.9, s * 1.1])
    folder = tmp_path_factory.mktemp("pressure")
    np.savez(folder / "trials.npz", pressure=stacks, subject=SUBJECTS, speed=SPEEDS)
    np.savez(folder / "peaks.npz", pressure=stacks.max(axis=1), subject=SUBJECTS,
             speed=SPEEDS)
    return folder


def test_items_of_a_file_of_many_trials(trials):
    stance_items = pressure_items(trials / "trials.npz")
    assert [i.id for i in stance_items] == [f"trial-00{k}" for k in range(4)]
    assert all(i.kind == "stance" and len(i.trials) == 1 for i in stance_items)
    foot_items = pressure_items(trials / "peaks.npz")  # one per subject
    assert [(i.id, i.kind, i.trials) for i in foot_items] == [
        ("subject-1", "footprints", (0, 1)), ("subject-2", "footprints", (2, 3))]
    assert len(pressure_items(trials / "peaks.npz", "stance")) == 1  # one (T, H, W) stack


def test_stance_trials_match_the_single_command(trials, tmp_path):
    """Each item's folder is what ``modalmorph stance`` writes for that trial, and the
    table has a row per subject and speed with the trials' numbers."""
    done = batch.run(pressure_items(trials / "trials.npz"), tmp_path / "out",
                     engine=POOL, settings=LEVEL)
    assert done.ok and done.counts == {"ok": 4}
    np.save(tmp_path / "one.npy", np.load(trials / "trials.npz")["pressure"][2])
    assert main(["stance", str(tmp_path / "one.npy"), "--threshold", "5", "--out",
                 str(tmp_path / "single"), "-q"]) == 0
    one = json.loads((tmp_path / "single" / "result.json").read_text())
    mine = json.loads((tmp_path / "out" / "trial-002" / "result.json").read_text())
    assert mine["meta"] == {"subject": 2, "speed": "slow"}
    assert mine["energy"] == pytest.approx(one["energy"], rel=1e-9)
    assert mine["summary"] == pytest.approx(one["summary"], rel=1e-9)
    table = rows(tmp_path / "out" / "pressure.csv")
    assert tuple(table[0]) == GROUP_COLUMNS
    assert [(r["subject"], r["speed"], r["trials"]) for r in table] == [
        ("1", "slow", "1"), ("1", "fast", "1"), ("2", "slow", "1"), ("2", "fast", "1")]
    assert float(table[2]["energy_median"]) == pytest.approx(one["summary"]["energy"],
                                                             rel=1e-5)
    summary = {r.id: r for r in done.results}
    assert summary["trial-002"].energy == pytest.approx(one["summary"]["energy"])


def test_footprints_per_subject_and_resume(trials, tmp_path):
    """Peak images registered per subject; a second run skips them; a changed option
    redoes them and says which."""
    items = pressure_items(trials / "peaks.npz")
    done = batch.run(items, tmp_path, engine=POOL, settings=LEVEL)
    assert done.counts == {"ok": 2}
    images = rows(tmp_path / "subject-2" / "footprints.csv")
    assert [(r["image"], r["subject"], r["speed"]) for r in images] == [
        ("0", "2", "slow"), ("1", "2", "fast")]
    table = rows(tmp_path / "pressure.csv")
    assert len(table) == 4 and all(r["kind"] == "footprints" for r in table)
    assert all(float(r["area_mm2"]) > 0 for r in table)
    again = batch.run(items, tmp_path, engine=POOL, settings=LEVEL)
    assert again.counts == {"skipped": 2}
    assert rows(tmp_path / "pressure.csv") == table  # the table of the skipped items
    wider = batch.run(items, tmp_path, engine=POOL,
                      settings=Settings(stance=StanceOptions(threshold=5.0,
                                                             pixel_size=2.0)))
    assert wider.counts == {"ok": 2}
    assert all("pixel_size 1 -> 2" in r.note for r in wider.results)
    doubled = rows(tmp_path / "pressure.csv")
    for old, new in zip(table, doubled, strict=True):  # mm^2 at 2 mm per sensor
        assert float(new["area_mm2"]) == pytest.approx(4 * float(old["area_mm2"]),
                                                       rel=1e-4)


def test_manifest_rows_and_a_bad_trial_named(trials, tmp_path, capsys):
    """Manifest rows of both kinds with their own options; a stack with a NaN fails on
    its own row, naming the frame, and the others are written."""
    stack = synthetic_stance()
    stack[3, 5, 5] = np.nan
    np.save(tmp_path / "bad.npy", stack)
    (tmp_path / "list.csv").write_text(
        "id,pressure,kind,trial,subject,speed,threshold,template\n"
        f"a,{trials / 'trials.npz'},stance,1,,,5,\n"
        f"b,{trials / 'peaks.npz'},footprints,,,,5,0\n"
        "c,bad.npy,stance,,3,slow,5,\n"
        f"d,{trials / 'peaks.npz'},footprints,,,,5,9\n")
    code = main(["batch", str(tmp_path / "list.csv"), "--out", str(tmp_path / "out"),
                 "--workers", "2", "--figures", "all", "-q"])
    assert code == 1  # an item failed, the others are written
    err = capsys.readouterr().err
    assert "c: failed:" in err and "frame 3" in err
    assert "d: failed:" in err and "template must be mean or an image number 0..3" in err
    summary = {r["id"]: r for r in rows(tmp_path / "out" / "summary.csv")}
    assert summary["a"]["status"] == summary["b"]["status"] == "ok"
    assert not (tmp_path / "out" / "c").exists()  # nothing half-written
    assert (tmp_path / "out" / "a" / "stance.png").is_file()  # the figures, with "all"
    assert (tmp_path / "out" / "b" / "footprints.png").is_file()
    table = rows(tmp_path / "out" / "pressure.csv")
    assert {(r["kind"], r["subject"], r["speed"]) for r in table} == {
        ("stance", "1", "fast"), *(("footprints", str(s), v)
                                   for s, v in zip(SUBJECTS, SPEEDS, strict=True))}


def test_bad_pressure_items_name_the_problem(trials, tmp_path):
    with pytest.raises(ValueError, match="kind stance or footprints"):
        batch.Item(id="x", pressure=str(trials / "trials.npz"), study="walk")
    with pytest.raises(ValueError, match="fraction"):
        batch.Item(id="x", pressure="p.npy", study="stance", options={"fraction": 3})
    with pytest.raises(ValueError, match="one trial"):
        batch.Item(id="x", pressure="p.npy", study="stance", trials=(0, 1))
    np.save(tmp_path / "flat.npy", np.zeros((5, 6)))
    assert main(["batch", str(tmp_path / "flat.npy"), "--out", str(tmp_path / "o"),
                 "-q"]) == 2  # (H, W): not a file of many trials
    assert main(["batch", str(trials / "peaks.npz"), "--kind", "walk", "--out",
                 str(tmp_path / "o"), "-q"]) == 2


def test_stance_trials_on_dask(trials, tmp_path):
    """The same items on a Dask LocalCluster give the same numbers as the process pool."""
    pytest.importorskip("distributed")
    items = pressure_items(trials / "trials.npz")[:2]
    on_dask = batch.run(items, tmp_path / "dask", settings=LEVEL,
                        engine=batch.Engine("dask", workers=1))
    local = batch.run(items, tmp_path / "pool", settings=LEVEL, engine=POOL)
    assert on_dask.engine.startswith("Dask LocalCluster") and on_dask.counts == {"ok": 2}
    assert local.counts == {"ok": 2}
    assert rows(tmp_path / "dask" / "pressure.csv") == rows(tmp_path / "pool" /
                                                            "pressure.csv")
