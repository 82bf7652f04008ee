"""Who may connect to ``agentsim serve``, as a real browser asks (headless Chromium, its own ``Origin`` and
``Host`` headers): the viewer's page opened with ``?token=`` passes the token on to its WebSocket and hears
another client's blocks (it subscribes to the feedback); without the token the page is ``Forbidden``; a page
of another origin, or one whose name resolves to this machine (DNS rebinding, made here with Chromium's
resolver rules), cannot open a WebSocket to it, even with the token."""

from __future__ import annotations

import functools
import http.server
import threading

import pytest

from agentsim.live.poses import viewer_files
from agentsim.live.service import Background, Service
from agentsim.media.report.browser import Chromium, find_chromium
from speech_timing.builtin import BuiltinBackend
from test_live_viewer import BLOCK, clean, feedback_until, free_port, open_viewer

pytestmark = pytest.mark.system

TOKEN = "s3cret-token"
#: What a page's script does to reach the service: open a WebSocket and say whether it opened or how it closed.
OPEN = ("new Promise(done => {{ const ws = new WebSocket({url!r}); ws.onopen = () => {{ ws.close(); done('open'); }};"
        " ws.onclose = e => done('closed ' + e.code); }})")


@pytest.fixture(scope="module")
def chromium():
    """Chromium that takes ``evil.example`` to be this machine, as a rebinding attacker's DNS would make it."""
    try:
        find_chromium()
    except RuntimeError as e:
        pytest.fail(str(e))
    with Chromium(width=800, height=600, args=["--host-resolver-rules=MAP evil.example 127.0.0.1"]) as browser:
        yield browser


@pytest.fixture
def other_site(tmp_path):
    """A web site of another origin (``http://localhost:PORT``), serving an empty page."""
    (tmp_path / "index.html").write_text("<!doctype html><title>another site</title>")
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(tmp_path))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://localhost:{server.server_address[1]}/"
    server.shutdown()
    server.server_close()


def test_the_viewer_passes_its_token_on_and_another_sites_page_is_refused(chromium, other_site):
    port = free_port()
    with Background(Service(port=port, audio="none", fps=30.0, tts=BuiltinBackend(), token=TOKEN)) as running:
        server = running.service.server
        ws_url = f"ws://127.0.0.1:{port}/?token={TOKEN}"
        # the viewer, opened with the token: it connects with it, and hears another client's block
        open_viewer(chromium, port, f"?token={TOKEN}", timeout=15)
        assert chromium.evaluate("report.live.url") == ws_url
        times = feedback_until(running.url, BLOCK, "b1:end")
        chromium.wait_for("document.getElementById('feed').innerText.includes('b1:end')", timeout=10)
        clean(chromium)
        assert "b1:g:stroke" in times
        assert server.counters["refused_tokens"] == 0 and server.counters["refused_origins"] == 0
        # the page without the token: Forbidden, and nothing of the viewer
        chromium.navigate(f"http://127.0.0.1:{port}/")
        assert chromium.evaluate("document.body.innerText").strip() == "Forbidden"
        assert chromium.evaluate("typeof window.report") == "undefined"
        assert server.counters["refused_tokens"] == 1
        # another site's page, even with the token: its WebSocket is refused (403 to the handshake, 1006 to the
        # page)
        chromium.navigate(other_site)
        assert chromium.evaluate(OPEN.format(url=ws_url), await_promise=True) == "closed 1006"
        assert server.counters["refused_origins"] == 1


def test_on_loopback_only_the_viewers_own_pages_may_open_a_websocket(chromium, other_site):
    port = free_port()
    with Background(Service(port=port, audio="none", fps=0, tts=BuiltinBackend())) as running:
        server = running.service.server
        server.files = viewer_files()  # the page, without evaluating poses
        ws_url = f"ws://127.0.0.1:{port}/"
        chromium.navigate(other_site)
        assert chromium.evaluate(OPEN.format(url=ws_url), await_promise=True) == "closed 1006"
        assert server.counters["refused_origins"] == 1
        # a page whose name resolves here (DNS rebinding) is served the server's own page, but cannot open a
        # WebSocket to it by that name
        chromium.navigate(f"http://evil.example:{port}/")
        assert chromium.evaluate("document.title") == "agentsim serve: live"
        rebound = f"ws://evil.example:{port}/"
        assert chromium.evaluate(OPEN.format(url=rebound), await_promise=True) == "closed 1006"
        assert server.counters["refused_origins"] >= 2
        # the server's own pages may, by its loopback names
        for own in (f"http://127.0.0.1:{port}/", f"http://localhost:{port}/"):
            chromium.navigate(own)
            url = own.replace("http://", "ws://")
            assert chromium.evaluate(OPEN.format(url=url), await_promise=True) == "open", own
