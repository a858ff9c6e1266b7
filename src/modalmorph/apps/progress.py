"""The command line's progress bars (rich, on a terminal only): one over a morph's steps or
a sequence's frames (:func:`progress_bar`), one over a batch's items
(:func:`batch_progress`)."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
import time

__all__ = ["progress_bar", "batch_progress", "interruptible"]

_INTERRUPTED: list[int] = []  # SIGINT seen during the command (interruptible)


@contextlib.contextmanager
def interruptible():
    """Ctrl-C that C code cannot swallow: SIGINT raises KeyboardInterrupt as Python's own
    handler does, and is remembered, so that each step of a progress bar raises it again
    where a C callback ignored it (numba's compiler, on the first match after installing:
    under load the run then went on to its end); the unraisable hook's report of that
    ignored interrupt is not printed."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        _INTERRUPTED.append(signum)
        raise KeyboardInterrupt

    def unraisable(info, hook=sys.unraisablehook):
        if not isinstance(info.exc_value, KeyboardInterrupt):
            hook(info)

    _INTERRUPTED.clear()
    previous, hook = signal.signal(signal.SIGINT, interrupt), sys.unraisablehook
    sys.unraisablehook = unraisable
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        sys.unraisablehook = hook
        _INTERRUPTED.clear()


def _check() -> None:
    """KeyboardInterrupt where a SIGINT was seen (:func:`interruptible`)."""
    if _INTERRUPTED:
        raise KeyboardInterrupt


@contextlib.contextmanager
def progress_bar(total: int | None, *, quiet: bool, what: str = "morphing", unit: str = "step"):
    """A rich progress bar on a terminal, completed to 100 % when the run ends (its total
    becomes the steps taken); nothing shown when quiet or not on a terminal. Each step
    raises a Ctrl-C that C code swallowed (:func:`interruptible`)."""
    if quiet or not sys.stderr.isatty():
        yield lambda step, distance: _check()
        return
    from rich.console import Console
    from rich.progress import Progress

    done = [0]
    with Progress(console=Console(stderr=True)) as bar:
        task = bar.add_task(what, total=total)

        def update(step, distance):
            _check()
            done[0] = step
            bar.update(task, completed=step, description=f"{what}: {unit} {step}" + (
                "" if distance is None else f", mean distance of matched pairs {distance:.3g}"))

        yield update
        bar.update(task, total=max(done[0], 1), completed=max(done[0], 1))



@contextlib.contextmanager
def batch_progress(*, quiet: bool):
    """One rich progress bar over the items to compute: done of total, failed, rate and
    ETA; nothing when quiet or not on a terminal."""
    if quiet or not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    columns = (TextColumn("batch"), BarColumn(), MofNCompleteColumn(),
               TextColumn("{task.fields[failed]} failed"),
               TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), TextColumn("ETA"),
               TimeRemainingColumn())
    failed, start = [0], time.perf_counter()
    with Progress(*columns, console=Console(stderr=True)) as bar:
        task = bar.add_task("batch", total=None, failed=0, rate="")

        def update(row, n_done, total):
            failed[0] += row is not None and row.status == "failed"
            rate = n_done / max(time.perf_counter() - start, 1e-9) * 60
            bar.update(task, completed=n_done, total=total, failed=failed[0],
                       rate=f"{rate:.0f} items/min" if n_done else "")

        yield update
