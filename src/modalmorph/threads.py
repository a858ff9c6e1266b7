"""How many BLAS threads the library's calls use: chosen per call by problem size and by
what the machine offers, overridable by the user.

Small problems are fastest on one BLAS thread: their matrix products are too small to
share, and every extra thread spins, fights the caller for a core on a busy machine, and
wakes up again for each of the thousands of small products of a morph. Measured on the
2-core development machine (``benchmarks/threads.py``; heart pairs resampled, median of
5): 70 nodes 21.5 ms with one thread against 88 ms with OpenBLAS's default two; 250 nodes
0.15 s against 0.39 s; 1000 nodes 0.50 s against 1.0 s; with two other processes busy on
the cores a bundled heart pair took 0.24 s with one thread and 1.6-19 s with two.

The policy (:func:`blas_threads`): ``MODALMORPH_BLAS_THREADS`` or :func:`set_blas_threads`
when set; else one thread up to :data:`ONE_THREAD_NODES` nodes, and beyond it the cores
that are free (the cores this process may use less the load average, at least one).
The public calls (:func:`modalmorph.match`, :func:`modalmorph.morph`,
:func:`modalmorph.track`) run inside :func:`limit`; a call inside another keeps the outer
call's choice.

The command line (and so the web app and local batches) tunes glibc's allocator at start
(:func:`tune_allocator`); a program using the library may call it once itself. glibc
hands freed memory back to the system once more than twice its largest freed block lies
free at the top of its heap, so the (dm, dm) temporaries of each morph (2 MB at 250
nodes) came back as fresh pages every call: 5100 minor page faults in a 250-node heart
morph, 28 ms CPU against 19 ms without them (one thread, ``benchmarks/speed.py``'s heart
pair 3; the match: 80 faults). The library does not tune it on its own: the setting is
the whole process's, and the process keeps up to ``TRIM_THRESHOLD`` of freed memory
(after a 1000-node 2D morph 250 MiB resident against 196 MiB). ``MODALMORPH_MALLOC=system``
leaves the allocator as it is.
"""

from __future__ import annotations

import ctypes
import os
import threading
from contextlib import contextmanager

__all__ = ["ONE_THREAD_NODES", "MMAP_THRESHOLD", "TRIM_THRESHOLD", "blas_threads", "limit",
           "set_blas_threads", "tune_allocator"]

# Up to this many nodes one BLAS thread is faster than two (see the module's docstring).
ONE_THREAD_NODES = 1000
_ENV = "MODALMORPH_BLAS_THREADS"

# glibc's mallopt: blocks below MMAP_THRESHOLD come from its heap (32 MiB, the ceiling of
# glibc's own adaptive threshold on 64-bit), which keeps up to TRIM_THRESHOLD free at its top
# (64 MiB; a 1000-node 2D morph's temporaries are 32 MB each): no page faults in 2D at
# 70-1000 nodes (a 1000-node 3D morph's 72 MB temporaries still come from mmap), the peak
# memory (ru_maxrss) of match + morph at 70 and 250 nodes unchanged (216 MB).
MMAP_THRESHOLD = 32 << 20
TRIM_THRESHOLD = 64 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # malloc.h
_MALLOC_ENV = "MODALMORPH_MALLOC"
_tuned: list[bool] = []  # tune_allocator's outcome, once per process

_state = threading.local()  # .depth: nesting of limit() in this thread
_override: list[int | None] = [None]
_controller = []  # the threadpoolctl controller, made on first use (about 1 ms)


def set_blas_threads(count: int | None) -> None:
    """Use ``count`` BLAS threads in every call from now on (None: the size policy)."""
    if count is not None and not (isinstance(count, int) and count >= 1):
        raise ValueError(f"count must be an integer >= 1 or None, got {count!r}")
    _override[0] = count


def tune_allocator() -> bool:
    """Set glibc's ``M_MMAP_THRESHOLD`` and ``M_TRIM_THRESHOLD`` (:data:`MMAP_THRESHOLD`,
    :data:`TRIM_THRESHOLD`), once per process (the module's docstring says why); whether
    they were set: not where the C library is not glibc, nor with
    ``MODALMORPH_MALLOC=system``."""
    if not _tuned:
        _tuned.append(_set_mallopt())
    return _tuned[0]


def _set_mallopt() -> bool:
    if os.environ.get(_MALLOC_ENV, "").strip().lower() == "system":
        return False
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return False
        mallopt = ctypes.CDLL(None).mallopt
    except (AttributeError, OSError, ValueError):  # not glibc (macOS, musl, Windows)
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))


def blas_threads(nodes: int) -> int:
    """The BLAS threads for a problem of ``nodes`` nodes (the larger object's count)."""
    if _override[0] is not None:
        return _override[0]
    env = os.environ.get(_ENV, "").strip()
    if env:
        try:
            return max(1, int(env))
        except ValueError:
            raise ValueError(f"{_ENV} must be an integer >= 1, got {env!r}") from None
    if nodes <= ONE_THREAD_NODES:
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else \
        (os.cpu_count() or 1)
    return max(1, min(cores, round(cores - os.getloadavg()[0])))


@contextmanager
def limit(nodes: int):
    """Run the block with :func:`blas_threads` ``(nodes)`` BLAS threads (the outermost
    call of a thread decides; nested calls keep its choice)."""
    depth = getattr(_state, "depth", 0)
    if depth:
        _state.depth = depth + 1
        try:
            yield
        finally:
            _state.depth = depth
        return
    if not _controller:
        from threadpoolctl import ThreadpoolController

        _controller.append(ThreadpoolController())
    _state.depth = 1
    try:
        with _controller[0].limit(limits=blas_threads(nodes), user_api="blas"):
            yield
    finally:
        _state.depth = 0
