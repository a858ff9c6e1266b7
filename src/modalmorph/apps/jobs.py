"""The app's runs: each a call of morph() on a bounded pool of threads, with its progress,
a Stop that works whether it waits or runs, and its files, removed when it expires."""

from __future__ import annotations

import json
import logging
import shutil
import threading
import time
import uuid
from concurrent.futures import ThreadPoolExecutor
from http import HTTPStatus
from pathlib import Path

from .. import figures
from ..io import save_result
from .form import field_of
from .policy import APP_LIMITS, AppLimits, Refused
from .report import result_payload, write_html
from .runs import FORM_CLASSES, Settings, compute_morph

__all__ = ["FILES", "Job", "Jobs", "Stopped"]

log = logging.getLogger(__name__)

FILES = ("morph.json", "result.json", "shapes.npz", "final_shape.csv", "report.html",
         "shapes_plain.png", "shapes_load.png", "shapes_energy.png", "matches.png",
         "energy.png", "morph.gif")


class Stopped(Exception):
    """Raised from the progress callback when the run is stopped (by the user, by its
    eviction from the table, or by the server's shutdown)."""


class Job:
    """One run of morph(): "queued", "running", then "done" or "error"."""

    def __init__(self, source, target, settings: Settings, folder: Path, title: str,
                 images: dict):
        self.source, self.target, self.settings = source, target, settings
        self.folder, self.title, self.images = folder, title, images
        self.state, self.step, self.distance = "queued", 0, None
        self.error = self.field = self.result = self.payload = None
        self.finished_at: float | None = None
        self.stop = threading.Event()
        self.why_stopped = "stopped by the user"
        self.lock = threading.Lock()

    def cancel(self, why: str) -> None:
        """Stop the run at its next step (or before it starts)."""
        self.why_stopped = why
        self.stop.set()

    def _progress(self, step: int, distance: float) -> None:
        self.step, self.distance = step, distance
        if self.stop.is_set():
            raise Stopped(f"{self.why_stopped} at step {step}")

    def run(self) -> None:
        """Compute (on a worker thread); every outcome ends in a state and a message."""
        try:
            if self.stop.is_set():
                raise Stopped(f"{self.why_stopped} before it started")
            self.state = "running"
            result = compute_morph(self.source, self.target, self.settings,
                                   progress=self._progress)
            self.payload = result_payload(result, title=self.title, images=self.images)
            self.result, self.state = result, "done"
        except (ValueError, ArithmeticError, Stopped) as exc:  # MorphDivergedError too
            self.error, self.state = str(exc).splitlines()[0], "error"
            self.field = field_of(self.error)
        except Exception as exc:  # reported to the page, logged in full here
            log.exception("morph failed")
            self.error, self.state = f"internal error: {type(exc).__name__}: {exc}", "error"
        finally:
            self.finished_at = time.monotonic()

    @property
    def active(self) -> bool:
        return self.state in ("queued", "running")

    def status(self) -> dict:
        return dict(state=self.state, step=self.step, distance=self.distance,
                    max_steps=self.settings.morph.max_steps, error=self.error,
                    field=self.field, files=list(FILES) if self.state == "done" else [])

    def file(self, name: str) -> Path:
        """Write (once) and return a download."""
        if name not in FILES or self.state != "done":
            raise FileNotFoundError(name)
        path = self.folder / name
        with self.lock:
            if not path.exists():
                self._write(name)
        return path

    def _write(self, name: str) -> None:
        r, out = self.result, self.folder
        if name == "morph.json":
            (out / name).write_text(json.dumps(self.payload, allow_nan=False), "utf-8")
        elif name in ("result.json", "shapes.npz", "final_shape.csv"):
            save_result(r, out, options=self.settings.record(FORM_CLASSES))
        elif name == "report.html":
            write_html(r, out / name, title=self.title, images=self.images)
        elif name == "morph.gif":
            figures.animate(r, out / name)
        else:
            figures.save_figures(r, out, formats=("png",), dpi=120)


class Jobs:
    """The table of runs: at most ``max_running`` computed at once and ``max_queued``
    waiting, ``keep`` remembered (a forgotten run is cancelled and its folder removed),
    a finished one expired after ``job_ttl`` seconds."""

    def __init__(self, root: Path, limits: AppLimits = APP_LIMITS):
        self.root, self.limits = Path(root), limits
        self.table: dict[str, Job] = {}
        self.lock = threading.Lock()
        self.pool = ThreadPoolExecutor(max_workers=limits.max_running,
                                       thread_name_prefix="modalmorph-run")

    def submit(self, source, target, settings: Settings, title: str, images: dict) -> str:
        """Queue a run; :class:`Refused` (429) when the queue is full."""
        with self.lock:
            self._expire()
            active = sum(job.active for job in self.table.values())
            most = self.limits.max_running + self.limits.max_queued
            if active >= most:
                raise Refused(HTTPStatus.TOO_MANY_REQUESTS, f"too many runs: {active} running "
                              f"or queued, the limit (max_running + max_queued) is {most}; "
                              "wait for one to finish or stop one")
            jid = uuid.uuid4().hex
            folder = self.root / jid
            folder.mkdir()
            job = Job(source, target, settings, folder, title, images)
            self.table[jid] = job
            self._evict()
        self.pool.submit(job.run)
        return jid

    def get(self, jid: str) -> Job | None:
        with self.lock:
            self._expire()
            return self.table.get(jid)

    def _forget(self, jid: str, why: str) -> None:
        job = self.table.pop(jid)
        job.cancel(why)
        shutil.rmtree(job.folder, ignore_errors=True)

    def _evict(self) -> None:
        """Forget the oldest runs beyond ``keep``, finished ones first."""
        while len(self.table) > self.limits.keep:
            done = [jid for jid, job in self.table.items() if not job.active]
            self._forget((done or list(self.table))[0], "stopped: pushed out of the table")

    def _expire(self) -> None:
        now = time.monotonic()
        old = [jid for jid, job in self.table.items() if job.finished_at is not None
               and now - job.finished_at > self.limits.job_ttl]
        for jid in old:
            self._forget(jid, "expired")

    def close(self) -> None:
        """Cancel every run and wait for the workers (each stops at its next step)."""
        with self.lock:
            for jid in list(self.table):
                self._forget(jid, "stopped: the server is shutting down")
        self.pool.shutdown(wait=True, cancel_futures=True)
