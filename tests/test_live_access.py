"""Who may connect to ``agentsim serve``, with a real WebSocket client and real HTTP requests: a browser page
from a foreign origin is refused with 403 and nothing else, the viewer's own origin and ``--allow-origin``
ones are taken, programs without an Origin are taken; a token is needed on the WebSocket and the viewer's
page when there is one, and is made up (and printed) when the server listens beyond loopback."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from agentsim.errors import UsageError
from agentsim.live.poses import viewer_files
from agentsim.live.access import is_loopback, origin_of
from agentsim.live.service import Background, Service
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
NOD = f'<bml {NS} id="n"><head id="h" lexeme="NOD"/></bml>'


@pytest.fixture(scope="module")
def open_server():
    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend(),
                            allow_origins=["https://Friend.example:8443/"])) as running:
        running.service.server.files = viewer_files()  # the page, without evaluating poses
        yield running


@pytest.fixture(scope="module")
def token_server():
    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend(), token="s3cret")) as running:
        running.service.server.files = viewer_files()
        yield running


def runs_a_block(ws) -> None:
    """The connection works: a block sent on it is answered with its end."""
    ws.send(NOD)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        item = json.loads(ws.recv(timeout=deadline - time.monotonic()))
        if item["id"] == "n:end":
            return
    raise AssertionError("no n:end")


def refused(url: str, **options) -> InvalidStatus:
    with pytest.raises(InvalidStatus) as caught:
        with connect(url, open_timeout=5, **options):
            pass
    assert caught.value.response.status_code == 403
    return caught.value


def raw_handshake(port: int, host_header: str, origin: str, path: str = "/") -> bytes:
    """The HTTP response to a WebSocket upgrade with these ``Host`` and ``Origin`` headers (as a page whose
    own name resolves to this machine sends it)."""
    request = (f"GET {path} HTTP/1.1\r\nHost: {host_header}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\nOrigin: {origin}\r\n\r\n")
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(request.encode())
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = sock.recv(4096)
            if not chunk:
                break
            data += chunk
        sock.settimeout(0.5)
        try:
            while chunk := sock.recv(4096):
                data += chunk
        except TimeoutError:
            pass
    return data


def http_status(url: str, origin: str | None = None) -> tuple[int, bytes]:
    request = urllib.request.Request(url, headers={"Origin": origin} if origin else {})
    try:
        with urllib.request.urlopen(request, timeout=5) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def test_a_foreign_origin_is_refused_with_403_and_counted(open_server):
    server = open_server.service.server
    before = server.counters["refused_origins"]
    error = refused(open_server.url, origin="https://evil.example")
    assert error.response.body == b"Forbidden\n"
    refused(open_server.url, origin=f"http://evil.example:{server.port}")
    assert server.counters["refused_origins"] == before + 2


def test_a_page_whose_name_resolves_here_is_refused(open_server):
    """DNS rebinding: the page's origin and the Host header agree, but name another host than loopback."""
    port = open_server.service.server.port
    answer = raw_handshake(port, f"evil.example:{port}", f"http://evil.example:{port}")
    assert answer.startswith(b"HTTP/1.1 403 "), answer[:80]
    head = answer.split(b"\r\n\r\n")[0].lower()
    assert b"upgrade" not in head and b"\r\nserver:" not in head, head  # nor the library's name and version
    assert answer.endswith(b"Forbidden\n")
    answer = raw_handshake(port, f"localhost:{port}", f"http://localhost:{port}")
    assert answer.startswith(b"HTTP/1.1 101 "), answer[:80]
    assert b"\r\nserver:" not in answer.split(b"\r\n\r\n")[0].lower()


def test_the_viewers_own_origin_an_allowed_one_and_programs_are_taken(open_server):
    port = open_server.service.server.port
    with connect(open_server.url, origin=f"http://127.0.0.1:{port}") as ws:
        runs_a_block(ws)
    with connect(open_server.url, origin="https://friend.example:8443") as ws:
        runs_a_block(ws)
    with connect(open_server.url) as ws:  # no Origin: a program
        runs_a_block(ws)
    refused(open_server.url, origin="https://friend.example")  # another port is another origin
    refused(open_server.url, origin=f"http://127.0.0.1:{port + 1}")


def test_a_page_fetched_from_a_foreign_origin_is_refused(open_server):
    base = f"http://127.0.0.1:{open_server.service.server.port}/"
    status, body = http_status(base)
    assert status == 200 and b"agentsim serve: live" in body
    assert http_status(base, origin="https://evil.example") == (403, b"Forbidden\n")


def test_the_token_is_needed_on_the_websocket_and_the_page(token_server):
    server = token_server.service.server
    assert not server.access.token_made and token_server.url.endswith("/?token=s3cret")
    plain = f"ws://127.0.0.1:{server.port}/"
    before = server.counters["refused_tokens"]
    refused(plain)
    refused(plain + "?token=s3cre")
    refused(plain + "?token=s3cretx")
    assert server.counters["refused_tokens"] == before + 3
    with connect(token_server.url) as ws:
        runs_a_block(ws)
    page = f"http://127.0.0.1:{server.port}/"
    assert http_status(page) == (403, b"Forbidden\n")
    assert http_status(page + "index.html?token=nope") == (403, b"Forbidden\n")
    status, body = http_status(page + "?token=s3cret")
    assert status == 200 and b"report.js" in body
    # the page's script, which passes the page's token on to its WebSocket, is the package's own file
    status, script = http_status(page + "report.js")
    assert status == 200 and b'get("token")' in script
    # the right token from a foreign page is still a foreign page
    refused(token_server.url, origin="https://evil.example")


def test_loopback_names_and_origins():
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("[::1]") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("::") and not is_loopback("example.org")
    assert origin_of("HTTPS://Friend.Example:8443/") == "https://friend.example:8443"
    for bad in ("friend.example", "ftp://x", "https://x/path", "https://x:99999", "https://x/?q=1"):
        with pytest.raises(UsageError, match="--allow-origin takes an origin"):
            origin_of(bad)


def test_serving_beyond_loopback_makes_up_a_token_and_prints_the_urls_with_it():
    proc = subprocess.Popen([sys.executable, "-m", "agentsim.cli", "serve", "--host", "0.0.0.0", "--port", "0",
                             "--audio", "none", "--fps", "0", "--tts", "builtin"], stderr=subprocess.PIPE, text=True)
    try:
        line = ""
        for line in proc.stderr:
            if line.startswith("agentsim serve:"):
                break
        words = line.split()
        ws_url = next(w for w in words if w.startswith("ws://"))
        http_url = next(w for w in words if w.startswith("http://"))
        assert "0.0.0.0 is not loopback: clients need the token" in line, line
        port, token = ws_url.split(":")[2].split("/")[0], ws_url.split("?token=")[1]
        assert len(token) >= 32 and http_url == f"http://0.0.0.0:{port}/?token={token}"
        local = f"ws://127.0.0.1:{port}/"
        refused(local)
        with connect(f"{local}?token={token}") as ws:
            runs_a_block(ws)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 130
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize("option, message", [
    (("--allow-origin", "evil.example"), "--allow-origin takes an origin"),
    (("--token", ""), "--token must not be empty"),
])
def test_bad_access_options_are_usage_errors(option, message):
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "serve", "--port", "0", "--audio", "none",
                           "--fps", "0", "--tts", "builtin", *option], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    (line,) = proc.stderr.splitlines()
    assert message in line, line
