"""Frames on the wire: 0x00 + COBS(version | type | seq | payload | CRC16-LE) + 0x00 (protocol/SPEC.md).

The leading 0x00 ends whatever junk came before (REPL text, a dead sender's half
frame).  FrameEncoder and FrameDecoder own preallocated buffers, so the firmware's send
and receive paths allocate nothing once built.  The decoder never raises on wire data:
every bad frame is dropped at the next 0x00 and counted by reason, and sequence gaps are
counted (a HELLO starts the count afresh: the peer may have restarted).
"""
from protocol.cobs import _copy_bytes, decode_into, encode_into
from protocol.compat import const
from protocol.crc16 import CRC_INIT, crc16_byte, crc16_update
from protocol.wire import HELLO, N_TYPES, PAYLOAD_SIZE, PROTOCOL_VERSION, SCHEMA, UNKNOWN, VARIABLE_TYPE

HEADER_SIZE = const(3)  # version, type, seq
CRC_SIZE = const(2)
MAX_BODY = const(254)  # so that COBS adds exactly one byte
MAX_ENCODED = const(255)  # COBS(body) without the delimiters
MAX_FRAME = const(257)  # leading 0x00 + COBS(body) + trailing 0x00
_SATURATED = const(0x3FFFFFFF)  # counters stop at 2**30 - 1
OVERHEAD = const(8)  # header + CRC + COBS code byte + two delimiters


class FrameEncoder:
    """Builds frames; numbers them with a wrapping 8-bit sequence.

    Firmware use, allocation-free: struct.pack_into(fmt, enc.body, 3, ...),
    then n = enc.finish(msg_type, payload_len) and write the first n bytes
    of enc.frame (MicroPython streams take `write(buf, n)` without
    allocating).  Host use: enc.encode(msg_type, payload_bytes) -> bytes.
    """

    def __init__(self) -> None:
        self.seq = 0
        self.body = bytearray(MAX_BODY)
        self.frame = bytearray(MAX_FRAME)
        self._views: dict[int, memoryview] | None = None  # frame length -> view (host and test use)

    def finish(self, msg_type: int, payload_len: int) -> int:
        """Frame the payload already in body[3:]; return the frame length."""
        body = self.body
        body[0] = PROTOCOL_VERSION
        body[1] = msg_type
        body[2] = self.seq
        self.seq = (self.seq + 1) & 0xFF
        end = HEADER_SIZE + payload_len
        crc = _crc(body, end, msg_type)
        body[end] = crc & 0xFF
        body[end + 1] = crc >> 8
        frame = self.frame
        frame[0] = 0
        n = encode_into(body, end + CRC_SIZE, frame, 1)
        frame[n] = 0
        return n + 1

    def view(self, n: int) -> memoryview:
        """A memoryview of the first n frame bytes, cached per length.

        For hosts and tests: the first call for a length allocates a view,
        so the firmware writes (enc.frame, n) instead."""
        if self._views is None:
            self._views = {}
        v = self._views.get(n)
        if v is None:
            v = memoryview(self.frame)[:n]
            self._views[n] = v
        return v

    def encode(self, msg_type: int, payload: bytes | bytearray) -> bytes:
        """Host convenience: one complete frame as bytes."""
        n = len(payload)
        if n > MAX_BODY - HEADER_SIZE - CRC_SIZE:
            raise ValueError("payload of {} bytes exceeds {}".format(n, MAX_BODY - HEADER_SIZE - CRC_SIZE))
        _copy_bytes(self.body, HEADER_SIZE, payload, 0, n)
        m = self.finish(msg_type, n)
        return bytes(self.frame[:m])


def _crc(body: bytearray, end: int, msg_type: int) -> int:
    """CRC-16 of body[:end], then of the type's 16-bit schema value, low byte first."""
    crc = crc16_update(CRC_INIT, body, 0, end)
    schema = SCHEMA[msg_type]
    crc = crc16_byte(crc, schema & 0xFF)
    return crc16_byte(crc, schema >> 8)



def _count_up(n: int, k: int) -> int:
    """n + k for a counter that saturates at 2**30 - 1 instead of leaving the RP2040's small ints
    (tests/mp/counters_check.py)."""
    return n + k if n < _SATURATED - k else _SATURATED


class FrameDecoder:
    """Streaming decoder with a bounded buffer; never raises on wire data.

    feed(data, start, end) consumes bytes until one valid frame completes
    (then ready is True and msg_type, seq, payload_len describe it, the
    payload being body[3:3 + payload_len]) or the data runs out; it returns
    the index of the first byte not consumed.  data: bytes or bytearray.
    """

    def __init__(self) -> None:
        self._raw = bytearray(MAX_ENCODED)
        self._n = 0
        self._overflow = False
        self.body = bytearray(MAX_BODY)
        self.ready = False
        self.msg_type = 0
        self.seq = 0
        self.payload_len = 0
        self._last_seq = -1
        self.frames = 0  # valid frames delivered
        self.cobs_errors = 0
        self.crc_errors = 0
        self.version_errors = 0
        self.unknown_types = 0
        self.length_errors = 0  # too short, or wrong size for the type
        self.overflows = 0  # more than 255 bytes before a 0x00
        self.abandoned = 0  # unfinished frames dropped by abandon_partial()
        self.seq_gaps = 0  # times the sequence jumped
        self.frames_lost = 0  # frames missing according to the sequence

    def reset_sequence(self) -> None:
        """Forget the last sequence number (e.g. after the peer restarted)."""
        self._last_seq = -1

    def abandon_partial(self) -> None:
        """Drop an unfinished frame (its sender went quiet); counted in `abandoned`."""
        if self._n or self._overflow:
            self.abandoned = _count_up(self.abandoned, 1)
        self._n = 0
        self._overflow = False

    @property
    def partial(self) -> bool:
        """True while an unfinished frame (or an overflow) is held."""
        return self._n > 0 or self._overflow

    @property
    def errors(self) -> int:
        return (self.cobs_errors + self.crc_errors + self.version_errors + self.unknown_types
                + self.length_errors + self.overflows + self.abandoned)

    def feed(self, data: bytes | bytearray, start: int = 0, end: int = -1) -> int:
        if end < 0:
            end = len(data)
        self.ready = False
        raw = self._raw
        n = self._n
        i = start
        while i < end:
            j = data.find(b"\x00", i, end)
            stop = end if j < 0 else j
            take = stop - i
            if take and not self._overflow:
                if n + take > MAX_ENCODED:
                    self._overflow = True
                else:
                    _copy_bytes(raw, n, data, i, take)
                    n += take
            if j < 0:
                i = end
                break
            i = j + 1
            if self._overflow:
                self._overflow = False
                self.overflows = _count_up(self.overflows, 1)
                n = 0
            elif n:
                ok = self._finish(n)
                n = 0
                if ok:
                    self._n = 0
                    return i
        self._n = n
        return i

    def _finish(self, n: int) -> bool:
        body = self.body
        m = decode_into(self._raw, 0, n, body)
        if m < 0:
            self.cobs_errors = _count_up(self.cobs_errors, 1)
            return False
        if m < HEADER_SIZE + CRC_SIZE:
            self.length_errors = _count_up(self.length_errors, 1)
            return False
        if body[0] != PROTOCOL_VERSION:
            self.version_errors = _count_up(self.version_errors, 1)
            return False
        msg_type = body[1]
        size = PAYLOAD_SIZE[msg_type] if msg_type < N_TYPES else UNKNOWN
        if size == UNKNOWN:
            self.unknown_types = _count_up(self.unknown_types, 1)
            return False
        plen = m - HEADER_SIZE - CRC_SIZE
        if plen != size and not (msg_type == VARIABLE_TYPE and plen > size):
            self.length_errors = _count_up(self.length_errors, 1)
            return False
        if _crc(body, m - CRC_SIZE, msg_type) != body[m - 2] | (body[m - 1] << 8):
            self.crc_errors = _count_up(self.crc_errors, 1)
            return False
        seq = body[2]
        if self._last_seq >= 0 and msg_type != HELLO:  # a HELLO may follow a restart
            gap = (seq - self._last_seq - 1) & 0xFF
            if gap:
                self.seq_gaps = _count_up(self.seq_gaps, 1)
                self.frames_lost = _count_up(self.frames_lost, gap)
        self._last_seq = seq
        self.msg_type = msg_type
        self.seq = seq
        self.payload_len = plen
        self.frames = _count_up(self.frames, 1)
        self.ready = True
        return True

    def stats(self) -> dict[str, int]:
        return {
            "frames": self.frames, "cobs_errors": self.cobs_errors, "crc_errors": self.crc_errors,
            "version_errors": self.version_errors, "unknown_types": self.unknown_types,
            "length_errors": self.length_errors, "overflows": self.overflows, "abandoned": self.abandoned,
            "seq_gaps": self.seq_gaps, "frames_lost": self.frames_lost,
        }

    def decode_all(self, data: bytes | bytearray) -> list[tuple[int, int, bytes]]:
        """Host convenience: every valid frame in data as (type, seq, payload bytes)."""
        out: list[tuple[int, int, bytes]] = []
        i = 0
        end = len(data)
        while i < end:
            i = self.feed(data, i, end)
            if self.ready:
                out.append((self.msg_type, self.seq, bytes(self.body[HEADER_SIZE : HEADER_SIZE + self.payload_len])))
        return out
