"""What runs the items of a batch: a local process pool, or Dask (a ``LocalCluster``, a
running scheduler, or a client).

Both engines send an item only to a free worker (a Dask cluster gets a window of two items
per worker thread), so a stopped batch starts no item after it stops, and a manifest of any
length holds no more than that window of tasks. The pool's workers are this module's
:func:`worker_loop`: they ignore Ctrl-C (the batch's process answers it, once) and die with
the batch's process, even when it is killed (``PR_SET_PDEATHSIG`` on Linux, else a thread
that watches the parent).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable
from concurrent.futures import CancelledError
from dataclasses import dataclass
from multiprocessing.connection import wait as wait_for

from ...errors import OptionError
from .items import ItemResult, failed_row, run_item

__all__ = ["ENGINES", "Engine", "SchedulerLost", "worker_loop", "one_blas_thread"]

log = logging.getLogger(__name__)

ENGINES = ("auto", "dask", "processes")
# Each worker process computes with one BLAS thread, so N workers use N cores without
# oversubscription (a loop of 4 pairs on 2 cores lost time to BLAS threads fighting).
_ONE_THREAD = {name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                      "MKL_NUM_THREADS")}
# Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which turns off glibc's
# dynamic mmap threshold: every array over 128 kB is mmap'ed and unmapped again. A heart
# pair (247 -> 180 nodes) then costs 0.28 s of CPU in the worker instead of 0.19 s (+47 %,
# 20 pairs, 1 worker); the local cluster leaves glibc's default. Its statistical profiler
# (a stack sample every 10 ms) added another 4 % of CPU (0.194 -> 0.187 s per pair).
_DASK_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                "distributed.worker.profile.enabled": False}
# The engine "auto" picks, on this machine, the one that ends the batch first: start-up
# plus the items' cost per worker. Measured with benchmarks/batch.py --pairs 40 --startup
# (2 workers, heart pairs, a 2-core machine shared with other jobs, load average ~10):
# a 2-item batch from start to end, and the CPU per item (this process and its workers).
POOL_START_S = 5.8  # spawn 2 workers that import modalmorph, 2 items
CLUSTER_START_S = 6.8  # LocalCluster of 2 nannies + workers, import modalmorph there
POOL_ITEM_S = 0.162  # CPU s per heart pair in the pool
CLUSTER_ITEM_S = 0.223  # CPU s per heart pair on the LocalCluster (scheduler included)
# A scheduler that stays unreachable this long is lost (the client tries to reconnect
# meanwhile); measured: a dead scheduler is noticed by the client within 0.1 s.
LOST_AFTER_S = 10.0
_POLL_S = 0.5  # how often the Dask loop looks at its client while no item ends
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


class SchedulerLost(RuntimeError):
    """The Dask scheduler could not be reached for :data:`LOST_AFTER_S` seconds."""


@dataclass(frozen=True)
class Engine:
    """What runs the items of a batch.

    Attributes
    ----------
    kind : {"auto", "dask", "processes"}
        ``"auto"``: Dask when given a scheduler or client, else whichever local engine
        ends the batch first by the measured start-up and per-item costs
        (:data:`POOL_START_S`, :data:`CLUSTER_START_S`): the process pool.
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

    def choice(self, n_items: int) -> tuple[bool, str]:
        """Whether ``n_items`` run on Dask, and why in words when ``auto`` chose."""
        if self.client is not None or self.scheduler is not None or self.kind == "dask":
            return True, ""
        if self.kind == "processes":
            return False, ""
        workers = self.workers or len(os.sched_getaffinity(0))
        extra = CLUSTER_START_S - POOL_START_S + n_items * (
            CLUSTER_ITEM_S - POOL_ITEM_S) / workers
        if extra < 0 and _has_dask():
            return True, f"auto: ends ~{-extra:.0f} s before a process pool"
        return False, (f"auto: a Dask LocalCluster would end ~{extra:.1f} s later "
                       f"for {n_items} items")

    @contextlib.contextmanager
    def start(self, n_items: int):
        """A runner for ``n_items`` items: ``.name`` (in words), ``.dashboard`` and
        ``.run(items, task, done)``."""
        workers = min(self.workers or len(os.sched_getaffinity(0)), max(n_items, 1))
        dask, why = self.choice(n_items)
        with one_blas_thread():
            runner = (_dask_runner(self.client, self.scheduler, workers) if dask
                      else _pool_runner(workers))
            with runner as started:
                if why:
                    started.name += f" ({why})"
                yield started


def _has_dask() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


@contextlib.contextmanager
def one_blas_thread():
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


Done = Callable[[object, ItemResult], None]


# ------------------------------------------------------------------------------ process pool


def worker_loop(conn, parent: int) -> None:
    """A pool worker: run each ``(item, task)`` received on ``conn``, send its row back,
    until ``None`` or the end of the pipe; die with the process ``parent``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is for the batch's process
    _die_with(parent)
    while True:
        try:
            message = conn.recv()
        except EOFError:
            return
        if message is None:
            return
        item, task = message
        conn.send(run_item(item, **task))


def _die_with(parent: int) -> None:
    """Have this process killed when ``parent`` ends (SIGKILL included)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL) != 0:
            raise OSError(ctypes.get_errno(), "prctl")
    except (OSError, AttributeError):  # not Linux: watch the parent
        def watch():
            while os.getppid() == parent:
                time.sleep(1.0)
            os._exit(1)

        threading.Thread(target=watch, daemon=True).start()
    if os.getppid() != parent:  # it ended before the signal was armed
        os._exit(1)


class _Pool:
    """Worker processes, each fed one item at a time through its own pipe."""

    def __init__(self, workers: int):
        self.size = workers
        self.name = f"local process pool, {workers} worker{'s' * (workers > 1)}"
        self.dashboard = None
        self._context = multiprocessing.get_context("spawn")  # fresh, one BLAS thread
        self._workers: dict = {}  # connection -> process

    def _spawn(self):
        here, there = self._context.Pipe()
        process = self._context.Process(target=worker_loop, args=(there, os.getpid()),
                                        daemon=True, name="modalmorph-batch-worker")
        process.start()
        there.close()  # the worker's end: its death then reads as the end of the pipe
        self._workers[here] = process
        return here

    def run(self, items: Iterable, task: dict, done: Done) -> None:
        """Run every ``item`` (``run_item(item, **task)``), calling ``done(item, row)``."""
        items = iter(items)
        idle = [self._spawn() for _ in range(self.size)]
        busy: dict = {}
        while True:
            while idle and (item := next(items, None)) is not None:
                conn = idle.pop()
                conn.send((item, task))
                busy[conn] = item
            if not busy:
                return
            for conn in wait_for(list(busy)):
                item = busy.pop(conn)
                try:
                    row = conn.recv()
                except (EOFError, OSError):  # the worker died with the item
                    row = failed_row(item, RuntimeError(self._died(conn)))
                    conn = self._spawn()
                idle.append(conn)
                done(item, row)

    def _died(self, conn) -> str:
        process = self._workers.pop(conn)
        process.join(5.0)
        conn.close()
        return f"the worker process died (exit code {process.exitcode})"

    def close(self, *, kill: bool) -> None:
        """Stop the workers: at once (``kill``) or after their item."""
        for conn, process in self._workers.items():
            if kill:
                process.kill()
            else:
                with contextlib.suppress(OSError):
                    conn.send(None)
        for conn, process in self._workers.items():
            process.join(10.0)
            if process.is_alive():
                process.kill()
                process.join()
            conn.close()


@contextlib.contextmanager
def _pool_runner(workers: int):
    pool = _Pool(workers)
    try:
        yield pool
    except BaseException:  # Ctrl-C, an error here: the items being computed are abandoned
        pool.close(kill=True)
        raise
    pool.close(kill=False)


# ------------------------------------------------------------------------------ Dask


class _DaskRunner:
    """Items as Dask tasks, two per worker thread in flight."""

    def __init__(self, client, name: str, *, local: bool = False):
        self.client, self.name = client, name
        self.dashboard = client.dashboard_link if local else None

    def run(self, items: Iterable, task: dict, done: Done) -> None:
        """As :meth:`_Pool.run`; raises :class:`SchedulerLost`."""
        from distributed import wait

        items, pending = iter(items), {}
        unreachable = None  # since when the client is not connected
        try:
            while True:
                window = max(2 * sum(self.client.nthreads().values()), 2) \
                    if self.client.status == "running" else len(pending)
                while len(pending) < window and (item := next(items, None)) is not None:
                    pending[self.client.submit(
                        run_item, item, pure=False,
                        key=f"item-{item.id}-{os.urandom(4).hex()}", **task)] = item
                if not pending:
                    return
                try:
                    finished, _ = wait(list(pending), timeout=_POLL_S,
                                       return_when="FIRST_COMPLETED")
                except TimeoutError:
                    finished = ()
                except CancelledError:  # the scheduler went away with them
                    finished = [f for f in pending if f.status == "cancelled"]
                unreachable = self._check(unreachable)
                for future in finished:
                    self._finished(future, pending.pop(future), done)
        except OSError:  # a call to the scheduler failed (reset) as the scheduler went away
            if self._losing(LOST_AFTER_S):
                raise SchedulerLost(f"the Dask scheduler {self.client.scheduler.address} "
                                    f"was lost") from None
            raise
        finally:  # stopped: what has not started will not
            with contextlib.suppress(Exception):
                self.client.cancel(list(pending))

    def _check(self, since):
        if self.client.status == "running":
            return None
        since = since or time.monotonic()
        if time.monotonic() - since > LOST_AFTER_S:
            raise SchedulerLost(f"the Dask scheduler {self.client.scheduler.address} "
                                f"could not be reached for {LOST_AFTER_S:.0f} s")
        return since

    def _finished(self, future, item, done: Done) -> None:
        if future.status == "cancelled" and self.client.status != "running":
            raise SchedulerLost(f"the Dask scheduler {self.client.scheduler.address} "
                                f"was lost")
        try:
            row = future.result()
        except Exception as exc:  # never the item's own error: run_item does not raise
            if self._losing():
                raise SchedulerLost(f"the Dask scheduler {self.client.scheduler.address} "
                                    f"was lost") from None
            row = failed_row(item, exc)  # KilledWorker: the item killed 3 workers
        done(item, row)

    def _losing(self, within: float = 2.0) -> bool:
        """Whether the client loses its scheduler (it says so within a second; ``within``
        seconds at most are waited for it)."""
        deadline = time.monotonic() + within
        while self.client.status == "running" and time.monotonic() < deadline:
            time.sleep(0.05)
        return self.client.status != "running"


@contextlib.contextmanager
def _dask_runner(client, scheduler, workers):
    try:
        from distributed import Client
    except ImportError as exc:
        raise ImportError("a Dask engine, scheduler or client needs Dask: pip install "
                          "'modalmorph[dask]'") from exc
    if client is not None:
        yield _DaskRunner(client, f"Dask client {client.scheduler.address}")
        return
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="10s")
        except OSError as exc:
            raise OSError(f"no Dask scheduler answers at {scheduler}: {exc}") from None
        name = f"Dask scheduler {scheduler}"
    else:
        client = _local_client(workers)
        name = f"Dask LocalCluster, {workers} worker{'s' * (workers > 1)}"
    try:
        yield _DaskRunner(client, name, local=scheduler is None)
    finally:
        _close(client)


def _local_client(workers: int):
    import dask
    from distributed import Client, LocalCluster

    # the workers log at Dask's default (warnings) or what the command line set (-v or not)
    quiet = max(logging.getLogger("distributed").getEffectiveLevel(), logging.WARNING)
    with dask.config.set(_DASK_CONFIG), _no_sigint():  # read as the workers are spawned
        # a free port for the dashboard: several batches may run on one machine
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=quiet)
    return Client(cluster)


@contextlib.contextmanager
def _no_sigint():
    """Processes started in this block ignore Ctrl-C (Python keeps an ignored SIGINT)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _close(client) -> None:
    cluster = client.cluster
    with contextlib.suppress(Exception):  # a lost scheduler: nothing to close cleanly
        client.close(timeout=5)
    if cluster is not None:
        with contextlib.suppress(Exception):
            cluster.close(timeout=10)
