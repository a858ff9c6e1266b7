"""Where the minor page faults of match + morph happen, function by function.

Runs ``speed.py``'s corpus (``--families``, each pair resampled to ``--nodes``) in its
loop: every pair once to warm up, then ``--repeat`` runs of ``modalmorph.match`` and
``modalmorph.morph`` under ``sys.setprofile``, reading ``resource.getrusage``'s
``ru_minflt`` at every call and return (Python functions and C functions called from
Python; NumPy's operators count in the function that runs them). Prints the faults a run,
then per function the faults counted in its own code (``self``) and with its callees
(``total``), the largest first. The count depends on the heap's history (glibc hands
freed memory back at the top of its heap, issue 22): compare versions in one loop.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/faults.py [--nodes 250]
        [--families hearts hands glyphs] [--repeat 3] [--top 20]
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
from collections import Counter

from speed import CHARS, corpus

import modalmorph as mm
from modalmorph.core.shape import forget_checks, resample


def _faults() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


class FaultProfile:
    """``sys.setprofile`` hook: faults per function, own and with callees."""

    def __init__(self):
        self.own, self.total, self.stack, self.last = Counter(), Counter(), [], 0

    def __call__(self, frame, event, arg):
        now = _faults()
        if self.stack:
            self.own[self.stack[-1][0]] += now - self.last
        if event in ("call", "c_call"):
            name = (f"C {getattr(arg, '__qualname__', arg)}" if event == "c_call" else
                    f"{os.path.basename(frame.f_code.co_filename)}:{frame.f_code.co_name}")
            self.stack.append((name, now))
        elif self.stack:  # return, c_return, c_exception
            name, start = self.stack.pop()
            self.total[name] += now - start
        self.last = _faults()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=250)
    parser.add_argument("--families", nargs="*", default=["hearts", "hands", "glyphs"])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--top", type=int, default=20)
    args = parser.parse_args(argv)
    families = corpus(CHARS)
    profile, runs, faults = FaultProfile(), 0, 0

    def run(a, b):
        forget_checks()
        mm.morph(a, b, matching=mm.match(a, b))

    for family in args.families:
        for _, a, b in families[family]:
            a, b = resample(a, args.nodes), resample(b, args.nodes)
            try:
                run(a, b)
            except ValueError:  # a glyph outline the library refuses
                continue
            for _ in range(args.repeat):
                start = profile.last = _faults()
                sys.setprofile(profile)
                run(a, b)
                sys.setprofile(None)
                faults, runs = faults + _faults() - start, runs + 1
    print(f"# {args.nodes} nodes, {' '.join(args.families)}: {runs} runs, "
          f"{faults / runs:.0f} minor page faults a run")
    print(f"{'self':>8} {'total':>8}  function (faults a run)")
    for name, own in profile.own.most_common(args.top):
        print(f"{own / runs:>8.0f} {profile.total[name] / runs:>8.0f}  {name}")


if __name__ == "__main__":
    main()
