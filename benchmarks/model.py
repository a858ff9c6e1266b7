"""Time to build the physical model (M, K) and its modes, dense solver (issue 2).

Cases: the bundled hand outline resampled to 62, 250 and 1000 nodes (M, K and *all*
modes), and a 2000-node deformed ellipsoid (Fibonacci lattice), lowest 20 modes, by the
dense solver and by the sparse one (which ``solver="auto"`` picks at that size).

Each time is the best of ``--repeat`` runs on a fresh model (wall clock, seconds):

- ``build``: the Gaussian Gram matrices ``G``, ``Gamma`` and ``K_g`` (or their sparse
  versions), i.e. everything the closed forms of method.md §1 give;
- ``M`` and ``K``: the dense nodal matrices (``model.mass``, ``model.stiffness``), which
  need solves with ``G``; the eigenproblem itself never forms them;
- ``modes``: ``model.modes(n)`` after ``build``.

Run ``python benchmarks/model.py`` (about a minute on 2 loaded cores) or ``--quick``
(skips the 2000-node dense case).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from modalmorph import FEModel
from modalmorph.core.shape import resample
from modalmorph.datasets import load_hand


def hand(m: int) -> np.ndarray:
    """The bundled hand 0 resampled to ``m`` nodes by arc length, shape (m, 2)."""
    return resample(load_hand(0), m)


def ellipsoid(m: int, seed: int = 0) -> np.ndarray:
    """``m`` nearly uniform points on an ellipsoid with radii (1, 0.7, 0.4) (Fibonacci
    lattice) plus a smooth bump and 1% jitter, shape (m, 3)."""
    rng = np.random.default_rng(seed)
    i = np.arange(m) + 0.5
    polar = np.arccos(1 - 2 * i / m)
    azimuth = np.pi * (1 + 5**0.5) * i
    p = np.c_[np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)]
    p *= 1 + 0.3 * np.exp(-np.sum((p - [0.0, 0.0, 1.0]) ** 2, axis=1) / 0.5)[:, None]
    spacing = np.sqrt(4 * np.pi / m)
    return p * [1.0, 0.7, 0.4] + 0.01 * spacing * rng.standard_normal((m, 3))


def _best(fn, repeat: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def time_case(points: np.ndarray, n: int | None, solver: str, repeat: int,
              matrices: bool) -> dict:
    """Time one model: build, M and K (when ``matrices``), and ``modes(n)``."""
    def build():
        model = FEModel(points, solver=solver)
        if model.truncated:
            _ = model.gram_sparse, model.stiffness_gaussian_sparse
        else:
            _ = model.gram, model.stiffness_gaussian
        return model

    row = {"m": len(points), "d": points.shape[1], "solver": solver}
    row["build"], _ = _best(build, repeat)
    if matrices:
        row["M"], _ = _best(lambda: build().mass, repeat)
        row["K"], _ = _best(lambda: build().stiffness, repeat)
    models = [build() for _ in range(repeat)]
    it = iter(models)
    row["modes"], modes = _best(lambda: next(it).modes(n), repeat)
    row["n"] = modes.n
    row["f1"] = modes.frequencies[0]
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per case (best kept)")
    parser.add_argument("--quick", action="store_true", help="skip the 3D dense case")
    args = parser.parse_args(argv)

    rows = [time_case(hand(m), None, "dense", args.repeat, True) for m in (62, 250, 1000)]
    pts3 = ellipsoid(2000)
    if not args.quick:
        rows.append(time_case(pts3, 20, "dense", 1, False))
    rows.append(time_case(pts3, 20, "sparse", args.repeat, False))

    print(f"{'nodes':>6} {'d':>2} {'solver':>7} {'modes':>6} {'build s':>8} {'M s':>7} "
          f"{'K s':>7} {'modes s':>8} {'total s':>8} {'omega_1':>10}")
    for r in rows:
        total = r["build"] + r["modes"]
        m_s = f"{r['M']:7.3f}" if "M" in r else f"{'-':>7}"
        k_s = f"{r['K']:7.3f}" if "K" in r else f"{'-':>7}"
        print(f"{r['m']:6d} {r['d']:2d} {r['solver']:>7} {r['n']:6d} {r['build']:8.3f} "
              f"{m_s} {k_s} {r['modes']:8.3f} {total:8.3f} {r['f1']:10.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
