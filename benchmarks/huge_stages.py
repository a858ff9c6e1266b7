"""The subset stage of the 1 000 000-point route, measured alone (issue 25, session huge10).

``matching._huge_landing`` matches even subsets of 100 000 nodes of both objects: the
subset's coarse modal landing, then refine's first level once and its second
``FINE_PASSES`` times, each pass from the best similarity of the landings before it, then
refine's finer levels. This script builds one case of ``match3d.py`` (same generator,
noise 0.01), caches the subset's coarse landing (the slow part), and runs the passes as
the route does (``main``) or one of the alternatives measured in docs/issue25/scale.md
("session 15, huge10"): the pose and the deformation grown together instead of the
restarts from the similarity.

- ``joint``: refine's first level with the landings a similarity plus a Gaussian field
  on 300 control nodes, both fitted (weighted least squares, ridge) to the transport's
  barycentres every round, the field's width annealed from 1.0 to 0.3 (normalised
  units), 2 x 200 rounds from the coarse landing; then refine from its second level.
- ``cpd``: coherent point drift with a similarity and the same kind of field on 2000
  subset nodes (their GMM, sigma annealed by EM, the field's width 1.0 -> 0.4), its
  landing carried to the subset as the start of main's passes.
- ``posed``: main's first level, then its second level's passes with a similarity step
  each round (the pulls' weighted best similarity applied to every node, the rest
  smoothed as refine does), no restarts.

Each row: the subset's landings against the truth, in the 1 000 000-point target's
spacings: median, p90, the angle of their best similarity to the truth's (rot), the
median normal and tangential parts of the error (normals of the truth's 32 nearest
subset nodes), and the CPU seconds of the stage. ``sim`` is the truth's best similarity
alone: its tangential part is the warp's slide along the surface.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/huge_stages.py blob 1000000 180 \
        base --methods main,joint,cpd,posed
"""

from __future__ import annotations

import argparse
import pickle
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

sys.path.insert(0, str(Path(__file__).parent))
from match3d import VARIANTS, make_case  # noqa: E402

from modalmorph.core.align import Similarity, align  # noqa: E402
from modalmorph.core.shape import Shape, even_subset  # noqa: E402
from modalmorph.matching import (  # noqa: E402
    DEFAULT_MODES,
    FINE_CLOUD,
    FINE_PASSES,
    HUGE_SMOOTHING,
    POSE_PASSES,
    _coarse_landing,
)
from modalmorph.matching import clouds as C  # noqa: E402
from modalmorph.options import MatchOptions  # noqa: E402
from modalmorph.threads import limit  # noqa: E402


def stage(shape: str, m: int, angle: float, variant: str, cache: Path) -> dict:
    """The subsets of ``_huge_landing`` and their coarse landing (cached), the truth of
    the source's subset and the full target's spacing."""
    path = cache / f"huge_stages_{shape}{m}_{int(angle)}_{variant}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())
    src, tgt, truth = make_case(shape, m, angle, 0.01, **VARIANTS[variant])
    full_s, full_t = Shape(src, ordered=False), Shape(tgt, ordered=False)
    keep = FINE_CLOUD / max(full_s.m, full_t.m)
    i = even_subset(full_s.normalized, int(keep * full_s.m))
    j = even_subset(full_t.normalized, int(keep * full_t.m))
    sub_s, sub_t = Shape(src[i], ordered=False), Shape(tgt[j], ordered=False)
    with limit(max(full_s.m, full_t.m)):
        landed, start = _coarse_landing(sub_s, sub_t, DEFAULT_MODES, MatchOptions())
    d = dict(sub_s=sub_s, sub_t=sub_t, z0=sub_t.to_normalized(landed), start=start,
             truth=truth[i], h=cKDTree(tgt).query(tgt, k=2)[0][:, 1].mean())
    path.write_bytes(pickle.dumps(d))
    return d


def score(d: dict, z: np.ndarray) -> dict:
    """Landings ``z`` (the subset target's normalised frame) against the truth."""
    u, truth = d["sub_t"].to_user(z), d["truth"]
    err = np.linalg.norm(u - truth, axis=1) / d["h"]
    e, p = (u - truth)[::10], truth[::10]
    near = cKDTree(truth).query(p, k=32)[1]
    normal = np.linalg.svd(truth[near] - truth[near].mean(axis=1, keepdims=True))[2][:, 2]
    along = np.sum(e * normal, axis=1)
    slide = np.linalg.norm(e - along[:, None] * normal, axis=1)
    return dict(median=np.median(err), p90=np.percentile(err, 90),
                rot=align(u, truth).angle, normal=np.median(np.abs(along)) / d["h"],
                tangential=np.median(slide) / d["h"])


def similar(x: np.ndarray, z: np.ndarray) -> np.ndarray:
    return align(x, z).apply(x)


def passes(d: dict, z: np.ndarray) -> np.ndarray:
    """``_huge_landing``'s passes and finer levels from the landings ``z``."""
    x, y, start = d["sub_s"].normalized, d["sub_t"].normalized, d["start"]
    for level, count, smoothing in ((1, POSE_PASSES, 8.0), (2, FINE_PASSES, HUGE_SMOOTHING)):
        for _ in range(count):
            z = C.refine(x, similar(x, z), y, C.finer(start, level - 1), levels=1,
                         smoothing=smoothing)
    return C.refine(x, z, y, C.finer(start, 2), smoothing=HUGE_SMOOTHING)


def kernel(a: np.ndarray, b: np.ndarray, width: float) -> np.ndarray:
    return np.exp(-cdist(a, b, "sqeuclidean") / (2 * width**2))


def weighted_similarity(x: np.ndarray, c: np.ndarray, w: np.ndarray) -> Similarity:
    """The similarity taking ``x`` nearest to ``c`` in least squares weighted by ``w``."""
    mx, mc = w @ x / w.sum(), w @ c / w.sum()
    u, s, vt = np.linalg.svd(((c - mc) * w[:, None]).T @ (x - mx))
    flip = np.array([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rot = u @ np.diag(flip) @ vt
    scale = float(s @ flip / (w @ np.sum((x - mx) ** 2, axis=1)))
    return Similarity(rot, scale, mc - scale * rot @ mx)


def field_fit(xc, ctr, width, resid, w, ridge):
    """Coefficients (k, 3) of the Gaussian field on the controls ``ctr`` that best fits
    ``resid`` at ``xc`` (weights ``w``; ``ridge`` weighs the field's RKHS norm)."""
    kac, kcc = kernel(xc, ctr, width), kernel(ctr, ctr, width)
    a = kac.T @ (w[:, None] * kac) + ridge * (kcc + 1e-6 * np.eye(len(ctr)))
    return np.linalg.solve(a, kac.T @ (w[:, None] * resid))


def level_cubes(x, y, start):
    """What refine's level sets up from ``start``: the source's node count, the cube
    width, the source's areas, its nodes' cubes, both summaries (means and masses)."""
    m, n = len(x), len(y)
    spacing = cKDTree(y).query(y, k=2)[0][:, 1].mean()
    width = max(spacing * np.sqrt(n / max(start, 1)) / C._STEP, spacing)
    wx, wy = C._area(x), C._area(y) * (m / n)
    label = C._cells(x, width)
    xc, mu = C._means(label, x, wx)
    yc, nu = C._means(C._cells(y, width), y, wy)
    return m, width, wx, label, xc, mu, yc, nu


def joint_level(x, z, y, start, widths=(1.0, 0.3), rounds=200, ridge=1e-3, controls=300):
    """Refine's first level with the landings a similarity plus a Gaussian field on
    ``controls`` nodes, both refitted to the transport's barycentres every round, the
    field's width annealed from ``widths[0]`` to ``widths[1]``."""
    m, width, wx, label, xc, mu, yc, nu = level_cubes(x, y, start)
    zc = C._means(label, z, wx)[0]
    ctr = xc[even_subset(xc, controls)]
    sim = weighted_similarity(xc, zc, mu)
    alpha = field_fit(xc, ctr, widths[0], zc - sim.apply(xc), mu, ridge * mu.sum())
    zc, graph = sim.apply(xc) + kernel(xc, ctr, widths[0]) @ alpha, None
    for i in range(rounds):
        beta = widths[0] * (widths[1] / widths[0]) ** (i / max(rounds - 1, 1))
        if max(len(mu), len(nu)) > C._MANY_POINTS and i % C._REGRAPH == 0:
            graph = C._graph(zc, yc)
        goal, share = C._transport(zc, mu, yc, nu, C._TEMPERATURE * width, graph)
        sim = weighted_similarity(xc, goal - kernel(xc, ctr, beta) @ alpha, mu * share)
        alpha = field_fit(xc, ctr, beta, goal - sim.apply(xc), mu * share,
                          ridge * (mu * share).sum())
        zc = sim.apply(xc) + kernel(xc, ctr, beta) @ alpha
    return sim.apply(x) + np.vstack([kernel(x[k:k + 20_000], ctr, beta) @ alpha
                                     for k in range(0, m, 20_000)])


def coherent(x, z, y, nodes=2000, controls=300, widths=(1.0, 0.4), lam=2.0, rounds=60,
             outlier=0.1):
    """Coherent point drift with a similarity and a Gaussian field on ``controls`` of
    ``nodes`` even subset nodes, from the similarity of ``z``; where it takes every
    node of ``x``."""
    ia = even_subset(x, nodes)
    xa, b = x[ia], y[even_subset(y, max(nodes * len(y) // len(x), 1))]
    ctr = xa[even_subset(xa, controls)]
    sim, alpha = align(xa, z[ia]), np.zeros((len(ctr), 3))
    t = sim.apply(xa)
    sigma2 = np.mean(cdist(t, b, "sqeuclidean")) / 3
    for r in range(rounds):
        beta = widths[0] * (widths[1] / widths[0]) ** (r / max(rounds - 1, 1))
        p = np.exp(-cdist(t, b, "sqeuclidean") / (2 * sigma2))
        floor = (2 * np.pi * sigma2) ** 1.5 * outlier / (1 - outlier) * len(xa) / len(b)
        p /= p.sum(axis=0, keepdims=True) + floor
        p1 = p.sum(axis=1)
        bary = (p @ b) / np.maximum(p1, 1e-12)[:, None]
        sim = weighted_similarity(xa, bary - kernel(xa, ctr, beta) @ alpha, p1)
        alpha = field_fit(xa, ctr, beta, bary - sim.apply(xa), p1, lam * sigma2)
        t = sim.apply(xa) + kernel(xa, ctr, beta) @ alpha
        sigma2 = max(float(np.sum(p * cdist(t, b, "sqeuclidean")) / (p1.sum() * 3)), 1e-10)
    return sim.apply(x) + kernel(x, ctr, beta) @ alpha


def posed_level(x, z, y, start, smoothing=HUGE_SMOOTHING):
    """Refine's level from ``start`` with a similarity step every round: the pulls'
    weighted best similarity moves every node, the rest is smoothed as refine does."""
    m, width, wx, label, xc, mu, yc, nu = level_cubes(x, y, start)
    smooth, graph = C._smoother(xc, mu, x, smoothing * width), None
    for i in range(C._COARSE_ROUNDS[len(mu) >= C._FEW * m]):
        zc = C._means(label, z, wx)[0]
        if max(len(mu), len(nu)) > C._MANY_POINTS and i % C._REGRAPH == 0:
            graph = C._graph(zc, yc)
        goal, share = C._transport(zc, mu, yc, nu, C._TEMPERATURE * width, graph)
        sim = weighted_similarity(zc, goal, mu * share)
        z = z + C._OVERRELAX * (sim.apply(z) - z)
        pull = goal - zc - C._OVERRELAX * (sim.apply(zc) - zc)
        z = z + C._OVERRELAX * smooth(pull, share)
    return z


def run(method: str, d: dict) -> np.ndarray:
    x, y, start, z = d["sub_s"].normalized, d["sub_t"].normalized, d["start"], d["z0"]
    if method == "main":
        return passes(d, z)
    if method == "joint":
        for _ in range(2):
            z = joint_level(x, z, y, start)
        return C.refine(x, z, y, C.finer(start, 1), smoothing=HUGE_SMOOTHING)
    if method == "cpd":
        return passes(d, coherent(x, z, y))
    if method == "posed":
        z = C.refine(x, similar(x, z), y, start, levels=1, smoothing=8.0)
        for _ in range(FINE_PASSES):
            z = posed_level(x, z, y, C.finer(start, 1))
        return C.refine(x, z, y, C.finer(start, 2), smoothing=HUGE_SMOOTHING)
    if method == "sim":
        return similar(x, d["sub_t"].to_normalized(d["truth"]))
    return d["z0"]  # "coarse"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("shape")
    p.add_argument("size", type=int)
    p.add_argument("angle", type=float)
    p.add_argument("variant", nargs="?", default="base", choices=sorted(VARIANTS))
    p.add_argument("--methods", default="coarse,sim,main,joint,cpd,posed")
    p.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()))
    args = p.parse_args(argv)
    d = stage(args.shape, args.size, args.angle, args.variant, args.cache)
    print(f"{args.shape} {args.size} {args.angle:g} deg {args.variant}")
    print("| method | median | p90 | rot deg | normal | tangential | CPU s |")
    print("|---|---|---|---|---|---|---|")
    for method in args.methods.split(","):
        t = time.process_time()
        z = run(method, d)
        s, cpu = score(d, z), time.process_time() - t
        print(f"| {method} | {s['median']:.2f} | {s['p90']:.2f} | {s['rot']:.2f} | "
              f"{s['normal']:.2f} | {s['tangential']:.2f} | {cpu:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
