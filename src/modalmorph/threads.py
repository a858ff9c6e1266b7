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
"""

from __future__ import annotations

import os
import threading
from contextlib import contextmanager

__all__ = ["ONE_THREAD_NODES", "blas_threads", "limit", "set_blas_threads"]

# Up to this many nodes one BLAS thread is faster than two (see the module's docstring).
ONE_THREAD_NODES = 1000
_ENV = "MODALMORPH_BLAS_THREADS"

_state = threading.local()  # .depth: nesting of limit() in this thread
_override: list[int | None] = [None]
_controller = []  # the threadpoolctl controller, made on first use (about 1 ms)


def set_blas_threads(count: int | None) -> None:
    """Use ``count`` BLAS threads in every call from now on (None: the size policy)."""
    if count is not None and not (isinstance(count, int) and count >= 1):
        raise ValueError(f"count must be an integer >= 1 or None, got {count!r}")
    _override[0] = count


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
