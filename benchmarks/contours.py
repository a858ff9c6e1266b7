"""Objects of several contours (issues 23, 24): a myocardium-like ring and a footprint.

Prints four tables: the ring (time of match and morph, steps, the final distance of each
contour to its partner); the pose of a lobed ring turned by several angles with
``rotation="auto"``, from all the nodes as one unordered set against the largest contours
(the route match() takes); footprints of 3 and 2 contours; the paper's searches. Run
from the repository root, single-threaded BLAS:

    OMP_NUM_THREADS=1 PYTHONPATH=src:tests python benchmarks/contours.py
"""

import time

from test_contours import footprint, lobed_ring, ring

import modalmorph as mm
from modalmorph.core.quality import correspondence_rotation, crossing_segments, curve_distances
from modalmorph.core.shape import Shape

REPEAT = 5  # timings: the best of this many runs


def best_time(call):
    """The result of ``call()`` and its best time over REPEAT runs (s)."""
    times = []
    for _ in range(REPEAT):
        start = time.perf_counter()
        out = call()
        times.append(time.perf_counter() - start)
    return out, min(times)


def gaps(result, a, b):
    """Per pair of partners: the largest and the mean distance of the source contour's
    final nodes to its target contour, in % of the target's RMS radius."""
    out = []
    for k, j in result.matching.contours:
        d = curve_distances(result.shapes[-1][a.slices[k]], b.points[b.slices[j]])[0]
        out.append((k, j, 100 * d.max() / b.size, 100 * d.mean() / b.size))
    return out


def crossed(result, a) -> int:
    """The most crossing segment pairs of any step, within or between contours."""
    return max(len(crossing_segments(p, edges=a.edges)) for p in result.shapes)


def ring_table():
    a, b = ring(30, 20, 60, 40), ring(27, 15, 70, 35)
    m, t_match = best_time(lambda: mm.match(a, b))
    r, t_morph = best_time(lambda: mm.morph(a, b, matching=m))
    print("ring: outer 30 -> 27 (60 -> 70 nodes), inner 20 -> 15 (40 -> 35 nodes); "
          f"target RMS radius {b.size:.2f}")
    print(f"{'match s':>8} {'morph s':>8} {'steps':>5} {'stop':>10} {'crossings':>9} "
          f"{'contour':>8} {'max %':>6} {'mean %':>6}")
    for k, j, hi, mean in gaps(r, a, b):
        print(f"{t_match:>8.3f} {t_morph:>8.3f} {r.steps:>5} {r.stop_reason:>10} "
              f"{crossed(r, a):>9} {f'{k}->{j}':>8} {hi:>6.3f} {mean:>6.3f}")


def pose_table():
    print("\nlobed ring turned (outer x0.9, inner x0.75), rotation='auto': turn found (deg)")
    print(f"{'turn':>5} {'all nodes unordered':>20} {'largest contours':>17} "
          f"{'partners':>16} {'converged':>9}")
    a = lobed_ring()
    for turn in (0, 20, 40, 90, 160):
        b = lobed_ring(turn, 0.9, 0.75, 70, 35)
        cloud = mm.match(Shape(a.points, ordered=False), Shape(b.points, ordered=False))
        m = mm.match(a, b)
        r = mm.morph(a, b, matching=m)
        print(f"{turn:>5} {correspondence_rotation(a, b, cloud.pairs):>20.1f} "
              f"{correspondence_rotation(a, b, m.pairs):>17.1f} "
              f"{str(m.contours.tolist()):>16} {str(r.converged):>9}")


def footprint_table():
    print("\nfootprints (heel, forefoot, toes): the target moved by (3, -2), widened x1.15")
    print(f"{'case':>8} {'s':>6} {'partners':>24} {'steps':>5} {'stop':>10} "
          f"{'crossings':>9} {'worst max %':>11}")
    cases = {"3 -> 3": (footprint(), footprint(shift=(3.0, -2.0), squash=1.15)),
             "3 -> 2": (footprint(), footprint(False, shift=(3.0, -2.0), squash=1.15)),
             "2 -> 3": (footprint(False), footprint(shift=(3.0, -2.0), squash=1.15))}
    for name, (a, b) in cases.items():
        r, t = best_time(lambda a=a, b=b: mm.morph(a, b))
        worst = max(hi for *_, hi, _ in gaps(r, a, b))
        print(f"{name:>8} {t:>6.3f} {str(r.matching.contours.tolist()):>24} {r.steps:>5} "
              f"{r.stop_reason:>10} {crossed(r, a):>9} {worst:>11.3f}")


def paper_table():
    print("\nthe paper's searches over all nodes (pairs between non-partners dropped)")
    print(f"{'object':>9} {'method':>7} {'pairs':>5} {'steps':>5} {'stop':>11} "
          f"{'crossings':>9} {'distance %':>10}")
    for name, (a, b) in {"ring": (lobed_ring(), lobed_ring(0, 0.9, 0.75, 70, 35)),
                         "footprint": (footprint(),
                                       footprint(shift=(3.0, -2.0), squash=1.15))}.items():
        for method in ("auto", "global", "local"):
            m = mm.match(a, b, method=method)
            r = mm.morph(a, b, matching=m)
            print(f"{name:>9} {method:>7} {len(m):>5} {r.steps:>5} {r.stop_reason:>11} "
                  f"{crossed(r, a):>9} {100 * r.distance / b.size:>10.3f}")


if __name__ == "__main__":
    ring_table()
    pose_table()
    footprint_table()
    paper_table()
