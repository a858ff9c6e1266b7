"""Steps and time of match + morph on real hand pairs of 70, 250 and 1000 nodes.

Run:  python benchmarks/morph.py [--repeat 5]

The reference is a direct dense transcription of the paper, timed in the same run on the
same pair: for matching, G inverted explicitly, M and K formed, ``scipy.linalg.eigh(K, M)``
for both shapes, the affinity (8) and mutual best; for morphing, the same model and the
same number of Newmark steps on the modal equations with explicit nodal loads. The
speed-up is (reference match + reference morph) / (match + morph).
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
from scipy import linalg

import modalmorph as mm
from modalmorph.core.element import gram_entries, stiffness_entries
from modalmorph.datasets import load_hand


def pair(n):
    a = mm.resample(load_hand(0), n)
    b = mm.resample(load_hand(3), int(n * 1.1))
    return a, b


def best_of(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def dense_modes(points):
    """The paper's model transcribed directly: G inverted, M and K formed, eigh(K, M)."""
    model = mm.FEModel(points)
    x = model.points
    r = x[None] - x[:, None]
    G, Gamma = gram_entries(r, model.width)
    lam, mu = model.lame
    d, m = 2, len(x)
    Kg = stiffness_entries(r, model.width, lam, mu).transpose(2, 0, 3, 1).reshape(d * m, -1)
    A = np.kron(np.eye(d), np.linalg.inv(G))
    M = model.material.rho * A @ np.kron(np.eye(d), Gamma) @ A
    K = A @ Kg @ A
    w2, Phi = linalg.eigh(K, M)
    return model, M, w2, Phi


def reference_match(a, b, n_modes=24):
    """Modal matching transcribed directly: both models' modes, the affinity Z (8) on the
    lowest modes (rows of Phi per node), mutual best (the paper's local search)."""
    _, _, _, P1 = dense_modes(a)
    _, _, _, P2 = dense_modes(b)
    u1 = P1[:, :n_modes].reshape(2, len(a), -1).transpose(1, 0, 2).reshape(len(a), -1)
    u2 = P2[:, :n_modes].reshape(2, len(b), -1).transpose(1, 0, 2).reshape(len(b), -1)
    Z = np.sum(u1**2, 1)[:, None] + np.sum(u2**2, 1)[None] - 2 * u1 @ u2.T  # (8)
    j = Z.argmin(axis=1)
    mutual = Z.argmin(axis=0)[j] == np.arange(len(a))
    return np.c_[np.flatnonzero(mutual), j[mutual]]


def reference(a, b, pairs, steps):
    """The paper transcribed directly: dense model as above, Rayleigh C, then ``steps``
    Newmark steps (15) on the modal equations, loads (19) from the previous shape on the
    matched nodes."""
    model, M, w2, Phi = dense_modes(a)
    x = model.points
    y = model.shape.to_normalized(b)
    d, m = 2, len(x)
    w = np.sqrt(np.clip(w2, 0, None))
    al, be = mm.rayleigh(0.005, 0.03, w[0], w[-1])
    c = al + be * w2
    dt, k = 1.0 / w[-1], 1e-3 * w2[-1] * M[0, 0]
    a0, a1, a2, a3 = 4 / dt**2, 2 / dt, 4 / dt, 1.0
    keff = w2 + a0 + a1 * c
    X, V, Acc = np.zeros(d * m), np.zeros(d * m), np.zeros(d * m)
    for _ in range(steps):
        u = (Phi @ X).reshape(d, m).T
        R = np.zeros((m, d))
        R[pairs[:, 0]] = k * (y[pairs[:, 1]] - x[pairs[:, 0]] - u[pairs[:, 0]])  # (19)
        f = Phi.T @ R.T.reshape(-1)
        rhs = f + a0 * X + a2 * V + a3 * Acc + c * (a1 * X + V)  # (15), alpha=1/4
        X1 = rhs / keff
        A1 = a0 * (X1 - X) - a2 * V - a3 * Acc
        V = V + dt / 2 * (Acc + A1)
        X, Acc = X1, A1
    return X


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--sizes", type=int, nargs="*", default=[70, 250, 1000])
    args = parser.parse_args(argv)
    print(f"# {platform.processor() or platform.machine()}, numpy {np.__version__}, "
          f"best of {args.repeat}")
    print(f"{'nodes':>6} {'matches':>7} {'steps':>5} {'conv':>5} {'match s':>8} "
          f"{'morph s':>8} {'total s':>8} {'ref match s':>11} {'ref morph s':>11} "
          f"{'speed-up':>8}")
    for n in args.sizes:
        a, b = pair(n)
        t_match, matching = best_of(lambda a=a, b=b: mm.match(a, b), args.repeat)
        t_morph, result = best_of(lambda a=a, b=b, m=matching: mm.morph(a, b, matching=m),
                                  args.repeat)
        t_ref_match, _ = best_of(lambda a=a, b=b: reference_match(a, b), 1)
        t_ref, _ = best_of(lambda a=a, b=b, p=matching.pairs, s=result.steps:
                           reference(a, b, p, s), 1)
        total = t_match + t_morph
        print(f"{n:>6} {len(matching.pairs):>7} {result.steps:>5} "
              f"{str(result.converged):>5} {t_match:>8.4f} {t_morph:>8.4f} {total:>8.4f} "
              f"{t_ref_match:>11.4f} {t_ref:>11.4f} {(t_ref_match + t_ref) / total:>7.1f}x")


if __name__ == "__main__":
    main()
