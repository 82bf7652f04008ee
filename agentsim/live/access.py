"""Who may connect to ``agentsim serve`` (:class:`Access`), asked of every request before any handshake: a
request with an ``Origin`` header (a browser's) only from the server's own origin (the viewer's page) or one
named in ``allow_origins``; requests without one (programs) are taken. With a token, the WebSocket and the
viewer's page need ``?token=TOKEN`` (the page passes it on to its WebSocket); a server bound to an address
other than loopback without one makes one up."""

from __future__ import annotations

import ipaddress
import secrets

from agentsim.errors import UsageError

#: Host names that are loopback whatever the resolver says.
LOOPBACK_NAMES = ("localhost",)


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or ``localhost``) is reachable from this machine only."""
    host = host.strip().strip("[]").lower()
    if host in LOOPBACK_NAMES or host.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def origin_of(url: str) -> str:
    """``url`` as browsers write an ``Origin`` (``scheme://host[:port]``, lower case, no path);
    :class:`UsageError` if it is not one."""
    from urllib.parse import urlsplit

    text = url.strip()
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError:
        parts, port = None, None
    if (parts is None or parts.scheme.lower() not in ("http", "https") or not parts.hostname
            or parts.path not in ("", "/") or parts.query or parts.fragment or parts.username):
        raise UsageError(f"--allow-origin takes an origin such as https://example.org or http://localhost:8000 "
                         f"(a scheme, a host and a port if any, no path), got {url!r}")
    host = parts.hostname.lower()
    if ":" in host:
        host = f"[{host}]"
    return f"{parts.scheme.lower()}://{host}" + (f":{port}" if port is not None else "")


class Access:
    """Who may connect to a server listening on ``host:port`` (:attr:`port` is set once it listens, when
    it was 0). ``token``: what the WebSocket and the viewer's page need as ``?token=`` (None: nothing; made up
    when ``host`` is not loopback, :attr:`token_made` then). ``allow_origins``: origins
    (``https://host[:port]``) whose pages may connect besides the viewer's own."""

    def __init__(self, host: str, port: int, token: str | None = None,
                 allow_origins: tuple[str, ...] | list[str] = ()):
        self.host, self.port = host, port
        self.loopback = is_loopback(host)
        if token is not None and not token.strip():
            raise UsageError("--token must not be empty")
        self.token_made = token is None and not self.loopback
        self.token = secrets.token_urlsafe(24) if self.token_made else token
        self.allow_origins = frozenset(origin_of(o) for o in allow_origins)

    def own_origin(self, origin: str, host_header: str | None) -> bool:
        """Whether ``origin`` is the viewer's page as the browser reached it: ``http://`` and the ``Host`` the
        request names, when that host is this server's address, or a loopback name on a loopback server (a
        page elsewhere that a name of its own resolves here, DNS rebinding, names its own host), or anything
        on a server that needs a token (the page then had the token)."""
        if not host_header or origin != f"http://{host_header.strip().lower()}":
            return False
        from urllib.parse import urlsplit

        try:
            parts = urlsplit(origin)
            name, port = parts.hostname or "", parts.port or 80
        except ValueError:
            return False
        if port != self.port:
            return False
        if self.token is not None:
            return True
        return is_loopback(name) if self.loopback else name == self.host.strip("[]").lower()

    def refuses(self, origin: str | None, headers, path: str) -> str | None:
        """Why a request is refused (None: it is not): ``"origin"``, a foreign ``origin`` (None: the request
        had none), or ``"token"``, no or a wrong token on the WebSocket or the viewer's page. ``headers``: the
        request's (a mapping, read for its ``Host`` and ``Upgrade``), ``path`` with its query."""
        from urllib.parse import parse_qs

        if origin is not None and origin.lower() not in self.allow_origins \
                and not self.own_origin(origin.lower(), headers.get("Host")):
            return "origin"
        if self.token is not None:
            path, _, query = path.partition("?")
            upgrade = headers.get("Upgrade", "").lower() == "websocket"
            if upgrade or path in ("", "/", "/index.html"):  # the page's scripts and style are the package's
                given = parse_qs(query).get("token", [""])[-1]
                if not secrets.compare_digest(given.encode(), self.token.encode()):
                    return "token"
        return None

    def url(self, scheme: str = "ws") -> str:
        """The WebSocket's (``ws``) or the viewer's (``http``) address, with the token if there is one."""
        host = f"[{self.host}]" if ":" in self.host and not self.host.startswith("[") else self.host
        query = f"?token={self.token}" if self.token is not None else ""
        return f"{scheme}://{host}:{self.port}/{query}"
