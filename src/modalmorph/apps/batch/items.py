"""One item of a batch: compute it into its folder, read its row back, decide whether a
folder on disk still answers the item (resume).

A worker runs :func:`run_item`; the batch's own process decides with :class:`Resume`
which items to send, and reads each row of the summary back from the disk
(:func:`summary_row`).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass, replace
from pathlib import Path

from ...errors import OptionError
from ...options import OutputOptions
from ..runs import (
    PAIR_CLASSES,
    SEQUENCE_CLASSES,
    Settings,
    file_record,
    input_records,
    morph_files,
    track_files,
)
from .manifest import Item
from .pressure import PRESSURE_KINDS, pressure_record, read_numbers, run_pressure

__all__ = ["ItemResult", "Outcome", "Resume", "RESULT_FILE", "STAGING_SUFFIX", "run_item",
           "failed_row", "read_row", "summary_row", "remove_staging"]

# The file that makes an item's folder complete (written last by morph / track).
RESULT_FILE = {"pair": "result.json", "sequence": "track.json", "stance": "result.json",
               "footprints": "result.json"}
# Hidden staging folders: OUT/.<id>.<attempt>.partial, one per attempt of an item.
STAGING_SUFFIX = ".partial"
# Input files whose SHA-256 is kept while a batch is planned (shared by many items).
_FILES_KEPT = 4096
# Option differences named in a redone item's note (the rest counted).
_NAMED_CHANGES = 3


@dataclass(frozen=True)
class ItemResult:
    """One row of the batch summary.

    ``status`` is ``"ok"`` (computed now), ``"skipped"`` (complete from an earlier run),
    ``"failed"`` (``error`` says why) or ``"interrupted"`` (not finished when the batch
    was stopped or its scheduler lost; ``error`` says which). ``note`` says why an item
    complete on disk was redone (its inputs or options changed, or ``--force``). The
    numbers come from the item's written results: ``steps`` (summed over a sequence's
    morphs), ``converged`` (all of them), ``distance`` and ``tolerance`` (a pair's stop
    test: ``result.json``'s ``distance``, within ``tolerance`` when converged; empty for
    a sequence), ``frame_distance`` (a sequence's largest two-way distance of the tracked
    shape to a frame; empty for a pair), ``energy`` (final strain energy; a sequence's
    ``cumulative_energy`` at its last frame: the energy of the morphs that reached it from
    frame 0, the one morph from frame 0 with ``reference="first"``),
    ``strain_min``/``strain_max`` (a sequence's global contour strain), ``seconds``
    (wall time of the item in its worker, when computed now).
    """

    id: str
    kind: str
    inputs: str
    status: str
    error: str = ""
    steps: int | None = None
    converged: bool | None = None
    distance: float | None = None
    tolerance: float | None = None
    frame_distance: float | None = None
    energy: float | None = None
    strain_min: float | None = None
    strain_max: float | None = None
    seconds: float | None = None
    note: str = ""


@dataclass(frozen=True)
class Outcome:
    """What this run did with one item (the numbers stay on disk until the summary)."""

    status: str
    error: str = ""
    seconds: float | None = None
    note: str = ""


def run_item(item: Item, out, *, settings: Settings | None = None, figures: str = "none",
             force: bool = False) -> ItemResult:
    """Compute one item into ``out/<id>/`` (the task each worker runs); never raises.

    The item is written into a hidden staging folder ``out/.<id>.<attempt>.partial/`` and
    renamed to ``out/<id>`` when complete, so ``out/<id>`` is complete or absent at every
    moment (two attempts of one item, e.g. on a worker thought lost, never share a
    folder). An item already complete there is skipped unless ``force``. ``settings`` are
    the batch's (``settings.stance``: the pressure items'); the item's own options
    override them.
    """
    out = Path(out)
    final = out / item.id
    if not force and (final / RESULT_FILE[item.kind]).is_file():
        return read_row(item, final, "skipped")
    staging = out / f".{item.id}.{os.getpid()}-{os.urandom(3).hex()}{STAGING_SUFFIX}"
    start = time.perf_counter()
    try:
        staging.mkdir(parents=True)  # the writer's temporary folder then lives inside it
        if item.kind in PRESSURE_KINDS:
            run_pressure(item, staging / item.id, (settings or Settings()).stance,
                         figures == "all")
        elif item.kind == "pair":
            own = item_settings(item, settings or Settings(), figures)
            morph_files(item.source, item.target, staging / item.id, own)
        else:
            track_files(list(item.frames), staging / item.id,
                        item_settings(item, settings or Settings(), figures))
        _publish(staging / item.id, final)
        return read_row(item, final, "ok", seconds=time.perf_counter() - start)
    except Exception as exc:  # any failure of one item is recorded; the batch goes on
        return failed_row(item, exc, seconds=time.perf_counter() - start)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def item_settings(item: Item, settings: Settings, figures: str) -> Settings:
    """The item's settings over the batch's, with the outputs of ``--figures``."""
    render = figures == "all"
    return replace(item.settings(settings), output=OutputOptions(figures=render, gif=render))


def _publish(ready: Path, final: Path) -> None:
    """Put a finished item folder in place by renames (atomic on one file system)."""
    if final.exists():  # redone: the old folder goes away only once the new one is ready
        os.replace(final, ready.parent / "old")
    os.replace(ready, final)


def read_row(item: Item, folder: Path, status: str, *, seconds: float | None = None,
             note: str = "") -> ItemResult:
    """The summary row of an item from the results written in its folder."""
    data = json.loads((folder / RESULT_FILE[item.kind]).read_text(encoding="utf-8"))
    if item.kind in PRESSURE_KINDS:
        numbers = read_numbers(item, folder, data)
    elif item.kind == "pair":
        numbers = dict(steps=data["steps"], converged=data["converged"],
                       distance=data.get("distance"), tolerance=data.get("tolerance"),
                       energy=data["energy"][-1])
    else:
        frames = data["frames"]
        strain = [f["strain"] for f in frames]
        numbers = dict(steps=sum(f["steps"] for f in frames),
                       converged=all(f["converged"] for f in frames),
                       frame_distance=max(f["distance"] for f in frames),
                       energy=frames[-1]["cumulative_energy"],
                       strain_min=min(strain), strain_max=max(strain))
    return ItemResult(id=item.id, kind=item.kind, inputs=item.inputs, status=status,
                      seconds=seconds, note=note, **numbers)


def failed_row(item: Item, exc: BaseException, *, seconds: float | None = None) -> ItemResult:
    """The row of an item that raised ``exc``: its first line as the error."""
    text = str(exc).strip()
    message = text.splitlines()[0] if text else ""
    if not isinstance(exc, ValueError | OSError):
        message = f"{type(exc).__name__}: {message}" if message else type(exc).__name__
    return ItemResult(id=item.id, kind=item.kind, inputs=item.inputs, status="failed",
                      error=message or type(exc).__name__, seconds=seconds)


def remove_staging(out: Path) -> None:
    """Remove the hidden staging folders that killed items left in ``out``."""
    with os.scandir(out) as entries:
        for entry in entries:
            if entry.name.startswith(".") and entry.name.endswith(STAGING_SUFFIX):
                shutil.rmtree(entry.path, ignore_errors=True)


# ------------------------------------------------------------------------------ resume


class Resume:
    """Whether each item's folder on disk answers the item as the batch would run it.

    An item is complete when its ``result.json`` (``track.json``) is there, and fresh when
    the SHA-256 of its inputs and its options equal those recorded there. Items with the
    same options share their settings (checked once).
    """

    def __init__(self, out: Path, settings: Settings, figures: str, *, force: bool = False,
                 keep_stale: bool = False):
        self.out, self.settings, self.figures = out, settings, figures
        self.force, self.keep_stale = force, keep_stale
        self._records: dict[str, dict] = {}
        self._files: dict[tuple, dict] = {}

    def why_redo(self, item: Item) -> str | None:
        """``None``: skip the item; ``""``: compute it (nothing on disk); else why it is
        redone although complete on disk."""
        path = self.out / item.id / RESULT_FILE[item.kind]
        if not path.is_file():
            return ""
        if self.force:
            return "redone: --force"
        if self.keep_stale:
            return None
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return "redone: its record is unreadable"
        return self._difference(item, data)

    def _difference(self, item: Item, data: dict) -> str | None:
        if item.kind in PRESSURE_KINDS:
            try:
                wanted = pressure_record(item, self.settings.stance, self._file)
            except (OptionError, ValueError):
                return "redone: its options are invalid"
            files, recorded = wanted["inputs"], data.get("inputs") or []
        else:
            files = (input_records(list(item.frames)) if item.frames
                     else [self._file(item.source), self._file(item.target)])
            recorded = data.get("input_files" if item.frames else "inputs") or []
        if [r["sha256"] for r in files] != [r.get("sha256") for r in recorded]:
            changed = [Path(r["path"]).name for r, old in zip(files, recorded, strict=False)
                       if r["sha256"] != old.get("sha256")]
            return ("redone: inputs changed" + (f" ({', '.join(changed[:_NAMED_CHANGES])})"
                                                if changed else " (number of files)"))
        wanted = wanted["options"] if item.kind in PRESSURE_KINDS else self._record(item)
        old = data.get("options") or {}
        changes = [f"{k} {_text(old.get(k))} -> {_text(v)}" for k, v in wanted.items()
                   if old.get(k) != v]
        if not changes:
            return None
        more = len(changes) - _NAMED_CHANGES
        return ("redone: options changed (" + ", ".join(changes[:_NAMED_CHANGES])
                + (f", {more} more" if more > 0 else "") + ")")

    def _file(self, path: str) -> dict:
        """:func:`file_record` of a file, hashed once while its size and time stay."""
        try:
            stat = os.stat(path)
        except OSError:
            return file_record(path)
        key = (path, stat.st_size, stat.st_mtime_ns)
        if key not in self._files:
            if len(self._files) >= _FILES_KEPT:
                self._files.clear()
            self._files[key] = file_record(path)
        return self._files[key]

    def _record(self, item: Item) -> dict:
        """The options ``result.json`` records for the item as JSON reads them back."""
        key = f"{item.kind}:{json.dumps(item.options, sort_keys=True, default=str)}"
        if key not in self._records:
            try:
                own = item_settings(item, self.settings, self.figures)
            except (OptionError, ValueError):
                own = None  # the item fails when computed; never fresh
            classes = SEQUENCE_CLASSES if item.frames else PAIR_CLASSES
            self._records[key] = ({"": None} if own is None
                                  else json.loads(json.dumps(own.record(classes))))
        return self._records[key]


def _text(value) -> str:
    return f"{value:g}" if isinstance(value, float) else repr(value)


def summary_row(item: Item, out: Path, outcome: Outcome | None, since: float,
                unfinished: str = "not finished when the batch stopped") -> ItemResult:
    """The summary row of an item, read from the disk with what this run did with it.

    An item without an ``outcome`` was not finished when the batch stopped; it counts as
    done now (``ok``) when its folder was written by this run (from ``since``, a
    ``time.time()``), e.g. by a worker stopped just after publishing it; else it is
    ``interrupted``, with ``unfinished`` as its error.
    """
    folder = out / item.id
    path = folder / RESULT_FILE[item.kind]
    try:
        if outcome is None and path.is_file() and path.stat().st_mtime >= since:
            return read_row(item, folder, "ok")
        if outcome is not None and outcome.status in ("ok", "skipped"):
            return read_row(item, folder, outcome.status, seconds=outcome.seconds,
                            note=outcome.note)
    except (OSError, ValueError, KeyError) as exc:
        return failed_row(item, exc)
    if outcome is None:
        kept = " (an earlier result is kept in its folder)" if path.is_file() else ""
        outcome = Outcome("interrupted", unfinished + kept)
    return ItemResult(id=item.id, kind=item.kind, inputs=item.inputs,
                      status=outcome.status, error=outcome.error, seconds=outcome.seconds,
                      note=outcome.note)
