"""One end of the twinbot protocol over any pyserial port or URL (protocol/SPEC.md).

Opens /dev/tty..., socket://host:port, loop:// or rfc2217:// with errors a user can act
on, sends messages by name, and turns received bytes into decoded frames while the
decoder keeps count of everything it dropped.
"""
from __future__ import annotations

import errno
import time
from dataclasses import dataclass, field
from typing import Callable

from protocol import messages as M
from protocol.framing import FrameDecoder, FrameEncoder


class LinkError(Exception):
    """The port could not be opened or used; the text says what to do."""


@dataclass
class Frame:
    """A decoded frame, as the host sees it."""

    direction: str  # "rx" or "tx"
    t: float  # seconds since the link opened
    msg_type: int
    seq: int
    fields: dict[str, object]
    raw: bytes = field(repr=False, default=b"")

    @property
    def name(self) -> str:
        return M.NAMES.get(self.msg_type, f"0x{self.msg_type:02x}")


def open_port(port: str, baudrate: int = 115200, timeout: float = 0.05):  # -> serial.SerialBase
    """Open a pyserial port or URL exclusively, translating failures into LinkError."""
    import serial

    try:
        return serial.serial_for_url(port, baudrate=baudrate, timeout=timeout, exclusive=True)
    except ValueError as exc:  # unknown URL scheme, bad baud rate
        raise LinkError(f"cannot open '{port}': {exc}") from exc
    except serial.SerialException as exc:
        text = str(exc)
        err = getattr(exc, "errno", None)
        if err == errno.ENOENT or "No such file" in text:
            raise LinkError(
                f"no such port '{port}' (is the board connected? list ports with: python -m serial.tools.list_ports)"
            ) from exc
        if err in (errno.EAGAIN, errno.EBUSY) or "exclusively lock" in text or "busy" in text.lower():
            raise LinkError(
                f"port '{port}' is busy: another program has it open (a terminal, mpremote, another twinbot?)"
            ) from exc
        if err == errno.EACCES or "Permission denied" in text:
            raise LinkError(f"no permission to open '{port}' (add yourself to the 'dialout' group)") from exc
        raise LinkError(f"cannot open '{port}': {text}") from exc


IDLE_TIMEOUT_S = 0.2  # a partial frame older than this is abandoned: its sender died mid-frame


class SerialLink:
    """Protocol endpoint on an open port: send(), poll() and counters."""

    def __init__(self, port_obj, on_frame=None) -> None:
        self.port = port_obj
        self.encoder = FrameEncoder()
        self.decoder = FrameDecoder()
        self.on_frame = on_frame  # called with every Frame, rx and tx
        self.on_bytes: Callable[[bytes], None] | None = None  # called with every chunk read, before decoding
        self.t0 = time.monotonic()
        self.sent = 0
        self._buf = bytearray(4096)
        self._last_rx = 0.0  # when the last byte arrived (link time)

    @classmethod
    def open(cls, port: str, baudrate: int = 115200, on_frame=None) -> SerialLink:
        return cls(open_port(port, baudrate), on_frame)

    def close(self) -> None:
        self.port.close()

    def now(self) -> float:
        return time.monotonic() - self.t0

    def send(self, msg_type: int, fields: dict[str, object]) -> Frame:
        """Encode and write one message; returns it as a tx Frame."""
        payload = M.pack_payload(msg_type, fields)  # type: ignore[arg-type]
        seq = self.encoder.seq
        raw = self.encoder.encode(msg_type, payload)
        self.port.write(raw)
        self.sent += 1
        frame = Frame("tx", self.now(), msg_type, seq, dict(fields), raw)
        if self.on_frame:
            self.on_frame(frame)
        return frame

    def send_raw(self, data: bytes) -> None:
        """Write bytes as they are (for tests and fault injection)."""
        self.port.write(data)

    def poll(self, max_wait: float = 0.05) -> list[Frame]:
        """Read what has arrived (waiting at most max_wait) and decode it."""
        port = self.port
        n = port.in_waiting
        if n == 0:
            port.timeout = max_wait
            data = port.read(1)
            n = port.in_waiting
            if n:
                data += port.read(n)
        else:
            data = port.read(n)
        return self.feed(data)

    def feed(self, data: bytes) -> list[Frame]:
        frames = []
        dec = self.decoder
        i, end = 0, len(data)
        now = self.now()
        if end and dec.partial and now - self._last_rx > IDLE_TIMEOUT_S:
            dec.abandon_partial()  # stale: counted in 'abandoned'
        if end:
            self._last_rx = now
            if self.on_bytes:
                self.on_bytes(bytes(data))
        while i < end:
            j = dec.feed(data, i, end)
            if dec.ready:
                payload = bytes(dec.body[3 : 3 + dec.payload_len])
                frame = Frame("rx", now, dec.msg_type, dec.seq, M.unpack_payload(dec.msg_type, payload),
                              _reframe(dec))
                frames.append(frame)
                if self.on_frame:
                    self.on_frame(frame)
            i = j
        return frames

    def wait_for(self, msg_type: int, timeout: float) -> Frame | None:
        """Poll until a frame of msg_type arrives or timeout passes."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for frame in self.poll(min(0.05, max(0.0, deadline - time.monotonic()))):
                if frame.msg_type == msg_type:
                    return frame
        return None


def _reframe(dec: FrameDecoder) -> bytes:
    # The decoded body re-encoded is the frame exactly as it was on the wire
    # (COBS is canonical for bodies <= 254 bytes).
    from protocol.cobs import encode

    n = 3 + dec.payload_len + 2
    return b"\x00" + encode(bytes(dec.body[:n])) + b"\x00"
