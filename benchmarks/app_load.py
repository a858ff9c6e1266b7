"""Load test of ``modalmorph app`` on 127.0.0.1: 50 concurrent clients, 500 runs.

Each client uploads two small contours (30 nodes) and starts a run (10 steps), polls it
to its end, and so on; a refusal of the run cap (429) is retried after a pause, shapes
pushed out of the table (128 kept) are uploaded again, as the page's user would.
Prints one table: requests answered by status, runs done, wall time, latency quantiles
and the server's memory (this process: the server runs in a thread of it).

    PYTHONPATH=src python benchmarks/app_load.py [--clients 50] [--runs 500]
"""

from __future__ import annotations

import argparse
import collections
import http.client
import json
import resource
import threading
import time

import numpy as np

from modalmorph.apps.app import make_server


def _rss_mib() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


class Client:
    def __init__(self, srv, stats):
        self.srv, self.stats = srv, stats

    def request(self, method, path, body=b""):
        headers = {"X-Modalmorph-Token": self.srv.token} if method == "POST" else {}
        start = time.perf_counter()
        conn = http.client.HTTPConnection(*self.srv.server_address, timeout=60)
        try:
            conn.request(method, path, body=body, headers=headers)
            response = conn.getresponse()
            data = response.read()
            status = response.status
        except OSError as exc:
            status, data = type(exc).__name__, b"null"
        finally:
            conn.close()
        self.stats.answer(status, time.perf_counter() - start)
        return status, json.loads(data or b"null") if isinstance(status, int) else None

    def shapes(self, seed):
        t = np.linspace(0, 2 * np.pi, 30, endpoint=False)
        ids = []
        for r in (1.0, 1.2 + 0.01 * seed):
            csv = "x,y\n" + "\n".join(f"{x:.6f},{y:.6f}" for x, y in
                                      np.c_[r * np.cos(t), r * np.sin(t)])
            ids.append(self.request("POST", "/api/upload?name=c.csv", csv.encode())[1]["id"])
        return ids

    def run(self, seed, end):
        ids = self.shapes(seed)
        while time.monotonic() < end:
            body = json.dumps({"source": ids[0], "target": ids[1],
                               "options": {"max_steps": "10"}}).encode()
            status, answer = self.request("POST", "/api/run", body)
            if status == 429:  # the run cap: wait, as the page's user would
                time.sleep(0.2)
                continue
            if status == 400 and "shapes first" in answer["error"]:
                time.sleep(0.2)
                ids = self.shapes(seed)  # pushed out of the table by other clients
                continue
            if status != 200:
                return f"refused {status}"
            for _ in range(2000):
                status, state = self.request("GET", f"/api/job/{answer['job']}")
                if status == 404:  # finished and pushed out of the 16 runs kept
                    return "forgotten"
                if state and state["state"] not in ("queued", "running"):
                    return state["state"]
                time.sleep(0.2)  # the page polls every 200 ms too
        return "unfinished"


class Stats:
    def __init__(self):
        self.lock = threading.Lock()
        self.status = collections.Counter()
        self.latency = []
        self.runs = collections.Counter()
        self.peak_rss = 0.0

    def answer(self, status, seconds):
        with self.lock:
            self.status[status] += 1
            self.latency.append(seconds)


def main(clients: int, runs: int, deadline: float) -> None:
    srv = make_server("127.0.0.1", 0)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    stats, todo = Stats(), iter(range(runs))
    lock, end = threading.Lock(), time.monotonic() + deadline
    rss0 = _rss_mib()

    def work(seed):
        client = Client(srv, stats)
        while time.monotonic() < end:
            with lock:
                if next(todo, None) is None:
                    return
            outcome = client.run(seed, end)
            with stats.lock:
                stats.runs[outcome] += 1
                stats.peak_rss = max(stats.peak_rss, _rss_mib())

    start = time.monotonic()
    threads = [threading.Thread(target=work, args=(i,)) for i in range(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(max(1.0, end - time.monotonic()))
    wall = time.monotonic() - start
    srv.shutdown()
    srv.server_close()
    lat = np.array(stats.latency) * 1000
    print(f"{'clients':<28}{clients}")
    print(f"{'unanswered (no reply)':<28}"
          f"{sum(v for k, v in stats.status.items() if not isinstance(k, int))}")
    print(f"{'runs asked':<28}{runs}")
    for outcome, count in sorted(stats.runs.items()):
        print(f"{'  runs ' + outcome:<28}{count}")
    print(f"{'requests answered':<28}{len(lat)}")
    for status, count in sorted(stats.status.items(), key=str):
        print(f"{'  status ' + str(status):<28}{count}")
    print(f"{'wall time (s)':<28}{wall:.1f}")
    print(f"{'latency p50 / p99 / max ms':<28}{np.percentile(lat, 50):.1f} / "
          f"{np.percentile(lat, 99):.1f} / {lat.max():.1f}")
    print(f"{'RSS start / peak / end MiB':<28}{rss0:.0f} / {stats.peak_rss:.0f} / "
          f"{_rss_mib():.0f}")
    print(f"{'max RSS (getrusage) MiB':<28}"
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=50)
    parser.add_argument("--runs", type=int, default=500)
    parser.add_argument("--deadline", type=float, default=900,
                        help="seconds: the test stops here, whatever is left")
    args = parser.parse_args()
    main(args.clients, args.runs, args.deadline)
