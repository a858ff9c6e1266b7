"""Pressure items of a batch: one stance phase (kind ``stance``, :func:`modalmorph.stance`)
or peak-pressure images registered to a template (kind ``footprints``,
:func:`modalmorph.register_footprints`), each written into ``OUT/<id>/`` as ``modalmorph
stance`` / ``modalmorph footprints`` write it, plus the table of the whole batch per
subject and walking speed (``OUT/pressure.csv``).

A pressure item reads ``pressure``: an NPY/NPZ file, ``jiku:S:T`` (a stance phase of the
optional package jiku-data) or ``jiku:S`` (its 60 peak images of subject S). A file may
hold many trials, ``(N, T, H, W)`` stance phases or ``(N, H, W)`` peak images, with
per-trial metadata: the NPZ's other arrays of length N (``subject``, ``speed``, ...);
``trials`` picks some of them. :func:`pressure_items` makes the items of such a file,
or of jiku-data's set (``jiku``).
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from ...errors import InputFileError, OptionError
from ...io import atomic_output_dir, atomic_write
from ...io.pressure import check_pressure, jiku_conditions, jiku_peaks, jiku_trial
from ...options import StanceOptions, flat_fields, split
from ...pedobarography import register_footprints, stance
from ..runs import file_record
from ..stance import write_footprints, write_stance
from .manifest import PRESSURE_KINDS, Item

__all__ = ["PRESSURE_KINDS", "GROUP_COLUMNS", "add_pressure_flags", "batch_items",
           "batch_pressure", "pressure_items", "pressure_record", "run_pressure",
           "stance_options", "write_groups"]

JIKU = "jiku"
_SPEEDS = {1: "slow", 2: "normal", 3: "fast"}  # jiku-data's conditions
_META = ("subject", "speed")  # the columns that group the table of the batch
GROUP_COLUMNS = ("kind", "subject", "speed", "trials", "area_mm2", "energy_median",
                 "energy_q1", "energy_q3", "peak_x_mm", "peak_y_mm")


def stance_options(item: Item, batch: StanceOptions) -> StanceOptions:
    """The batch's pressure options with the item's own over them."""
    own = split(dict(item.options), (StanceOptions,), where=f"item {item.id!r}")[StanceOptions]
    return replace(batch, **{k: getattr(own, k) for k in item.options})


def _jiku(name: str) -> list[int] | None:
    if not name.startswith(JIKU + ":"):
        return None
    try:
        return [int(v) for v in name[len(JIKU) + 1:].split(":")]
    except ValueError:
        raise OptionError(f"{name}: jiku inputs are jiku:SUBJECT or jiku:SUBJECT:TRIAL") \
            from None


def _read_file(path: str) -> tuple[np.ndarray, dict]:
    """The array of an NPY/NPZ (``pressure``, else the first) and, of an NPZ, its other
    arrays of one value per trial (the metadata)."""
    if Path(path).suffix.lower() not in (".npy", ".npz"):
        raise InputFileError(f"{path}: pressure files are NPY or NPZ arrays")
    try:
        if Path(path).suffix.lower() == ".npy":
            return np.load(path, allow_pickle=False), {}
        with np.load(path, allow_pickle=False) as data:
            key = "pressure" if "pressure" in data else data.files[0]
            array = data[key]
            meta = {k: data[k] for k in data.files if k != key and data[k].ndim == 1
                    and len(data[k]) == len(array)}
    except (OSError, ValueError, IndexError) as exc:
        raise InputFileError(f"{path}: cannot read the array: {exc}") from None
    return array, meta


def load(item: Item) -> tuple[np.ndarray, dict]:
    """The item's pressure (a (T, H, W) stance, or (N, H, W) peak images) and the
    metadata of each of its trials (arrays of one value per trial)."""
    jiku = _jiku(item.pressure)
    if jiku is not None:
        if item.kind == "stance" and len(jiku) == 2:
            cond, speed = jiku_conditions(jiku[0])
            return jiku_trial(*jiku, every=1), dict(
                subject=np.array([jiku[0]]), speed=np.array([_SPEEDS[cond[jiku[1]]]]),
                speed_m_s=speed[jiku[1]:jiku[1] + 1])
        if item.kind == "footprints" and len(jiku) == 1:
            cond, speed = jiku_conditions(jiku[0])
            picked = list(item.trials) or list(range(len(cond)))
            return jiku_peaks(jiku[0])[picked], dict(
                subject=np.full(len(picked), jiku[0]),
                speed=np.array([_SPEEDS[c] for c in cond[picked]]), speed_m_s=speed[picked])
        raise OptionError(f"item {item.id!r}: kind {item.kind} reads jiku:"
                          f"{'SUBJECT:TRIAL' if item.kind == 'stance' else 'SUBJECT'}, "
                          f"got {item.pressure}")
    array, meta = _read_file(item.pressure)
    many = array.ndim == (4 if item.kind == "stance" else 3)
    if item.trials and not many:
        raise InputFileError(f"{item.pressure}: trials picked, but the array "
                             f"{array.shape} holds one {item.kind} trial")
    picked = list(item.trials) if item.trials else None
    if picked is not None and max(picked) >= len(array):
        raise InputFileError(f"{item.pressure}: trial {max(picked)} asked, the file holds "
                             f"{len(array)}")
    if item.kind == "stance":
        array = array[picked[0]] if many else array
        picked = picked or [0]
    elif picked is not None:
        array = array[picked]
    meta = {k: v[picked] if picked is not None else v for k, v in meta.items()} if many \
        else {}
    n = 1 if item.kind == "stance" else len(array)
    for key, value in item.meta.items():  # the manifest's cells, where the file has none
        meta.setdefault(key, np.full(n, value))
    return check_pressure(array, f"{item.pressure} ({item.id})"), meta


def pressure_record(item: Item, batch: StanceOptions, record=file_record) -> dict:
    """What the item's ``result.json`` records of its inputs and options (the batch
    compares them to redo an item whose input or options changed); ``record(path)`` is
    :func:`~modalmorph.apps.runs.file_record` or one that keeps its answers."""
    if _jiku(item.pressure) is not None:
        from importlib.metadata import version

        inputs = [dict(path=item.pressure, sha256=f"jiku-data {version('jiku-data')}")]
    else:
        inputs = [record(item.pressure)]
    options = dict(stance_options(item, batch).record(), trials=list(item.trials),
                   template=item.template)
    return json.loads(json.dumps(dict(inputs=inputs, options=options)))


def run_pressure(item: Item, folder: Path, batch: StanceOptions, figures: bool) -> None:
    """Compute a pressure item and write it into ``folder`` (as a whole)."""
    opts = stance_options(item, batch)
    pressure, meta = load(item)
    record = pressure_record(item, batch)
    if item.kind == "stance":
        result = stance(pressure, options=opts, name=f"{item.pressure} ({item.id})")
        with atomic_output_dir(folder) as tmp:
            write_stance(result, Path(tmp), item.pressure, extra=dict(
                record, meta={k: v[0].item() for k, v in meta.items()}))
            if figures:
                from ...figures.stance import save_stance_figures

                save_stance_figures(result, tmp)
        return
    template = item.template
    if not (template is None or template == "mean" or (
            isinstance(template, int) and 0 <= template < len(pressure))):
        raise OptionError(f"item {item.id!r}: template must be mean or an image number "
                          f"0..{len(pressure) - 1}, got {template!r}")
    regs = register_footprints(pressure, template=template, options=opts)
    with atomic_output_dir(folder) as tmp:
        write_footprints(regs, Path(tmp), meta, dict(record, input=item.pressure),
                         figure=figures)


def read_numbers(item: Item, folder: Path, data: dict) -> dict:
    """The summary row's numbers of a pressure item: energy (a stance's total, the
    footprints' sum) and a stance's largest node-to-boundary distance."""
    if item.kind == "stance":
        return dict(energy=data["summary"]["energy"],
                    frame_distance=data["summary"]["node_distance_mm"])
    return dict(energy=sum(float(r["energy"]) for r in _rows(folder / "footprints.csv")))


def _rows(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


# ------------------------------------------------------------------------------ items


def pressure_items(source, kind: str | None = None) -> list[Item]:
    """The items of a file of many trials, or of jiku-data's set (``"jiku"``).

    A file holding ``(N, T, H, W)`` gives N ``stance`` items; ``(N, H, W)`` gives
    ``footprints`` items, one per subject (the NPZ's ``subject`` array) or one of them
    all; ``kind="stance"`` on ``(N, H, W)`` takes each image as a one-frame stance, and
    a single ``(T, H, W)`` stack gives one stance item. ``jiku``: 600 stance phases
    (``jiku-s<S>-t<T>``), or 10 subjects' peak images (``footprints``, the default).
    """
    if kind is not None and kind not in PRESSURE_KINDS:
        raise OptionError(f"kind must be one of {PRESSURE_KINDS}, got {kind!r}")
    name = os.fspath(source)
    if name == JIKU:
        from importlib.util import find_spec

        if find_spec("jikudata") is None:
            raise ImportError("jiku: the pressure data of Pataky et al. (2008) needs the "
                              "optional package jiku-data (GPL-3): pip install jiku-data")
        if kind == "stance":
            return [Item(id=f"jiku-s{s}-t{t:02d}", pressure=f"{JIKU}:{s}:{t}", study=kind)
                    for s in range(10) for t in range(60)]
        return [Item(id=f"jiku-s{s}", pressure=f"{JIKU}:{s}", study="footprints")
                for s in range(10)]
    path = os.fspath(Path(name).absolute())
    array, meta = _read_file(path)
    if array.ndim not in (3, 4):
        raise InputFileError(f"{name}: a file of many trials holds (N, T, H, W) stance "
                             f"phases or (N, H, W) peak images, got shape {array.shape}")
    kind = kind or ("stance" if array.ndim == 4 else "footprints")
    if kind == "footprints":
        if array.ndim != 3:
            raise InputFileError(f"{name}: footprints need (N, H, W) peak images, got "
                                 f"shape {array.shape}")
        if "subject" not in meta:
            return [Item(id=Path(name).stem, pressure=path, study=kind)]
        return [Item(id=f"subject-{s}", pressure=path, study=kind, trials=tuple(
            int(i) for i in np.flatnonzero(meta["subject"] == s)))
            for s in np.unique(meta["subject"])]
    if array.ndim == 3:
        return [Item(id=Path(name).stem, pressure=path, study=kind)]
    return [Item(id=f"trial-{i:03d}", pressure=path, study=kind, trials=(i,))
            for i in range(len(array))]


# ------------------------------------------------------------------------------ table


def _trial_rows(item: Item, folder: Path):
    """Per trial of a finished item: (subject, speed, area, energy, peak x, peak y)."""
    if item.kind == "stance":
        data = json.loads((folder / "result.json").read_text(encoding="utf-8"))
        s, meta = data["summary"], data.get("meta", {})
        yield (meta.get("subject", ""), meta.get("speed", ""), s["area_mm2"], s["energy"],
               s["peak_x_mm"], s["peak_y_mm"])
        return
    for r in _rows(folder / "footprints.csv"):
        yield (r.get("subject", ""), r.get("speed", ""), float(r["area_mm2"]),
               float(r["energy"]), float(r["peak_x_mm"]), float(r["peak_y_mm"]))


def write_groups(items, out: Path, done: set) -> Path | None:
    """``OUT/pressure.csv``: a row per kind, subject and walking speed over the finished
    pressure items (``done``: their ids): trials, mean area (mm^2), strain energy (median
    and quartiles), mean location of the energy's peak (mm). None without such items."""
    groups: dict = {}
    for item in items:
        if item.kind in PRESSURE_KINDS and item.id in done:
            for subject, speed, *numbers in _trial_rows(item, out / item.id):
                groups.setdefault((item.kind, str(subject), str(speed)), []).append(numbers)
    if not groups:
        return None
    path = out / "pressure.csv"
    with atomic_write(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(GROUP_COLUMNS)
        for key in sorted(groups, key=lambda k: (k[0], _natural(k[1]), _natural(k[2]))):
            a = np.array(groups[key], dtype=float)
            q1, median, q3 = np.percentile(a[:, 1], [25, 50, 75])
            writer.writerow([*key, len(a), *(f"{v:.6g}" for v in (
                a[:, 0].mean(), median, q1, q3, a[:, 2].mean(), a[:, 3].mean()))])
    return path


def _natural(text: str):
    """Numbers in order, then jiku-data's speeds slow, normal, fast, then other text."""
    try:
        return (0, float(text), "")
    except ValueError:
        order = list(_SPEEDS.values())
        return (1, order.index(text), "") if text in order else (2, 0.0, text)


# ------------------------------------------------------------------------------ command line


def add_pressure_flags(parser, taken: set) -> None:
    """``modalmorph batch``'s flags of the pressure items: ``--kind`` and a flag per
    :class:`StanceOptions` field not in ``taken`` (``--threshold`` is shared)."""
    parser.add_argument(
        "--kind", choices=PRESSURE_KINDS, default=None,
        help="with a pressure file of many trials (or jiku: jiku-data's set) in place of "
             "the manifest: stance (a stance phase per trial; default for (N, T, H, W)) or "
             "footprints (peak images registered to a template, per subject; default for "
             "(N, H, W) and jiku)")
    group = parser.add_argument_group("pressure items (stance, footprints)")
    for name, _cls, f in flat_fields((StanceOptions,)):
        if name not in taken:
            group.add_argument("--" + name.replace("_", "-"), dest=name, default=None,
                               metavar=f.metadata["kind"].upper(),
                               help=f"{f.metadata['help']} (default: {f.default})")


def batch_items(manifest, kind: str | None) -> list[Item]:
    """The items of ``modalmorph batch``: a manifest (CSV/TOML), or the trials of a
    pressure file (NPY/NPZ) or of jiku-data (``jiku``)."""
    from .manifest import read_manifest

    name = os.fspath(manifest)
    if name == JIKU or Path(name).suffix.lower() in (".npy", ".npz"):
        return pressure_items(name, kind)
    if kind is not None:
        raise OptionError(f"--kind is for a pressure file of many trials, not the "
                          f"manifest {name}")
    return read_manifest(manifest)


def batch_pressure(args, settings):
    """The batch's settings with the pressure options of ``modalmorph batch``'s flags."""
    values = {name: getattr(args, name) for name, _c, _f in flat_fields((StanceOptions,))
              if getattr(args, name, None) is not None}
    return replace(settings, stance=split(values, (StanceOptions,),
                                          where="options")[StanceOptions])
