"""Manifests: the items of a batch, from a CSV or TOML file.

An :class:`Item` is one ``modalmorph morph`` (a source, target pair), one ``modalmorph
track`` (a sequence of frames), one stance phase or one set of peak-pressure images
registered to a template (:mod:`.pressure`) with its own options; :func:`read_manifest`
reads them.
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from ...options import StanceOptions, split
from ..runs import BATCH_CLASSES, Settings

__all__ = ["Item", "PRESSURE_KINDS", "read_manifest"]

PRESSURE_KINDS = ("stance", "footprints")
_PATH_KEYS = ("id", "source", "target", "frames", "pressure")
# Manifest cells of a pressure item that are not options: which trials, the template,
# and the metadata that groups the batch's table (per subject and walking speed).
_PRESSURE_KEYS = ("kind", "trial", "trials", "template", "subject", "speed")
# Option sets of items found valid (checking one costs 0.8 ms: 0.8 s for 1 000 items).
_VALID_OPTIONS: set[str] = set()
_VALID_OPTIONS_KEPT = 4096


@dataclass(frozen=True)
class Item:
    """One unit of a batch: a pair to morph or a sequence to track.

    Attributes
    ----------
    id : str
        Name of the output folder ``OUT/<id>/``.
    source, target : str or None
        The pair's shape files (both, or neither for a sequence).
    frames : tuple of str
        A sequence's frames (anything :func:`modalmorph.io.read_frames` reads: a glob
        pattern, a folder, a stack, or several files); empty for a pair.
    options : dict
        Options for this item by flat name, as in a ``--config`` file (those of
        :func:`modalmorph.track` included: ``reference``, ``cycle``, ...; a pressure
        item's are those of :class:`~modalmorph.options.StanceOptions`); they override
        the batch's options.
    pressure : str or None
        A pressure item's input: an NPY/NPZ file or ``jiku:S[:T]`` (:mod:`.pressure`).
    study : str
        A pressure item's kind, ``"stance"`` or ``"footprints"``; empty otherwise.
    trials : tuple of int
        The trials of a file of many that the item takes (empty: the whole file).
    template : int, "mean" or None
        The template of ``footprints`` (None: the most typical image).
    meta : dict
        Metadata of the item's trials (``subject``, ``speed``) where the file has none.
    """

    id: str
    source: str | None = None
    target: str | None = None
    frames: tuple = ()
    options: dict = field(default_factory=dict)
    pressure: str | None = None
    study: str = ""
    trials: tuple = ()
    template: int | str | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.id, str) or not self.id or self.id.startswith(".") \
                or any(c in self.id for c in '/\\:*?"<>|'):
            raise ValueError(f"item id must be a plain folder name (no path separators, "
                             f"not starting with '.'), got {self.id!r}")
        if self.pressure is not None or self.study:
            self._check_pressure()
            return
        pair = self.source is not None and self.target is not None
        if pair == bool(self.frames) or (not pair and (self.source or self.target)):
            raise ValueError(f"item {self.id!r}: give either source and target (a pair) "
                             f"or frames (a sequence)")
        key = json.dumps(self.options, sort_keys=True, default=repr)
        if key not in _VALID_OPTIONS:  # the same options are checked once (long manifests)
            self.settings(Settings())  # refuses unknown names and invalid values
            if len(_VALID_OPTIONS) >= _VALID_OPTIONS_KEPT:
                _VALID_OPTIONS.clear()
            _VALID_OPTIONS.add(key)

    def _check_pressure(self) -> None:
        if self.study not in PRESSURE_KINDS or not self.pressure or self.source \
                or self.target or self.frames:
            raise ValueError(f"item {self.id!r}: a pressure item gives pressure (a file or "
                             f"jiku:S[:T]) and kind {' or '.join(PRESSURE_KINDS)}, "
                             f"got kind {self.study!r}")
        if not all(isinstance(t, int) and t >= 0 for t in self.trials):
            raise ValueError(f"item {self.id!r}: trials are numbers >= 0, got {self.trials}")
        if self.study == "stance" and len(self.trials) > 1:
            raise ValueError(f"item {self.id!r}: a stance item takes one trial, got "
                             f"{len(self.trials)}")
        split(dict(self.options), (StanceOptions,), where=f"item {self.id!r}")

    def settings(self, batch: Settings) -> Settings:
        """The batch's settings with this item's options over them."""
        return Settings.from_flat({**batch.flat(BATCH_CLASSES), **self.options},
                                  BATCH_CLASSES, where=f"item {self.id!r}")

    @property
    def kind(self) -> str:
        """``"pair"``, ``"sequence"``, ``"stance"`` or ``"footprints"``."""
        return self.study or ("sequence" if self.frames else "pair")

    @property
    def inputs(self) -> str:
        """The inputs in one line, for the summary."""
        if self.pressure is not None:
            picked = f" trials {' '.join(map(str, self.trials))}" if self.trials else ""
            return f"{self.pressure}{picked}"
        return " ".join(self.frames) if self.frames else f"{self.source} {self.target}"


# ------------------------------------------------------------------------------ manifest


def read_manifest(path) -> list[Item]:
    """Read the items of a batch from a CSV or TOML manifest.

    CSV: a header with ``source`` and ``target`` (pairs) and/or ``frames`` (sequences: a
    glob pattern, folder or stack file), optionally ``id`` and option columns named as in
    a ``--config`` file (``k``, ``method``, ``reference``, ...). A cell is read as a TOML
    value (``60``, ``true``, ``[0.5, 1.0]``), else as text (``local``, ``2/3``); an empty
    cell leaves the option to the batch. TOML: an array of ``[[item]]`` tables with the
    same keys (``frames`` may be a list of files). Relative paths are taken from the
    manifest's folder. The default id is ``<source stem>-<target stem>`` for a pair and
    the frames' folder name or file stem for a sequence.

    Raises
    ------
    ValueError
        Naming the manifest, the line or item and the problem; also for duplicate ids.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: manifest not found")
    rows = _toml_rows(path) if path.suffix.lower() == ".toml" else _csv_rows(path)
    items, seen = [], {}
    for where, row in rows:
        entry = _resolve(row, path.parent)
        try:
            item = Item(**entry)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
        if item.id in seen:
            raise ValueError(f"{where}: id {item.id!r} already used by {seen[item.id]}")
        seen[item.id] = where
        items.append(item)
    if not items:
        raise ValueError(f"{path}: the manifest lists no item")
    return items


def _toml_rows(path: Path):
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None
    unknown = set(data) - {"item"}
    if unknown or not isinstance(data.get("item", []), list):
        raise ValueError(f"{path}: a manifest holds [[item]] tables only, got "
                         f"{sorted(unknown) or 'item = ' + repr(data['item'])}")
    return [(f"{path}: item {i + 1}", dict(row)) for i, row in enumerate(data.get("item", []))]


def _csv_rows(path: Path):
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

    def value(text):
        try:
            return tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            return text

    with open(path, newline="", encoding="utf-8-sig") as fh:
        reader = csv.DictReader(fh, skipinitialspace=True)
        if not reader.fieldnames or not {"source", "frames", "pressure"} & set(
                reader.fieldnames):
            raise ValueError(f"{path}: the header must name source,target, frames and/or "
                             f"pressure, "
                             f"got {reader.fieldnames}")
        rows = []
        for row in reader:
            where = f"{path}: line {reader.line_num}"
            if None in row:
                raise ValueError(f"{where}: more cells than columns")
            cells = {k.strip(): v.strip() for k, v in row.items() if v and v.strip()}
            rows.append((where, {k: v if k in _PATH_KEYS else value(v)
                                 for k, v in cells.items()}))
    return rows


def _resolve(row: dict, base: Path) -> dict:
    """Item keyword arguments from a manifest row: paths from ``base``, a default id."""
    entry = {key: row.pop(key) for key in _PATH_KEYS if key in row}

    def absolute(p):
        return os.fspath(p if Path(p).is_absolute() else base.absolute() / p)

    if "pressure" in entry:
        _pressure_entry(entry, row, absolute)

    for key in ("source", "target"):
        if key in entry:
            entry[key] = absolute(str(entry[key]))
    if "frames" in entry:
        frames = entry["frames"]
        entry["frames"] = tuple(absolute(str(f)) for f in
                                (frames if isinstance(frames, list) else [frames]))
    if "id" not in entry:
        if "pressure" in entry:
            name = entry["pressure"]
            entry["id"] = name.replace(":", "-") if name.startswith("jiku:") else \
                Path(name).stem + "".join(f"-{t}" for t in entry.get("trials", ()))
        elif "frames" in entry:
            first = Path(entry["frames"][0])
            entry["id"] = first.parent.name if any(c in first.name for c in "*?[") \
                else first.stem
        else:
            entry["id"] = "-".join(Path(entry.get(k, "")).stem for k in ("source", "target"))
    entry["id"] = str(entry["id"])
    entry["options"] = row
    return entry


def _pressure_entry(entry: dict, row: dict, absolute) -> None:
    """A pressure row's item arguments: its kind (default: ``footprints`` for
    ``jiku:S``, else ``stance``), trials, template and metadata."""
    cells = {key: row.pop(key) for key in _PRESSURE_KEYS if key in row}
    name = str(entry["pressure"])
    jiku = name.startswith("jiku:")
    entry["pressure"] = name if jiku else absolute(name)
    entry["study"] = str(cells.pop("kind", "footprints" if jiku and name.count(":") == 1
                                   else "stance"))
    trials = cells.pop("trials", cells.pop("trial", []))
    entry["trials"] = tuple(trials if isinstance(trials, list) else [trials])
    if "template" in cells:
        entry["template"] = cells.pop("template")
    entry["meta"] = cells
