"""The read guard: a reader runs with bounded time, and every failure of it becomes an
:class:`~modalmorph.errors.InputFileError` whose message starts with the file's name."""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from pathlib import Path

from ..errors import InputFileError
from ..options import ReadOptions
from .base import RawShape, Reader

__all__ = ["READ_SECONDS", "READ_SECONDS_PER_MB", "ReadTimeout", "deadline", "guarded",
           "read_guarded"]

# A read that takes longer than this is stopped (a parser stuck on a malformed file): base
# seconds plus seconds per MB. The slowest reader measured, meshio on ASCII PLY, takes
# 0.12 s per MB (100k vertices and 200k triangles, 9.8 MB, 1.17 s on a loaded 2-core
# machine; OBJ 0.075, Gmsh 0.061, OFF and VTK 0.02 s/MB): a margin of about 17x.
READ_SECONDS = 10.0
READ_SECONDS_PER_MB = 2.0


def read_guarded(reader: Reader, path: Path, name: str, options: ReadOptions) -> RawShape:
    """``reader(path, name, options)`` under :func:`guarded`."""
    with guarded(name, path.stat().st_size):
        return reader(path, name, options)


@contextmanager
def guarded(name: str, size: int):
    """Run the block (the read of file ``name`` of ``size`` bytes) with bounded time;
    every failure an InputFileError naming the file.

    Third-party parsers raise many types for a malformed file (and numpy a MemoryError for
    an absurd size in a header); they are reported as the file's problem. A parse that runs
    past its deadline (:data:`READ_SECONDS`, more for large files) is interrupted. An
    InputFileError passes as it is (it names its file, or its frame).
    """
    seconds = READ_SECONDS + READ_SECONDS_PER_MB * size / 1e6
    try:
        with deadline(seconds):
            yield
    except (ImportError, InputFileError):
        raise
    except ReadTimeout:
        raise InputFileError(f"{name}: cannot read it: the reader did not finish within "
                             f"{seconds:.0f} s (a malformed file?)") from None
    except ValueError as exc:
        text = str(exc)
        raise InputFileError(text if text.startswith(name) else f"{name}: {text}") from None
    except MemoryError as exc:
        raise InputFileError(f"{name}: cannot read it: sizes in the file need more memory "
                             f"than there is ({exc})") from None
    except RecursionError:
        raise InputFileError(f"{name}: cannot read it: nested too deeply") from None
    except Exception as exc:  # noqa: BLE001 - any parser failure is the file's problem
        raise InputFileError(f"{name}: cannot read it: {type(exc).__name__}: {exc}") from None


class ReadTimeout(BaseException):
    """Raised by the deadline's alarm; a BaseException so parsers' ``except Exception``
    clauses cannot swallow it."""


@contextmanager
def deadline(seconds: float):
    """Interrupt the block after ``seconds`` with :class:`ReadTimeout` (SIGALRM).

    Only in the main thread of a POSIX process with no interval timer already running;
    elsewhere the block runs without a deadline.
    """
    usable = (hasattr(signal, "setitimer") and threading.current_thread() is
              threading.main_thread() and signal.getitimer(signal.ITIMER_REAL)[0] == 0)
    if not usable:
        yield
        return

    def expire(signum, frame):
        raise ReadTimeout

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
