"""The web app probed over HTTP on 127.0.0.1 as an attacker and a careless user would
(issue 27): bombs, cross-site requests, malformed lengths, smuggling, caps, hostile names
and signals. Every loop is bounded in count and time."""

import gzip
import http.client
import io
import json
import os
import re
import resource
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
import zipfile
import zlib
from dataclasses import replace
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest

from modalmorph.apps.app import make_server
from modalmorph.apps.policy import APP_LIMITS

ROOT = Path(__file__).resolve().parents[1]
# Deadlines short enough for a test, long enough for a loaded 2-core machine.
FAST = replace(APP_LIMITS, header_timeout=1.0, body_timeout=2.0, keep_alive=1)
WAIT = 30  # seconds: the longest wait for any answer


def _start(limits=FAST):
    srv = make_server("127.0.0.1", 0, limits=limits)
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    return srv


def _stop(srv):
    srv.shutdown()
    srv.server_close()


@pytest.fixture(scope="module")
def server():
    srv = _start()
    yield srv
    _stop(srv)


def _request(srv, method, path, body=b"", headers=None, token=True):
    conn = http.client.HTTPConnection(*srv.server_address, timeout=WAIT)
    sent = {**({"X-Modalmorph-Token": srv.token} if token and method == "POST" else {}),
            **(headers or {})}
    try:
        conn.request(method, path, body=body, headers=sent)
        response = conn.getresponse()
        return response.status, json.loads(response.read() or b"null")
    finally:
        conn.close()


def _raw(srv, data: bytes, seconds: float = 5.0) -> bytes:
    """Send raw bytes, return everything answered until the server closes or goes quiet."""
    with socket.create_connection(srv.server_address, timeout=seconds) as sock:
        sock.sendall(data)
        out, deadline = b"", time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                chunk = sock.recv(65536)
            except TimeoutError:
                break
            if not chunk:
                break
            out += chunk
            sock.settimeout(0.5)  # the answer is in: stop once the line is quiet
    return out


def _csv(points) -> bytes:
    return ("x,y\n" + "\n".join(f"{x:.6f},{y:.6f}" for x, y in points)).encode()


def _circle(n=40, r=1.0, petals=0.0):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = r * (1 + petals * np.cos(3 * t))
    return np.c_[r * np.cos(t), r * np.sin(t)]


def _shapes(srv, n=40):
    """A circle and a flower: not a similarity of each other (a circle onto a larger one
    is reached by the pairs' turn and scale alone, in one step, whatever the springs)."""
    ids = []
    for name, pts in (("a.csv", _circle(n)), ("b.csv", _circle(n, 1.3, petals=0.2))):
        status, shape = _request(srv, "POST", f"/api/upload?name={name}", _csv(pts))
        assert status == 200, shape
        ids.append(shape["id"])
    return ids


def _run(srv, ids, options):
    return _request(srv, "POST", "/api/run", json.dumps(
        {"source": ids[0], "target": ids[1], "options": options}).encode())


# ----------------------------------------------------------------------------- bombs


def _npz_bomb(path: Path, gib: float = 1.0) -> Path:
    """An NPZ of compressed zeros: about 1 MB on disk, ``gib`` GiB once inflated."""
    n = int(gib * 2**30) // 8
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False,
                                                  "shape": (n,)})
    chunk = bytes(2**24)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive, \
            archive.open("points.npy", "w", force_zip64=True) as member:
        member.write(header.getvalue())
        for _ in range(n * 8 // len(chunk)):
            member.write(chunk)
    return path


def test_npz_bomb_is_refused_before_it_is_inflated(server, tmp_path):
    bomb = _npz_bomb(tmp_path / "bomb.npz").read_bytes()
    assert len(bomb) < 2 * 2**20  # 1 MB that declares 1 GiB
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    start = time.monotonic()
    status, answer = _request(server, "POST", "/api/upload?name=bomb.npz", bomb)
    assert status == 413 and "max_array_bytes" in answer["error"], answer
    assert answer["field"] == "max_array_bytes"
    assert time.monotonic() - start < 10
    grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
    assert grown < 200 * 2**10, f"the peak memory grew by {grown} KiB"  # < 200 MB, not 1 GiB


def _png_header(width: int, height: int) -> bytes:
    """A PNG that declares ``width`` x ``height`` pixels and holds none."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(
            ">I", zlib.crc32(kind + data))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b"")


@pytest.mark.parametrize("size", [(20000, 20000), (6000, 5000)])
def test_image_over_the_pixel_limit_is_refused_from_its_header(server, size):
    status, answer = _request(server, "POST", "/api/upload?name=big.png", _png_header(*size))
    assert status == 413 and "max_pixels" in answer["error"], answer


@pytest.mark.parametrize("name", ["big.nii", "big.nii.gz"])
def test_nifti_declaring_a_huge_volume_is_refused_from_its_header(server, name):
    """A NIfTI header of 2000 x 2000 x 2000 float64 voxels (64 GB), the data never sent."""
    nib = pytest.importorskip("nibabel")
    header = nib.Nifti1Header()
    header.set_data_shape((2000, 2000, 2000))
    header.set_data_dtype(np.float64)
    head = header.binaryblock + b"\0" * 4  # the extension flag, then no data at all
    body = gzip.compress(head) if name.endswith(".gz") else head
    status, answer = _request(server, "POST", f"/api/upload?name={name}", body)
    assert status == 413 and "max_array_bytes" in answer["error"], answer
    lying = nib.Nifti1Header()  # float64 voxels whose header claims 8 bits each
    lying.set_data_shape((400, 400, 100))
    lying.set_data_dtype(np.float64)
    block = bytearray(lying.binaryblock + b"\0" * 4)
    block[72:74] = struct.pack("<h", 8)  # bitpix; nibabel sizes the data by the datatype
    body = gzip.compress(bytes(block)) if name.endswith(".gz") else bytes(block)
    status, answer = _request(server, "POST", f"/api/upload?name={name}", body)
    assert status == 413 and "8 bytes a voxel" in answer["error"], answer
    if name.endswith(".gz"):  # a broken deflate stream: a 4xx naming the file, not a 500
        broken = b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\x03" + b"\xff" * 600
        status, answer = _request(server, "POST", f"/api/upload?name={name}", broken)
        assert 400 <= status < 500 and name in answer["error"], answer
    i, j = np.indices((40, 40))  # a small mask of the same kind is taken
    small = nib.Nifti1Image(((i - 20) ** 2 + (j - 18) ** 2 < 150).astype(np.uint8), np.eye(4))
    body = small.to_bytes()
    status, answer = _request(server, "POST", f"/api/upload?name={name}",
                              gzip.compress(body) if name.endswith(".gz") else body)
    assert status == 200, answer


@pytest.mark.parametrize("kind", ["nifti2", "big-endian"])
def test_check_nifti_reads_nifti2_and_big_endian_headers(tmp_path, kind):
    """The header bound reads a NIfTI-2 header (540 bytes, 64-bit dims) and a big-endian
    NIfTI-1 one as nibabel writes them: the shape they declare, and LimitError over the
    bound, from the header alone."""
    nib = pytest.importorskip("nibabel")
    from modalmorph.io.limits import LimitError, Limits, check_nifti

    def header(shape):
        h = nib.Nifti2Header() if kind == "nifti2" else nib.Nifti1Header().as_byteswapped(">")
        h.set_data_shape(shape)
        h.set_data_dtype(np.float32)
        return h.binaryblock + b"\0" * 4

    path = tmp_path / "x.nii"
    path.write_bytes(header((30, 20, 10)))
    assert check_nifti(path) == (30, 20, 10)
    path.write_bytes(header((3000, 2000, 1000)))  # 24 GB of float32 voxels
    with pytest.raises(LimitError, match="4 bytes a voxel"):
        check_nifti(path, Limits(max_array_bytes=10**9))


def test_npy_declaring_a_huge_array_is_refused(server):
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False,
                                                  "shape": (2**28, 2)})
    status, answer = _request(server, "POST", "/api/upload?name=big.npy", header.getvalue())
    assert status == 413 and "max_array_bytes" in answer["error"], answer
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "|O", "fortran_order": False,
                                                  "shape": (3, 2)})
    status, answer = _request(server, "POST", "/api/upload?name=obj.npy", header.getvalue())
    assert status == 413 and "objects" in answer["error"], answer


def _fanout_svg(depth: int) -> bytes:
    """Groups that each <use> the group below 10 times, ``depth`` deep (review17: 1.6 kB
    at depth 6 drew a million triangles, the server growing without bound)."""
    groups = "".join(f'<g id="p{i + 1}">' + f'<use xlink:href="#p{i}"/>' * 10 + "</g>"
                     for i in range(depth))
    return (f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/'
            f'xlink"><defs><path id="p0" d="M0 0 L10 0 L10 10 Z"/>{groups}</defs>'
            f'<use xlink:href="#p{depth}"/></svg>').encode()


def test_svg_whose_uses_multiply_is_refused_before_it_is_drawn(server, monkeypatch):
    svgelements = pytest.importorskip("svgelements")

    def drawn(*args, **kwargs):
        raise AssertionError("svgelements was asked to draw it")

    monkeypatch.setattr(svgelements.SVG, "parse", drawn)
    status, answer = _request(server, "POST", "/api/upload?name=fanout.svg", _fanout_svg(6))
    assert status == 413 and answer["field"] == "max_svg_elements", answer
    assert answer["error"].startswith("fanout.svg: 4691351 elements once each <use> is "
                                      "expanded, the limit (max_svg_elements) is "), answer


def test_deep_json_and_wrong_types_are_4xx_not_500(server):
    deep = b"[" * 20000 + b"]" * 20000
    status, answer = _request(server, "POST", "/api/run", deep)
    assert status == 413 and "max_json_depth" in answer["error"], answer
    status, answer = _request(server, "POST", "/api/upload?name=deep.json", deep)
    assert status == 413 and "max_json_depth" in answer["error"], answer
    ids = _shapes(server)
    for options in ([1, 2], "k=3", {"k": {"a": 1}}, {"k": [1]}):
        status, answer = _run(server, ids, options)
        assert status == 400 and "options must be an object" in answer["error"], answer
    for body in (b"[1]", b"not json", b'"text"'):
        assert _request(server, "POST", "/api/run", body)[0] == 400
    status, answer = _request(server, "POST", "/api/example", b'{"name": ["heart"]}')
    assert status == 400 and "no example" in answer["error"]
    for query in ("nodes=abc", "nodes=1", "nodes=10000000", "threshold=x"):
        status, answer = _request(server, "POST", f"/api/upload?name=a.csv&{query}",
                                  _csv(_circle()))
        assert status == 400 and answer["field"] == query.split("=")[0], answer


# ------------------------------------------------------------------------ cross-site


def test_cross_site_requests_are_refused(server):
    ids = _shapes(server)
    body = json.dumps({"source": ids[0], "target": ids[1], "options": {}}).encode()
    port = server.server_address[1]
    refused = [
        ({"Origin": "http://evil.example"}, True, "Origin"),
        ({"Origin": f"http://localhost:{port + 1}"}, True, "Origin"),  # another port
        ({"Origin": "null"}, True, "Origin"),  # a sandboxed frame or a file
        ({"Sec-Fetch-Site": "cross-site"}, True, "Sec-Fetch-Site"),
        ({"Sec-Fetch-Site": "same-site"}, True, "Sec-Fetch-Site"),
        ({}, False, "X-Modalmorph-Token"),  # no token: a form posted from another page
        ({"X-Modalmorph-Token": "guess"}, False, "X-Modalmorph-Token"),
        ({"Host": "evil.example"}, True, "Host"),  # DNS rebinding
    ]
    for headers, token, word in refused:
        status, answer = _request(server, "POST", "/api/run", body, headers, token=token)
        assert status == 403 and word in answer["error"], (headers, answer)
    status, answer = _request(server, "GET", "/api/schema",
                              headers={"Origin": "http://evil.example"})
    assert status == 403
    own = {"Origin": f"http://127.0.0.1:{port}", "Sec-Fetch-Site": "same-origin"}
    status, answer = _run(server, ids, {"max_steps": "2"})
    assert status == 200, answer
    assert _request(server, "POST", "/api/run", body, own)[0] == 200


def test_the_page_holds_the_token_and_forbids_framing(server):
    conn = http.client.HTTPConnection(*server.server_address, timeout=WAIT)
    conn.request("GET", "/")
    response = conn.getresponse()
    page = response.read().decode()
    conn.close()
    assert f'<meta name="mm-token" content="{server.token}">' in page
    assert "frame-ancestors 'none'" in response.getheader("Content-Security-Policy")
    assert response.getheader("X-Frame-Options") == "DENY"


# ------------------------------------------------------------- malformed HTTP, smuggling


def _status_lines(answer: bytes) -> list[bytes]:
    return re.findall(rb"HTTP/1\.1 (\d{3})", answer)


@pytest.mark.parametrize("headers", [
    b"Content-Length: -1\r\n",
    b"Content-Length: 5\r\nContent-Length: 6\r\n",
    b"Content-Length: 5\r\nTransfer-Encoding: chunked\r\n",
    b"Content-Length: 1e3\r\n",
    b"Transfer-Encoding: gzip, chunked, identity\r\n",
])
def test_malformed_lengths_are_400(server, headers):
    answer = _raw(server, b"POST /api/run HTTP/1.1\r\nHost: 127.0.0.1\r\n" + headers +
                  b"\r\nhello")
    assert _status_lines(answer) == [b"400"], answer[:200]


def test_no_length_is_411(server):
    answer = _raw(server, b"POST /api/run HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                  b"Transfer-Encoding: chunked\r\nX-Modalmorph-Token: " + server.token.encode()
                  + b"\r\n\r\n2\r\n{}\r\n0\r\n\r\n")
    assert _status_lines(answer) == [b"411"], answer[:300]


def test_refused_body_is_not_served_as_a_request(server):
    inner = b"GET /api/schema HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
    answer = _raw(server, b"POST /api/run HTTP/1.1\r\nHost: evil.example\r\n"
                  b"Content-Length: %d\r\n\r\n" % len(inner) + inner)
    assert _status_lines(answer) == [b"403"], answer  # one answer: the body was discarded
    too_big = str(APP_LIMITS.files.max_file_bytes * 100).encode()
    answer = _raw(server, b"POST /api/upload?name=a.csv HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                  b"X-Modalmorph-Token: " + server.token.encode() +
                  b"\r\nContent-Length: " + too_big + b"\r\n\r\n" + inner)
    assert _status_lines(answer) == [b"413"] and b"max_upload" in answer, answer


def test_idle_and_slow_connections_are_closed(server):
    start = time.monotonic()
    with socket.create_connection(server.server_address, timeout=WAIT) as sock:
        assert sock.recv(1) == b""  # closed by the server, no answer
    assert time.monotonic() - start < FAST.header_timeout + 5
    start = time.monotonic()
    with socket.create_connection(server.server_address, timeout=WAIT) as sock:
        closed = False
        for byte in b"GET /api/schema HTTP/1.1\r\nHost: 127.0.0.1\r\n":  # slow loris
            try:
                sock.sendall(bytes([byte]))
            except OSError:
                closed = True
                break
            time.sleep(0.2)
            if time.monotonic() - start > FAST.header_timeout + 5:
                break
        closed = closed or sock.recv(1) == b""
    assert closed and time.monotonic() - start < FAST.header_timeout + 5
    status, answer = _request(server, "POST", "/api/upload?name=a.csv", b"x,y\n",
                              {"Content-Length": "1000"})  # a body that never comes
    assert status == 408 and "body_timeout" in answer["error"], answer


def test_simultaneous_clients_are_all_answered(server):
    answers = []

    def client():
        answers.append(_request(server, "GET", "/api/schema")[0])

    threads = [threading.Thread(target=client) for _ in range(50)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(WAIT)
    assert answers == [200] * 50


# ---------------------------------------------------------------------------- caps


def test_steps_and_nodes_are_bounded(server):
    ids = _shapes(server)
    status, answer = _run(server, ids, {"max_steps": str(APP_LIMITS.max_steps + 1)})
    assert status == 400 and answer["field"] == "max_steps" and "max_steps limit" in \
        answer["error"], answer
    status, answer = _run(server, ids, {"max_steps": "5000", "model_nodes": "1001"})
    assert status == 400 and answer["field"] == "model_nodes", answer
    big = _shapes(server, n=200)
    status, answer = _run(server, big, {"max_steps": "2000"})
    assert status == 400 and "max_node_steps" in answer["error"], answer
    status, answer = _request(server, "POST", "/api/upload?name=many.csv",
                              _csv(_circle(APP_LIMITS.max_nodes + 1)))
    assert status == 413 and "max_nodes" in answer["error"], answer


def _state(srv, job):
    return _request(srv, "GET", f"/api/job/{job}")


def _until(check, what: str, seconds: float = WAIT):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if check():
            return
        time.sleep(0.05)
    raise AssertionError(f"not within {seconds} s: {what}")


LONG = {"k": "0.01", "dt": "0.001", "max_steps": "5000", "equilibrium_tol": "0"}


def test_runs_are_capped_queued_cancelled_when_evicted_and_expired():
    srv = _start(replace(FAST, max_running=1, max_queued=1, keep=2, job_ttl=1.0))
    try:
        ids = _shapes(srv)
        first = _run(srv, ids, LONG)[1]["job"]
        _until(lambda: _state(srv, first)[1]["state"] == "running", "the first run starts")
        second = _run(srv, ids, LONG)[1]["job"]
        assert _state(srv, second)[1]["state"] == "queued"
        status, answer = _run(srv, ids, LONG)
        assert status == 429 and "max_running + max_queued" in answer["error"], answer
        # a third entry pushes the oldest (running) run out: it is cancelled, the queued
        # one runs
        _request(srv, "POST", f"/api/job/{second}/stop", b"{}")
        _until(lambda: _state(srv, second)[1]["state"] == "error", "the queued run stops")
        third = _run(srv, ids, {"max_steps": "3"})[1]["job"]
        assert _state(srv, first)[0] == 404  # forgotten
        _until(lambda: _state(srv, third)[1]["state"] == "done", "the slot is freed")
        folder = Path(srv.tmp.name) / third
        assert folder.is_dir()
        time.sleep(1.5)  # past job_ttl
        assert _state(srv, third)[0] == 404 and not folder.exists()  # expired, removed
    finally:
        _stop(srv)


# --------------------------------------------------------------------- hostile names


# (a "/" never reaches the app: it keeps the name's last part)
HOSTILE = ["<!--<script>.csv", "<img src=x onerror=alert(1)>&amp;.csv"]


def test_hostile_file_names_reach_the_report_escaped(server):
    shapes = []
    for name, r in zip(HOSTILE, (1.0, 1.3), strict=True):
        status, shape = _request(server, "POST", "/api/upload?name=" + quote(name),
                                 _csv(_circle(40, r)))
        assert status == 200 and shape["name"] == name, shape
        shapes.append(shape["id"])
    job = _run(server, shapes, {"max_steps": "3"})[1]["job"]
    _until(lambda: _state(server, job)[1]["state"] == "done", "the run")
    conn = http.client.HTTPConnection(*server.server_address, timeout=WAIT)
    conn.request("GET", f"/api/job/{job}/file/report.html")
    page = conn.getresponse().read().decode()
    conn.close()
    data = page.split('id="mm-data" type="application/json">', 1)[1].split("</script>")[0]
    assert "<" not in data and ">" not in data and "&" not in data
    assert json.loads(data)["title"] == f"{HOSTILE[0]} → {HOSTILE[1]}"


# -------------------------------------------------------------------------- signals


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_signals_stop_the_app_and_remove_its_folder(tmp_path, sig):
    env = {**os.environ, "TMPDIR": str(tmp_path), "PYTHONPATH": str(ROOT / "src")}
    with subprocess.Popen([sys.executable, "-m", "modalmorph", "app", "--port", "0"],
                          env=env, stderr=subprocess.PIPE, text=True) as proc:
        try:
            line = proc.stderr.readline()  # "modalmorph app at http://localhost:PORT/ ..."
            port = int(re.search(r":(\d+)/", line).group(1))
            page = http.client.HTTPConnection("127.0.0.1", port, timeout=WAIT)
            page.request("GET", "/")
            token = re.search(r'mm-token" content="([^"]+)"',
                              page.getresponse().read().decode()).group(1)
            page.close()
            srv = type("Session", (), {"server_address": ("127.0.0.1", port), "token": token})
            _run(srv, _shapes(srv), LONG)  # a run under way when the signal comes
            assert [p for p in tmp_path.iterdir() if p.name.startswith("modalmorph-app-")]
            proc.send_signal(sig)
            expected = 130 if sig == signal.SIGINT else 0  # Ctrl-C: the interrupted code
            assert proc.wait(WAIT) == expected, proc.stderr.read()
            assert proc.stderr.read().strip().splitlines() == ["modalmorph app stopped"]
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(WAIT)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("modalmorph-app-")]


# A server whose reads never end (allocating as review17's SVG did), started as `modalmorph app`.
_STUCK_APP = """
import sys, threading
from modalmorph.apps import routes
from modalmorph.apps.cli import main

def stuck(*args):
    print("reading", file=sys.stderr, flush=True)
    held = []
    while not threading.Event().wait(0.2):
        held.append(bytearray(2**20))

routes._read_upload = stuck
sys.exit(main(["app", "--port", "0"]))
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signals_stop_the_app_while_a_read_never_ends(tmp_path, sig):
    """review17: "modalmorph app stopped" was logged, and the process went on reading and
    growing until kill -9 (the reader's thread was joined at exit)."""
    env = {**os.environ, "TMPDIR": str(tmp_path), "PYTHONPATH": str(ROOT / "src")}
    with subprocess.Popen([sys.executable, "-c", _STUCK_APP], env=env,
                          stderr=subprocess.PIPE, text=True) as proc:
        try:
            port = int(re.search(r":(\d+)/", proc.stderr.readline()).group(1))
            page = http.client.HTTPConnection("127.0.0.1", port, timeout=WAIT)
            page.request("GET", "/")
            token = re.search(r'mm-token" content="([^"]+)"',
                              page.getresponse().read().decode()).group(1)
            page.close()
            upload = http.client.HTTPConnection("127.0.0.1", port, timeout=WAIT)
            upload.request("POST", "/api/upload?name=a.csv", body=_csv(_circle()),
                           headers={"X-Modalmorph-Token": token})
            assert proc.stderr.readline().strip() == "reading"
            proc.send_signal(sig)
            expected = 130 if sig == signal.SIGINT else 0
            assert proc.wait(WAIT) == expected, proc.stderr.read()
            status = upload.getresponse().status
            lines = proc.stderr.read().strip().splitlines()
            assert lines[-1] == "modalmorph app stopped" and "Traceback" not in lines, lines
            assert status == 503
            upload.close()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(WAIT)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("modalmorph-app-")]


def test_without_the_extra_the_app_says_what_to_install(monkeypatch, capsys):
    from modalmorph.apps.app import MISSING_EXTRA
    from modalmorph.apps.cli import main

    for name in [m for m in sys.modules if m.split(".")[0] in ("starlette", "uvicorn")]:
        monkeypatch.setitem(sys.modules, name, None)  # as if not installed
    monkeypatch.setitem(sys.modules, "starlette", None)
    for name in ("server", "routes", "guard"):
        monkeypatch.delitem(sys.modules, f"modalmorph.apps.{name}", raising=False)
    assert main(["app", "--port", "0"]) == 2
    assert capsys.readouterr().err.strip() == f"modalmorph: error: {MISSING_EXTRA}"
