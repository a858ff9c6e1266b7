"""The BLAS thread policy of the library's calls (modalmorph.threads)."""

import numpy as np
import pytest
from threadpoolctl import threadpool_info

import modalmorph as mm
from modalmorph import threads


def _blas_threads() -> set[int]:
    return {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}


def test_small_problems_run_on_one_thread_and_the_outer_call_decides():
    with threads.limit(threads.ONE_THREAD_NODES):
        assert _blas_threads() == {1}
        with threads.limit(10**6):  # a nested call keeps the outer choice
            assert _blas_threads() == {1}
        assert _blas_threads() == {1}


def test_the_user_overrides_the_policy(monkeypatch):
    threads.set_blas_threads(2)
    try:
        assert threads.blas_threads(10) == 2
    finally:
        threads.set_blas_threads(None)
    monkeypatch.setenv("MODALMORPH_BLAS_THREADS", "3")
    assert threads.blas_threads(10) == 3
    monkeypatch.setenv("MODALMORPH_BLAS_THREADS", "many")
    with pytest.raises(ValueError, match="MODALMORPH_BLAS_THREADS must be an integer"):
        threads.blas_threads(10)
    with pytest.raises(ValueError, match="count must be an integer >= 1"):
        threads.set_blas_threads(0)


def test_large_problems_use_the_free_cores():
    assert threads.blas_threads(10**6) >= 1


def test_morph_computes_inside_the_policy(monkeypatch):
    seen = []
    real = mm.pipeline.Simulation.run

    def spy(self, progress=None):
        seen.append(_blas_threads())
        return real(self, progress)

    monkeypatch.setattr(mm.pipeline.Simulation, "run", spy)
    a = np.linspace(0.0, 2.0 * np.pi, 30, endpoint=False)
    mm.morph(np.c_[np.cos(a), np.sin(a)], np.c_[2 * np.cos(a), np.sin(a)])
    assert seen == [{1}]


def test_the_allocator_is_tuned_once_on_glibc_and_left_alone_when_asked(monkeypatch):
    import os

    monkeypatch.setattr(threads, "_tuned", [])
    monkeypatch.setenv("MODALMORPH_MALLOC", "system")
    assert threads.tune_allocator() is False
    assert threads.tune_allocator() is False  # decided once per process
    monkeypatch.setattr(threads, "_tuned", [])
    monkeypatch.delenv("MODALMORPH_MALLOC")
    try:
        glibc = bool(os.confstr("CS_GNU_LIBC_VERSION"))
    except (ValueError, OSError):
        glibc = False
    assert threads.tune_allocator() is glibc
    if glibc:  # five 2 MB temporaries freed together are reused, not fresh pages each
        # time (untuned: 40 000 minor page faults in these 20 rounds, tuned 0), measured
        # in a fresh process: late in a full run, beside the threads other tests leave,
        # the same rounds faulted 20 500 pages in every try (glibc may serve the test's
        # thread from another arena), so the process's own history decides, not the tuning
        import subprocess
        import sys

        script = """
import resource, numpy as np
from modalmorph import threads
assert threads.tune_allocator() is True
def work():
    return sum(block.sum() for block in [np.ones(1 << 18) for _ in range(5)])
work()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    work()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""
        env = {k: v for k, v in os.environ.items() if k != "MODALMORPH_MALLOC"}
        out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                             env=env, timeout=120, check=True)
        assert int(out.stdout.split()[-1]) < 1000
