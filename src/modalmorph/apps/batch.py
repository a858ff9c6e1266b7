"""Batches: many pairs and sequences, on a Dask cluster or a local process pool, resumable.

Each item of a batch is one ``modalmorph morph`` (a source, target pair) or one
``modalmorph track`` (a sequence of frames); it is computed and written by a worker into
``OUT/<id>/``, exactly as the single command writes it (:func:`modalmorph.apps.runs.morph_files`,
:func:`modalmorph.apps.runs.track_files`). The folder appears at once, by one rename of a
finished staging folder, so a killed run leaves every item folder complete or absent, and
an item whose folder exists is skipped on the next run. A failing item is recorded with its
one-line message and the batch goes on. ``OUT/summary.csv`` (and ``summary.parquet`` with
pyarrow) has a row per item.

The engine is Dask (``pip install modalmorph[dask]``): a ``LocalCluster`` of single-threaded
worker processes, a scheduler address, or a ``dask.distributed.Client``; without Dask, a
local process pool.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import csv
import logging
import multiprocessing
import os
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from ..errors import OptionError
from ..figures import plot_batch
from ..io import atomic_write
from ..options import OutputOptions
from .runs import BATCH_CLASSES, Settings, morph_files, track_files

__all__ = ["FIGURES", "ENGINES", "Engine", "Item", "ItemResult", "Batch", "read_manifest",
           "run", "run_item", "write_summary"]

log = logging.getLogger(__name__)

FIGURES = ("none", "summary", "all")
ENGINES = ("auto", "dask", "processes")
# Each worker process computes with one BLAS thread, so N workers use N cores without
# oversubscription (a loop of 4 pairs on 2 cores lost time to BLAS threads fighting).
_ONE_THREAD = {name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                      "MKL_NUM_THREADS")}
_PATH_KEYS = ("id", "source", "target", "frames")
# Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which turns off glibc's
# dynamic mmap threshold: every array over 128 kB is mmap'ed and unmapped again. A heart
# pair (247 -> 180 nodes) then costs 0.28 s of CPU in the worker instead of 0.19 s (+47 %,
# 20 pairs, 1 worker); the local cluster leaves glibc's default. Its statistical profiler
# (a stack sample every 10 ms) added another 4 % of CPU (0.194 -> 0.187 s per pair).
_DASK_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                "distributed.worker.profile.enabled": False}


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
        :func:`modalmorph.track` included: ``reference``, ``cycle``, ...); they override
        the batch's options.
    """

    id: str
    source: str | None = None
    target: str | None = None
    frames: tuple = ()
    options: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.id, str) or not self.id or self.id.startswith(".") \
                or any(c in self.id for c in '/\\:*?"<>|'):
            raise ValueError(f"item id must be a plain folder name (no path separators, "
                             f"not starting with '.'), got {self.id!r}")
        pair = self.source is not None and self.target is not None
        if pair == bool(self.frames) or (not pair and (self.source or self.target)):
            raise ValueError(f"item {self.id!r}: give either source and target (a pair) "
                             f"or frames (a sequence)")
        self.settings(Settings())  # refuses unknown names and invalid values

    def settings(self, batch: Settings) -> Settings:
        """The batch's settings with this item's options over them."""
        return Settings.from_flat({**batch.flat(BATCH_CLASSES), **self.options},
                                  BATCH_CLASSES, where=f"item {self.id!r}")

    @property
    def kind(self) -> str:
        """``"pair"`` or ``"sequence"``."""
        return "sequence" if self.frames else "pair"

    @property
    def inputs(self) -> str:
        """The inputs in one line, for the summary."""
        return " ".join(self.frames) if self.frames else f"{self.source} {self.target}"


@dataclass(frozen=True)
class ItemResult:
    """One row of the batch summary.

    ``status`` is ``"ok"`` (computed now), ``"skipped"`` (complete from an earlier run),
    ``"failed"`` (``error`` says why) or ``"interrupted"`` (not finished when the batch
    was stopped). The numbers come from the item's written results: ``steps`` (summed
    over a sequence's morphs), ``converged`` (all of them), ``distance`` (the final mean
    distance of a pair's matched nodes to their partners; a sequence's largest distance
    to a frame), ``energy`` (final strain energy; a sequence's cumulative energy),
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
    energy: float | None = None
    strain_min: float | None = None
    strain_max: float | None = None
    seconds: float | None = None


@dataclass(frozen=True)
class Batch:
    """The outcome of :func:`run`: a summary row per item and where it was written.

    Attributes
    ----------
    out : Path
    results : tuple of ItemResult
        In the order of the items.
    files : tuple of Path
        The summary files written (``summary.csv``, ``summary.parquet``, ``summary.png``).
    engine : str
        What ran the items, in words (e.g. ``"Dask LocalCluster, 2 workers"``).
    dashboard : str or None
        The Dask dashboard's address, when there is one.
    interrupted : bool
        Whether the batch was stopped (Ctrl-C) before every item was done.
    """

    out: Path
    results: tuple
    files: tuple
    engine: str
    dashboard: str | None = None
    interrupted: bool = False

    @property
    def ok(self) -> bool:
        """Whether every item is complete (computed now or before)."""
        return all(row.status in ("ok", "skipped") for row in self.results)


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
        if not reader.fieldnames or not {"source", "frames"} & set(reader.fieldnames):
            raise ValueError(f"{path}: the header must name source,target and/or frames, "
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

    for key in ("source", "target"):
        if key in entry:
            entry[key] = absolute(str(entry[key]))
    if "frames" in entry:
        frames = entry["frames"]
        entry["frames"] = tuple(absolute(str(f)) for f in
                                (frames if isinstance(frames, list) else [frames]))
    if "id" not in entry:
        if "frames" in entry:
            first = Path(entry["frames"][0])
            entry["id"] = first.parent.name if any(c in first.name for c in "*?[") \
                else first.stem
        else:
            entry["id"] = "-".join(Path(entry.get(k, "")).stem for k in ("source", "target"))
    entry["id"] = str(entry["id"])
    entry["options"] = row
    return entry


# ------------------------------------------------------------------------------ one item


def run_item(item: Item, out, *, settings: Settings | None = None, figures: str = "none",
             force: bool = False) -> ItemResult:
    """Compute one item into ``out/<id>/`` (the task each worker runs); never raises.

    The item is written into a hidden staging folder ``out/.<id>.partial/`` and renamed
    to ``out/<id>`` when complete, so ``out/<id>`` is complete or absent at every moment.
    An item already complete there is skipped unless ``force``. ``settings`` are the
    batch's; the item's own options override them.
    """
    out = Path(out)
    final = out / item.id
    if not force and (final / _RESULT_FILE[item.kind]).is_file():
        return _row(item, final, "skipped")
    staging = out / f".{item.id}.partial"
    start = time.perf_counter()
    try:
        shutil.rmtree(staging, ignore_errors=True)  # left by a killed run
        staging.mkdir(parents=True)  # the writer's temporary folder then lives inside it
        render = figures == "all"
        own = replace(item.settings(settings or Settings()),
                      output=OutputOptions(figures=render, gif=render))
        if item.kind == "pair":
            morph_files(item.source, item.target, staging / item.id, own)
        else:
            track_files(list(item.frames), staging / item.id, own)
        _publish(staging / item.id, final)
        return _row(item, final, "ok", seconds=time.perf_counter() - start)
    except Exception as exc:  # any failure of one item is recorded; the batch goes on
        return _failed(item, exc, seconds=time.perf_counter() - start)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


_RESULT_FILE = {"pair": "result.json", "sequence": "track.json"}


def _publish(ready: Path, final: Path) -> None:
    """Put a finished item folder in place by renames (atomic on one file system)."""
    if final.exists():  # --force: the old folder goes away only once the new one is ready
        old = ready.parent / "old"
        os.replace(final, old)
    os.replace(ready, final)


def _row(item: Item, folder: Path, status: str, *, seconds: float | None = None):
    import json

    data = json.loads((folder / _RESULT_FILE[item.kind]).read_text(encoding="utf-8"))
    if item.kind == "pair":
        numbers = dict(steps=data["steps"], converged=data["converged"],
                       distance=data["mean_distance"][-1], energy=data["energy"][-1])
    else:
        frames = data["frames"]
        strain = [f["strain"] for f in frames]
        numbers = dict(steps=sum(f["steps"] for f in frames),
                       converged=all(f["converged"] for f in frames),
                       distance=max(f["distance"] for f in frames),
                       energy=frames[-1]["cumulative_energy"],
                       strain_min=min(strain), strain_max=max(strain))
    return ItemResult(id=item.id, kind=item.kind, inputs=item.inputs, status=status,
                      seconds=seconds, **numbers)


def _failed(item: Item, exc: BaseException, *, seconds: float | None = None) -> ItemResult:
    text = str(exc).strip()
    message = text.splitlines()[0] if text else ""
    if not isinstance(exc, ValueError | OSError):
        message = f"{type(exc).__name__}: {message}" if message else type(exc).__name__
    return ItemResult(id=item.id, kind=item.kind, inputs=item.inputs, status="failed",
                      error=message or type(exc).__name__, seconds=seconds)


# ------------------------------------------------------------------------------ the batch


@dataclass(frozen=True)
class Engine:
    """What runs the items of a batch.

    Attributes
    ----------
    kind : {"auto", "dask", "processes"}
        ``"auto"``: Dask when installed, else a local process pool (with a warning).
    workers : int, optional
        Worker processes of a local cluster or pool (default: one per core).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:port``).
    client : dask.distributed.Client, optional
        Run on this client's cluster (it is left open).
    """

    kind: str = "auto"
    workers: int | None = None
    scheduler: str | None = None
    client: object = None

    def __post_init__(self):
        if self.kind not in ENGINES:
            raise OptionError(f"engine must be one of {ENGINES}, got {self.kind!r}")
        if self.workers is not None and (isinstance(self.workers, bool) or self.workers < 1):
            raise OptionError(f"workers must be a positive integer, got {self.workers!r}")
        if self.kind == "processes" and (self.client is not None
                                         or self.scheduler is not None):
            raise OptionError("engine 'processes' cannot use a Dask client or scheduler")

    def uses_dask(self) -> bool:
        """Whether the items run on Dask (said once in the log when it is missing)."""
        if self.client is not None or self.scheduler is not None or self.kind == "dask":
            return True
        if self.kind == "processes":
            return False
        try:
            import distributed  # noqa: F401
            return True
        except ImportError:
            log.warning("Dask is not installed (pip install 'modalmorph[dask]'): running "
                        "the batch in a local process pool")
            return False

    def start(self):
        """The context of :func:`_on_dask` or :func:`_on_processes`."""
        workers = self.workers or len(os.sched_getaffinity(0))
        if self.uses_dask():
            return _on_dask(self.client, self.scheduler, workers)
        return _on_processes(workers)


def run(items: Sequence[Item], out, *, settings: Settings | None = None,
        figures: str = "none", force: bool = False, engine: Engine | None = None,
        progress: Callable[[ItemResult, int, int], None] | None = None) -> Batch:
    """Run every item of a batch and write ``out/summary.csv``.

    Parameters
    ----------
    items : sequence of Item
        From :func:`read_manifest`, or built directly.
    out : str or os.PathLike
        Output folder: ``out/<id>/`` per item, and the summary.
    settings : Settings, optional
        Options for every item (:class:`modalmorph.apps.runs.Settings`); an item's own win.
    figures : {"none", "summary", "all"}, optional
        ``"none"`` (default): results only; ``"summary"``: also ``out/summary.png``,
        rendered once; ``"all"``: each item's figures and animation too, rendered by its
        worker.
    force : bool, optional
        Redo items already complete in ``out``.
    engine : Engine, optional
        Dask or a local process pool (default ``Engine()``: Dask when installed).
    progress : callable, optional
        Called as each item ends: ``progress(row, n_done, n_items)``.

    Returns
    -------
    Batch
        The summary rows; ``interrupted`` when Ctrl-C stopped it (the items finished by
        then are complete and recorded).
    """
    if figures not in FIGURES:
        raise OptionError(f"figures must be one of {FIGURES}, got {figures!r}")
    items = list(items)
    ids = [item.id for item in items]
    if len(set(ids)) != len(ids):
        raise ValueError(f"items must have distinct ids; repeated: "
                         f"{sorted({i for i in ids if ids.count(i) > 1})}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows: dict[str, ItemResult] = {}

    def done(row):
        rows[row.id] = row
        if progress is not None:
            progress(row, len(rows), len(items))

    task = dict(out=out, settings=settings or Settings(), figures=figures, force=force)
    interrupted = False
    with _one_blas_thread(), (engine or Engine()).start() as (submit, wait, name, dashboard):
        try:
            wait({submit(item, task): item for item in items}, done)
        except KeyboardInterrupt:
            interrupted = True
    results = tuple(rows.get(item.id) or ItemResult(
        id=item.id, kind=item.kind, inputs=item.inputs, status="interrupted",
        error="not finished when the batch was stopped") for item in items)
    files = write_summary(results, out, figure=figures == "summary")
    return Batch(out=out, results=results, files=tuple(files), engine=name,
                 dashboard=dashboard, interrupted=interrupted)


@contextlib.contextmanager
def _one_blas_thread():
    """Worker processes started in this block compute with one BLAS thread each."""
    saved = {key: os.environ.get(key) for key in _ONE_THREAD}
    os.environ.update(_ONE_THREAD)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


@contextlib.contextmanager
def _on_dask(client, scheduler, workers):
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as exc:
        raise ImportError("a Dask engine, scheduler or client needs Dask: pip install "
                          "'modalmorph[dask]'") from exc

    with contextlib.ExitStack() as stack:
        if client is None and scheduler is not None:
            client = stack.enter_context(Client(scheduler))
            name = f"Dask scheduler {scheduler}"
        elif client is None:
            import dask

            with dask.config.set(_DASK_CONFIG):  # read when the workers are spawned
                # a free port for the dashboard: several batches may run on one machine
                cluster = stack.enter_context(LocalCluster(
                    n_workers=workers, threads_per_worker=1, processes=True,
                    dashboard_address=":0"))
            client = stack.enter_context(Client(cluster))
            name = f"Dask LocalCluster, {workers} workers"
        else:
            name = f"Dask client {client.scheduler.address}"
        dashboard = client.dashboard_link
        log.info("Dask dashboard: %s", dashboard)

        def submit(item, task):
            return client.submit(run_item, item, pure=False, key=f"item-{item.id}-"
                                 f"{os.urandom(4).hex()}", **task)

        def wait(futures, done):
            try:
                for future in as_completed(futures):
                    item = futures[future]
                    try:
                        done(future.result())
                    except Exception as exc:  # the worker died (KilledWorker), ...
                        done(_failed(item, exc))
            finally:  # Ctrl-C: what has not started will not
                client.cancel([future for future in futures if not future.done()])

        yield submit, wait, name, dashboard


@contextlib.contextmanager
def _on_processes(workers):
    # spawn: fresh interpreters that start with one BLAS thread (the environment above)
    pool = concurrent.futures.ProcessPoolExecutor(
        workers, mp_context=multiprocessing.get_context("spawn"))

    def submit(item, task):
        return pool.submit(run_item, item, **task)

    def wait(futures, done):
        try:
            for future in concurrent.futures.as_completed(futures):
                try:
                    done(future.result())
                except Exception as exc:  # a worker process died (BrokenProcessPool)
                    done(_failed(futures[future], exc))
        finally:
            for future in futures:
                future.cancel()

    try:
        yield submit, wait, f"local process pool, {workers} workers", None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


# ------------------------------------------------------------------------------ summary


def write_summary(results: Sequence[ItemResult], out, *, figure: bool = False) -> list[Path]:
    """Write ``out/summary.csv``, ``summary.parquet`` (when pyarrow is installed) and,
    with ``figure``, ``summary.png``; each file atomically. Returns the paths written."""
    out = Path(out)
    columns = [f.name for f in fields(ItemResult)]
    records = [asdict(row) for row in results]
    written = [out / "summary.csv"]
    with atomic_write(written[0]) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        writer.writerows({k: "" if v is None else v for k, v in r.items()} for r in records)
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        pass
    else:
        types = {"steps": pa.int64(), "converged": pa.bool_(), "error": pa.string()}
        schema = pa.schema([(c, types.get(c, pa.float64() if c in _FLOAT_COLUMNS
                                          else pa.string())) for c in columns])
        written.append(out / "summary.parquet")
        with atomic_write(written[-1]) as tmp:
            pq.write_table(pa.Table.from_pylist(records, schema=schema), tmp)
    if figure:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(6.4, 4.4))  # no pyplot: no figure left open
        plot_batch(results, ax=fig.add_subplot())
        written.append(out / "summary.png")
        with atomic_write(written[-1]) as tmp:
            fig.savefig(tmp, dpi=150, bbox_inches="tight")
    return written


_FLOAT_COLUMNS = ("distance", "energy", "strain_min", "strain_max", "seconds")
