"""Open a run report in headless Chromium over the DevTools protocol: load it, ask its ``window.report``,
take screenshots.

:class:`Chromium` starts ``chromium --headless=new`` with a remote debugging port of its own choosing
(read back from ``DevToolsActivePort`` in a temporary profile) and speaks the protocol over a WebSocket
(the ``websockets`` package, sync client) to one page: ``Page.navigate``, ``Runtime.evaluate``,
``Page.captureScreenshot``. Script errors the page throws (``Runtime.exceptionThrown``) and its console
errors are collected in :attr:`Chromium.exceptions`. Nothing but loopback is contacted.
"""

from __future__ import annotations

import base64
import contextlib
import json
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

#: Where Debian's chromium package puts the browser.
CHROMIUM = "/usr/bin/chromium"
#: How to get it.
INSTALL = "apt-get install chromium"


class BrowserError(RuntimeError):
    """Chromium could not be started or driven, or the page threw on an evaluation."""


def find_chromium(executable: str | None = None) -> str:
    """The Chromium executable to run: ``executable``, else ``/usr/bin/chromium`` or one on PATH."""
    for candidate in (executable, CHROMIUM, shutil.which("chromium"), shutil.which("chromium-browser"),
                      shutil.which("google-chrome")):
        if candidate and Path(candidate).exists():
            return str(candidate)
    raise BrowserError(f"no Chromium found: {INSTALL}")


class Chromium:
    """A headless Chromium with one page, driven over the DevTools protocol. Use as a context manager.

    Parameters
    ----------
    executable : str, optional
        The browser (default: :func:`find_chromium`).
    width, height : int
        The page's viewport in CSS pixels.
    args : sequence of str
        More command-line switches.
    timeout : float
        Seconds to wait for the browser to start and for each protocol answer.
    """

    def __init__(self, executable: str | None = None, width: int = 1280, height: int = 900, args=(),
                 timeout: float = 60.0):
        self.executable = find_chromium(executable)
        self.width, self.height = int(width), int(height)
        self.args = list(args)
        self.timeout = float(timeout)
        self.exceptions: list[str] = []
        self.console: list[str] = []
        self.events: list[dict] = []
        self.process: subprocess.Popen | None = None
        self.profile: str | None = None
        self.socket = None
        self.connection = contextlib.ExitStack()
        self.next_id = 0

    # ------------------------------------------------------------------ lifetime
    def __enter__(self) -> "Chromium":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:
        """Start the browser and connect to its page."""
        try:
            from websockets.sync.client import connect
        except ImportError as e:  # pragma: no cover - a dependency of the project
            raise BrowserError("driving Chromium needs the websockets package: pip install websockets") from e
        self.profile = tempfile.mkdtemp(prefix="agentsim-chromium-")
        log = open(Path(self.profile) / "chromium.log", "wb")
        command = [self.executable, "--headless=new", "--no-sandbox", "--disable-gpu", "--remote-debugging-port=0",
                   f"--user-data-dir={self.profile}", "--autoplay-policy=no-user-gesture-required",
                   "--no-first-run", "--no-default-browser-check", "--disable-extensions",
                   "--disable-background-networking", "--disable-component-update", "--disable-sync",
                   f"--window-size={self.width},{self.height}", *self.args, "about:blank"]
        self.process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=log, stderr=log)
        log.close()
        port_file = Path(self.profile) / "DevToolsActivePort"
        deadline = time.monotonic() + self.timeout
        while True:
            if port_file.exists() and len(port_file.read_text().split()) >= 2:
                break
            if self.process.poll() is not None or time.monotonic() > deadline:
                text = (Path(self.profile) / "chromium.log").read_text(errors="replace")[-2000:]
                self.close()
                raise BrowserError(f"Chromium did not start ({self.executable}):\n{text}")
            time.sleep(0.05)
        port = int(port_file.read_text().split()[0])
        page = None
        while page is None:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=self.timeout) as answer:
                targets = json.loads(answer.read())
            page = next((t for t in targets if t.get("type") == "page"), None)
            if page is None:
                if time.monotonic() > deadline:
                    self.close()
                    raise BrowserError("Chromium has no page to drive")
                time.sleep(0.05)
        self.socket = self.connection.enter_context(
            connect(page["webSocketDebuggerUrl"], max_size=None, open_timeout=self.timeout))
        self.send("Page.enable")
        self.send("Runtime.enable")
        self.send("Emulation.setDeviceMetricsOverride",
                  {"width": self.width, "height": self.height, "deviceScaleFactor": 1, "mobile": False})

    def close(self) -> None:
        """Disconnect, stop the browser and remove its temporary profile."""
        if self.socket is not None:
            try:
                self.connection.close()
            except Exception:  # the browser may be gone already
                pass
            self.socket = None
        if self.process is not None:
            if self.process.poll() is None:
                self.process.terminate()
                try:
                    self.process.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    self.process.kill()
                    self.process.wait(timeout=10)
            self.process = None
        if self.profile is not None:
            shutil.rmtree(self.profile, ignore_errors=True)
            self.profile = None

    # ------------------------------------------------------------------ the protocol
    def send(self, method: str, params: dict | None = None, timeout: float | None = None) -> dict:
        """Send one command and return its result (events that arrive meanwhile are kept)."""
        if self.socket is None:
            raise BrowserError("the browser is not running")
        self.next_id += 1
        ident = self.next_id
        self.socket.send(json.dumps({"id": ident, "method": method, "params": params or {}}))
        deadline = time.monotonic() + (timeout if timeout is not None else self.timeout)
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise BrowserError(f"no answer to {method} in time")
            try:
                message = json.loads(self.socket.recv(timeout=remaining))
            except TimeoutError:
                raise BrowserError(f"no answer to {method} in time") from None
            if message.get("id") == ident:
                if "error" in message:
                    raise BrowserError(f"{method}: {message['error'].get('message')}")
                return message.get("result", {})
            self.event(message)

    def event(self, message: dict) -> None:
        """Keep an event; script errors and console errors go to :attr:`exceptions` and :attr:`console`."""
        method = message.get("method", "")
        params = message.get("params", {})
        self.events.append(message)
        if method == "Runtime.exceptionThrown":
            details = params.get("exceptionDetails", {})
            described = details.get("exception", {}).get("description") or details.get("text", "")
            self.exceptions.append(f"{described} ({details.get('url', '')}:{details.get('lineNumber')})")
        elif method == "Runtime.consoleAPICalled":
            text = " ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", []))
            self.console.append(f"{params.get('type')}: {text}")

    def wait_event(self, method: str, timeout: float | None = None, since: int = 0) -> dict:
        """Wait for an event named ``method`` (among those after index ``since`` of :attr:`events`)."""
        deadline = time.monotonic() + (timeout if timeout is not None else self.timeout)
        while True:
            for message in self.events[since:]:
                if message.get("method") == method:
                    return message
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise BrowserError(f"no {method} in time")
            try:
                self.event(json.loads(self.socket.recv(timeout=remaining)))
            except TimeoutError:
                raise BrowserError(f"no {method} in time") from None

    # ------------------------------------------------------------------ pages
    def navigate(self, url: str | Path, timeout: float | None = None) -> float:
        """Load ``url`` (a path is opened as ``file://``) and wait for its load event; returns the seconds
        it took."""
        if isinstance(url, Path) or str(url).split(":", 1)[0] not in ("http", "https", "file", "about", "data"):
            url = Path(url).resolve().as_uri()
        since = len(self.events)
        started = time.perf_counter()
        result = self.send("Page.navigate", {"url": str(url)})
        if result.get("errorText"):
            raise BrowserError(f"cannot open {url}: {result['errorText']}")
        self.wait_event("Page.loadEventFired", timeout, since)
        return time.perf_counter() - started

    def evaluate(self, expression: str, await_promise: bool = False):
        """The value of a JavaScript expression in the page (JSON-like values come back as Python values)."""
        result = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                                "awaitPromise": await_promise})
        if "exceptionDetails" in result:
            details = result["exceptionDetails"]
            raise BrowserError(details.get("exception", {}).get("description") or details.get("text", "error"))
        return result.get("result", {}).get("value")

    def wait_for(self, expression: str, timeout: float | None = None, interval: float = 0.05):
        """Wait until ``expression`` is truthy in the page; returns its value."""
        deadline = time.monotonic() + (timeout if timeout is not None else self.timeout)
        while True:
            value = self.evaluate(expression)
            if value:
                return value
            if time.monotonic() > deadline:
                raise BrowserError(f"{expression} did not become true in time")
            time.sleep(interval)

    def screenshot(self, path: str | Path, full_page: bool = False) -> Path:
        """Save a PNG of the viewport (or of the whole page) to ``path``."""
        params = {"format": "png"}
        if full_page:
            metrics = self.send("Page.getLayoutMetrics")
            size = metrics.get("cssContentSize") or metrics.get("contentSize")
            params.update(captureBeyondViewport=True, clip={"x": 0, "y": 0, "width": size["width"],
                                                            "height": size["height"], "scale": 1})
        data = self.send("Page.captureScreenshot", params)["data"]
        from agentsim.written import written

        path = Path(path)
        with written(path) as tmp:
            tmp.write_bytes(base64.b64decode(data))
        return path


def open_report(path: str | Path, browser: Chromium, timeout: float = 60.0) -> float:
    """Open a report written by :func:`~agentsim.media.report.write_report` in ``browser`` and wait until its
    ``window.report.ready``; returns the seconds from navigation to ready."""
    started = time.perf_counter()
    browser.navigate(path, timeout)
    browser.wait_for("window.report && window.report.ready", timeout, interval=0.01)
    return time.perf_counter() - started
