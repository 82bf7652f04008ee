"""A WebSocket client on a bare socket, for tests of clients that stop reading: it does the handshake, sends
text frames, and reads (or does not read) frames only when told to."""

from __future__ import annotations

import base64
import os
import socket
import struct
import time
from urllib.parse import urlsplit


class RawClient:
    """``RawClient(url)``: connected and upgraded; ``receive_buffer`` sets ``SO_RCVBUF`` before connecting."""

    def __init__(self, url: str, receive_buffer: int | None = None, timeout: float = 10.0):
        parts = urlsplit(url)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if receive_buffer is not None:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
        self.sock.settimeout(timeout)
        self.sock.connect((parts.hostname, parts.port))
        key = base64.b64encode(os.urandom(16)).decode()
        path = parts.path or "/"
        if parts.query:
            path += "?" + parts.query
        self.sock.sendall(f"GET {path} HTTP/1.1\r\nHost: {parts.hostname}:{parts.port}\r\nUpgrade: websocket\r\n"
                          f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
                          .encode())
        self.buffer = b""
        while b"\r\n\r\n" not in self.buffer:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("the server closed the connection during the handshake")
            self.buffer += chunk
        head, _, self.buffer = self.buffer.partition(b"\r\n\r\n")
        if not head.startswith(b"HTTP/1.1 101"):
            raise ConnectionError(head.split(b"\r\n", 1)[0].decode())

    def send(self, text: str | bytes, opcode: int = 0x1) -> None:
        """A masked frame (text by default; 0x8: a close frame, ``text`` its payload)."""
        payload = text.encode() if isinstance(text, str) else text
        n = len(payload)
        if n < 126:
            header = struct.pack("!BB", 0x80 | opcode, 0x80 | n)
        elif n < 2 ** 16:
            header = struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, n)
        else:
            header = struct.pack("!BBQ", 0x80 | opcode, 0x80 | 127, n)
        mask = os.urandom(4)
        self.sock.sendall(header + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))

    def read(self, n: int, deadline: float) -> bytes:
        while len(self.buffer) < n:
            self.sock.settimeout(max(0.01, deadline - time.monotonic()))
            chunk = self.sock.recv(2 ** 16)
            if not chunk:
                raise EOFError
            self.buffer += chunk
        data, self.buffer = self.buffer[:n], self.buffer[n:]
        return data

    def frame(self, deadline: float) -> tuple[int, bytes]:
        """The next frame the server sent: (opcode, payload); EOFError when the connection ended. A ping read
        is answered with its pong, as every WebSocket client does, and not returned."""
        while True:
            b0, b1 = self.read(2, deadline)
            n = b1 & 0x7F
            if n == 126:
                (n,) = struct.unpack("!H", self.read(2, deadline))
            elif n == 127:
                (n,) = struct.unpack("!Q", self.read(8, deadline))
            opcode, payload = b0 & 0x0F, self.read(n, deadline)
            if opcode != 0x9:
                return opcode, payload
            self.send(payload, opcode=0xA)

    def close(self) -> None:
        self.sock.close()
