"""How the Gaussian width sigma changes conditioning, matching and morphing.

Run:  python benchmarks/sigma.py

For each sigma (in units of the mean node spacing) on pairs of the bundled hands
(100 nodes, ground-truth correspondence row i <-> row i): the condition number of Gamma,
the fraction of correct pairs from ``match`` (within +-1 node) on pairs rotated and
resampled, and the steps, final mean distance (fraction of the target size) and
self-crossings of ``morph`` driven by the ground-truth pairs.
"""

from __future__ import annotations

import itertools

import numpy as np

import modalmorph as mm
from modalmorph.datasets import load_hand


def crossings(p):
    q = np.roll(p, -1, axis=0)
    n = len(p)

    def orient(a, b, c):
        return np.sign((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                       - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))

    A, B, C, D = p[:, None], q[:, None], p[None], q[None]
    cross = (orient(A, B, C) * orient(A, B, D) < 0) & (orient(C, D, A) * orient(C, D, B) < 0)
    i, j = np.triu_indices(n, k=2)
    keep = ~((i == 0) & (j == n - 1))
    return int(cross[i[keep], j[keep]].sum())


def main():
    n = 100
    idx = np.linspace(0, 1590, n, endpoint=False).astype(int)
    hands = [load_hand(i)[idx] for i in range(8)]
    pairs = list(itertools.combinations(range(8), 2))[::3]
    truth = np.c_[np.arange(n), np.arange(n)]
    rng = np.random.default_rng(0)
    print(f"{'sigma':>5} {'cond(Gamma)':>11} {'match acc':>9} {'steps':>5} "
          f"{'final dist':>10} {'crossing':>8}")
    for sigma in (0.5, 0.75, 1.0, 1.5, 2.0, 2.5):
        model = mm.FEModel(hands[0], sigma=sigma)
        lam = np.linalg.eigvalsh(model.gram[1])
        accs, steps, dists, cross = [], [], [], 0
        for i, j in pairs:
            a, b = hands[i], hands[j]
            th = rng.uniform(-np.pi, np.pi)
            rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
            shift = rng.integers(n)
            b_moved = np.roll(b @ rot.T, -shift, axis=0)
            try:
                got = mm.match(a, b_moved, sigma=sigma).pairs
                ok = np.abs((got[:, 1] + shift - got[:, 0] + n // 2) % n - n // 2) <= 1
                accs.append(ok.sum() / n)
                r = mm.morph(a, b, matching=truth, sigma=sigma)
            except ValueError as exc:
                print(f"{sigma:>5} {lam[-1] / lam[0]:>11.1e}  failed: {exc}")
                break
            steps.append(r.steps)
            size = np.sqrt(np.mean(np.sum((b - b.mean(0)) ** 2, axis=1)))
            dists.append(r.mean_distance[-1] / size)
            cross += any(crossings(s) for s in r.shapes)
        else:
            print(f"{sigma:>5} {lam[-1] / lam[0]:>11.1e} {np.mean(accs):>9.3f} "
                  f"{np.median(steps):>5.0f} {np.mean(dists):>10.4f} "
                  f"{cross:>4}/{len(pairs)}")


if __name__ == "__main__":
    main()
