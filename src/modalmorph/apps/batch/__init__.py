"""Batches: many pairs and sequences, on a local process pool or a Dask cluster, resumable.

Each item of a batch is one ``modalmorph morph`` (a source, target pair), one
``modalmorph track`` (a sequence of frames), one stance phase or one set of peak-pressure
images registered to a template (:mod:`.pressure`); it is computed and written by a
worker into ``OUT/<id>/``, exactly as the single command writes it
(:func:`modalmorph.apps.runs.morph_files`, :func:`modalmorph.apps.runs.track_files`,
``modalmorph stance``, ``modalmorph footprints``); pressure items also give
``OUT/pressure.csv``, a row per subject and walking speed. The folder appears at once,
by one rename of a finished staging folder, so a killed run leaves every item folder
complete or absent.

An item is skipped on the next run only when its folder answers it: the SHA-256 of its
inputs and its options equal those its ``result.json`` (``track.json``) records; else it
is redone and its summary row says why (``keep_stale`` skips every complete item). A
failing item is recorded with its one-line message and the batch goes on.
``OUT/summary.csv`` (and ``summary.parquet`` with pyarrow) has a row per item, rewritten
from the disk on every run and streamed, so it always agrees with the item folders.

The engine (:class:`Engine`) is a local process pool by default, or Dask
(``pip install modalmorph[dask]``): a scheduler address, a ``dask.distributed.Client``,
or a ``LocalCluster``.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from ...errors import OptionError
from ..runs import Settings
from .engines import ENGINES, Engine, SchedulerLost
from .items import (
    ItemResult,
    Outcome,
    Resume,
    remove_staging,
    run_item,
    summary_row,
)
from .manifest import Item, read_manifest
from .pressure import pressure_items, write_groups
from .summary import read_summary, write_summary

__all__ = ["FIGURES", "ENGINES", "Engine", "Item", "ItemResult", "Batch", "SchedulerLost",
           "pressure_items", "read_manifest", "read_summary", "run", "run_item",
           "write_summary"]

log = logging.getLogger(__name__)

FIGURES = ("none", "summary", "all")
_SKIPPED = Outcome("skipped")


@dataclass(frozen=True)
class Batch:
    """The outcome of :func:`run`: how many items ended how, and where it was written.

    Attributes
    ----------
    out : Path
    counts : dict
        Items per status (``ok``, ``skipped``, ``failed``, ``interrupted``).
    files : tuple of Path
        The summary files written (``summary.csv``, ``summary.parquet``, ``summary.png``,
        ``pressure.csv``).
    engine : str
        What ran the items, in words (e.g. ``"local process pool, 2 workers"``); empty
        when every item was skipped.
    dashboard : str or None
        The Dask dashboard's address, when there is one.
    interrupted : bool
        Whether the batch was stopped (Ctrl-C) before every item was done.
    lost : str
        Why the batch stopped early when its Dask scheduler was lost (else empty).
    """

    out: Path
    counts: dict
    files: tuple
    engine: str
    dashboard: str | None = None
    interrupted: bool = False
    lost: str = ""

    @property
    def results(self) -> tuple:
        """The summary rows (:class:`ItemResult`), in the order of the items, read back
        from ``summary.csv`` (:meth:`rows` reads them one at a time)."""
        return tuple(self.rows())

    def rows(self) -> Iterator[ItemResult]:
        """The summary rows one at a time, from ``summary.csv``."""
        return read_summary(self.out)

    @property
    def ok(self) -> bool:
        """Whether every item is complete (computed now or before)."""
        return sum(self.counts.get(s, 0) for s in ("ok", "skipped")) == sum(
            self.counts.values())


def run(items: Sequence[Item], out, *, settings: Settings | None = None,
        figures: str = "none", force: bool = False, keep_stale: bool = False,
        engine: Engine | None = None,
        progress: Callable[[ItemResult | None, int, int], None] | None = None) -> Batch:
    """Run the items of a batch that the disk does not answer; write ``out/summary.csv``.

    Parameters
    ----------
    items : sequence of Item
        From :func:`read_manifest`, or built directly.
    out : str or os.PathLike
        Output folder: ``out/<id>/`` per item, and the summary.
    settings : Settings, optional
        Options for every item (:class:`modalmorph.apps.runs.Settings`; its ``stance``:
        those of the pressure items); an item's own win.
    figures : {"none", "summary", "all"}, optional
        ``"none"`` (default): results only; ``"summary"``: also ``out/summary.png``,
        rendered once; ``"all"``: each item's figures and animation too, rendered by its
        worker.
    force : bool, optional
        Redo items already complete in ``out``.
    keep_stale : bool, optional
        Skip every item complete in ``out`` without comparing its recorded inputs and
        options with the batch's (by default an item whose inputs or options changed is
        redone).
    engine : Engine, optional
        A local process pool or Dask (default ``Engine()``: chosen by the measured
        start-up and per-item costs, said in the log).
    progress : callable, optional
        Called as ``progress(None, 0, n)`` when the ``n`` items to compute are known,
        then as each of them ends: ``progress(row, n_done, n)``.

    Returns
    -------
    Batch
        The counts and files; ``interrupted`` when Ctrl-C stopped it, ``lost`` when the
        Dask scheduler went away (the items finished by then are complete and recorded).
    """
    if figures not in FIGURES:
        raise OptionError(f"figures must be one of {FIGURES}, got {figures!r}")
    _check_ids(items)
    out = Path(out).absolute()  # workers elsewhere get the same path
    out.mkdir(parents=True, exist_ok=True)
    since = time.time()
    remove_staging(out)  # of killed items, whether they are redone or skipped now
    settings = settings or Settings()
    resume = Resume(out, settings, figures, force=force, keep_stale=keep_stale)
    outcomes, todo, notes = {}, [], {}
    for item in items:
        why = resume.why_redo(item)
        if why is None:
            outcomes[item.id] = _SKIPPED
        else:
            todo.append(item)
            if why:
                notes[item.id] = why
    log.info("%d of %d items to compute, %d complete in %s", len(todo), len(items),
             len(items) - len(todo), out)
    state = _execute(todo, dict(out=out, settings=settings, figures=figures, force=True),
                     engine or Engine(), outcomes, notes, progress)
    remove_staging(out)  # of items stopped midway
    unfinished = state["lost"] or "not finished when the batch was stopped"
    counts = Counter()
    rows = (summary_row(item, out, outcomes.get(item.id), since, unfinished)
            for item in items)
    files = write_summary(_counted(rows, counts), out, figure=figures == "summary")
    done = {i for i, o in outcomes.items() if o.status in ("ok", "skipped")}
    table = write_groups(items, out, done)
    files += [table] if table is not None else []
    return Batch(out=out, counts=dict(counts), files=tuple(files), engine=state["engine"],
                 dashboard=state["dashboard"], interrupted=state["interrupted"],
                 lost=state["lost"])


def _check_ids(items) -> None:
    ids = Counter(item.id for item in items)
    repeated = sorted(i for i, n in ids.items() if n > 1)
    if repeated:
        raise ValueError(f"items must have distinct ids; repeated: {repeated}")


def _execute(todo, task, engine, outcomes, notes, progress) -> dict:
    """Compute the ``todo`` items on the engine, recording each outcome as it ends."""
    state = dict(engine="", dashboard=None, interrupted=False, lost="")
    if progress is not None:
        progress(None, 0, len(todo))
    if not todo:
        return state

    def done(item, row):
        row = replace(row, note=notes.get(item.id, ""))
        outcomes[item.id] = Outcome(row.status, row.error, row.seconds, row.note)
        if progress is not None:
            progress(row, len(outcomes) - skipped, len(todo))

    skipped = len(outcomes)
    try:
        with engine.start(len(todo)) as runner:
            state.update(engine=runner.name, dashboard=runner.dashboard)
            log.info("engine: %s", runner.name)
            if runner.dashboard:
                log.info("Dask dashboard: %s", runner.dashboard)
            runner.run(todo, task, done)
    except KeyboardInterrupt:
        state["interrupted"] = True
    except SchedulerLost as exc:
        state["lost"] = str(exc)
    return state


def _counted(rows, counts: Counter):
    for row in rows:
        counts[row.status] += 1
        yield row
