"""Regenerate tests/data/protocol_golden.json, the protocol's golden vectors (protocol/SPEC.md).

    python -m tests.data.make_golden_vectors [OUTPUT]

The file freezes the wire format: for every message type field values (zeros, extremes,
seeded random) with the exact frame bytes, and streams mixing frames with garbage with the
decoder counters they must produce.  tests/test_golden_vectors.py checks it on CPython, under
MicroPython (tests/mp/golden_check.py), and that it equals what this deterministic script
writes.  Plain JSON, one case per line, so MicroPython reads it and diffs stay readable.
"""
from __future__ import annotations

import json
import random
import sys
from pathlib import Path

from protocol import cobs, crc16, framing, messages

OUTPUT = Path(__file__).resolve().with_name("protocol_golden.json")
SEED = 0x7B07
FORMAT_VERSION = 1

RANGES = {
    "B": (0, 0xFF), "b": (-0x80, 0x7F), "H": (0, 0xFFFF), "h": (-0x8000, 0x7FFF),
    "I": (0, 0xFFFFFFFF), "i": (-0x80000000, 0x7FFFFFFF),
}
MAX_TEXT = messages.MAX_PAYLOAD - 1  # LOG: level byte + text
COUNTERS = ("frames", "cobs_errors", "crc_errors", "version_errors", "unknown_types",
            "length_errors", "overflows", "abandoned", "seq_gaps", "frames_lost")


def _fields(msg_type: int, pick) -> dict:
    out: dict = {}
    for fname, code, count in messages._layout(msg_type):
        if count == 0:
            out[fname] = pick("s", 0)
        elif count == 1:
            out[fname] = pick(code, 0)
        else:
            out[fname] = [pick(code, k) for k in range(count)]
    return out


def _edge_cases(rng: random.Random) -> list[tuple[str, int, int, dict]]:
    """(name, type, seq, fields) for every type."""
    out = []
    for k, (msg_type, name, _layout) in enumerate(messages.LAYOUTS):
        texts = {
            "zeros": "", "minima": "a", "maxima": "~" * MAX_TEXT,
            "ff_heavy": "\u00ff" * (MAX_TEXT // 2),  # UTF-8 c3 bf, 248 bytes
            "zero_heavy": "\x00" * MAX_TEXT,  # 248 zero bytes: the COBS worst case
            "alternating": "\x00\x7f" * 20,
        }
        variants = {
            "zeros": lambda code, i: 0,
            "minima": lambda code, i: RANGES[code][0],
            "maxima": lambda code, i: RANGES[code][1],
            # every byte 0xFF (-1 for signed codes), but the last element of arrays 0xFE..
            "ff_heavy": lambda code, i: (-1 if RANGES[code][0] < 0 else RANGES[code][1]) - (i == 7),
            # one 0x01 byte per field, every other byte 0x00
            "zero_heavy": lambda code, i: 1 if i % 2 == 0 else 0,
            # alternating signs / bytes 0x00 0xFF 0x80 0x7F
            "alternating": lambda code, i: RANGES[code][i % 2] if RANGES[code][0] < 0
            else (0x80 if code == "B" else 0x8000 if code == "H" else 0x80000000) * (i % 2),
        }
        seqs = {"zeros": 0, "minima": 1, "maxima": 255, "ff_heavy": 254, "zero_heavy": 0,
                "alternating": (17 * k + 3) & 0xFF}
        for vname, fn in variants.items():
            def pick(code: str, i: int, fn=fn, vname=vname):
                return texts[vname] if code == "s" else fn(code, i)

            out.append(("{} {}".format(name, vname), msg_type, seqs[vname], _fields(msg_type, pick)))
        for r in range(3):
            def pick_random(code: str, i: int):
                if code == "s":
                    n = rng.choice((1, 5, 40, rng.randrange(MAX_TEXT + 1)))
                    return "".join(chr(rng.randrange(0x20, 0x7F)) for _ in range(n))
                return rng.randint(*RANGES[code])

            out.append(("{} random {}".format(name, r), msg_type, rng.randrange(256), _fields(msg_type, pick_random)))
    # A few texts worth pinning down on their own.
    for i, text in enumerate(("hello", "ambient 12 mV \u00e9\u00b0\u03a9", "x\n\ty\r", "\x01" * 248)):
        out.append(("LOG text {}".format(i), messages.LOG, 100 + i, {"level": i, "text": text}))
    return out


def _frame(msg_type: int, seq: int, fields: dict) -> bytes:
    enc = framing.FrameEncoder()
    enc.seq = seq
    return enc.encode(msg_type, messages.pack_payload(msg_type, fields))


def _raw_frame(version: int, msg_type: int, seq: int, payload: bytes, schema: int | None = None) -> bytes:
    """A frame with a correct CRC but any header (for version / type / length errors)."""
    body = bytes([version, msg_type, seq]) + payload
    crc = crc16.crc16(body)
    value = messages.SCHEMA[msg_type] if schema is None else schema
    crc = crc16.crc16_byte(crc16.crc16_byte(crc, value & 0xFF), value >> 8)
    return b"\x00" + cobs.encode(body + bytes([crc & 0xFF, crc >> 8])) + b"\x00"


def _flip(frame: bytes, index: int, mask: int) -> bytes:
    b = bytearray(frame)
    b[index] ^= mask
    return bytes(b)


def _sequence_streams(add, cmd, ack, log) -> None:  # type: ignore[no-untyped-def]
    """Streams about sequence numbers and frame boundaries: restarts, wraps, dead senders, long frames."""
    T = messages.TYPES
    hello = _frame(T["HELLO"], 0, {"protocol": 1, "fw_major": 0, "fw_minor": 3, "fw_patch": 0, "board": 2,
                                   "sensors": 8, "wheel_diameter_um": 42000, "wheel_base_um": 96000,
                                   "ticks_per_rev": 1200})
    add("junk without a delimiter costs no frame", [(b"\x05\x01\x02", "cobs"), (cmd(20, 1, 1), "COMMAND"),
                                                     (cmd(21)[:6], "a dead sender's half frame"),
                                                     (cmd(22, 2, 2), "COMMAND")],
        [("COMMAND", 20), ("COMMAND", 22)], cobs_errors=1, length_errors=1, seq_gaps=1, frames_lost=1)
    add("HELLO after a restart is no gap", [(ack(40), "ACK"), (ack(41), "ACK"), (hello, "HELLO"), (ack(1), "ACK")],
        [("ACK", 40), ("ACK", 41), ("HELLO", 0), ("ACK", 1)])
    add("sequence wraps", [(ack(254), "ACK"), (ack(255), "ACK"), (ack(0), "ACK"), (ack(2), "ACK")],
        [("ACK", 254), ("ACK", 255), ("ACK", 0), ("ACK", 2)], seq_gaps=1, frames_lost=1)
    add("longest frames back to back", [(log(10, "L" * MAX_TEXT), "LOG"), (log(11, "\x00" * MAX_TEXT), "LOG"),
                                        (log(12, ""), "LOG")],
        [("LOG", 10), ("LOG", 11), ("LOG", 12)])


def _streams(rng: random.Random) -> list[dict]:
    """Streams whose counters are known by construction (and checked against the decoder)."""
    T = messages.TYPES

    def cmd(seq: int, left: int = 0, right: int = 0) -> bytes:
        return _frame(T["COMMAND"], seq, {"mode": 2, "left": left, "right": right})

    def ack(seq: int) -> bytes:
        return _frame(T["ACK"], seq, {"ack_seq": seq, "ack_type": T["COMMAND"]})

    def log(seq: int, text: str) -> bytes:
        return _frame(T["LOG"], seq, {"level": 1, "text": text})

    streams = []

    def add(name: str, parts: list[tuple[bytes, str]], decoded: list[tuple[str, int]], **counters: int) -> None:
        data = b"".join(p for p, _ in parts)
        want = dict.fromkeys(COUNTERS, 0)
        want.update(counters)
        want["frames"] = len(decoded)
        streams.append({"name": name, "stream": data.hex(), "counters": want,
                        "decoded": [[n, s] for n, s in decoded]})

    add("garbage then frames", [(b"\x13\x37\xff\x00", "cobs"), (cmd(0, 100, -100), "COMMAND"),
                                 (ack(1), "ACK"), (log(2, "ok"), "LOG")],
        [("COMMAND", 0), ("ACK", 1), ("LOG", 2)], cobs_errors=1)
    noise = bytes(rng.randrange(1, 256) for _ in range(300))
    add("overflow then frame", [(noise + b"\x00", "overflow"), (cmd(9, -1, 1), "COMMAND")],
        [("COMMAND", 9)], overflows=1)
    add("255 bytes fit, 256 overflow",
        [(b"\xff" * 255 + b"\x00", "version"), (b"\xff" * 256 + b"\x00", "overflow"), (ack(0), "ACK")],
        [("ACK", 0)], version_errors=1, overflows=1)
    seqs = [s for s in range(10) if s not in (3, 4)]
    parts = []
    for s in seqs:
        f = cmd(s, s, -s)
        parts.append((_flip(f, 5, 0x10), "crc") if s == 7 else (f, "COMMAND"))
    add("dropped and corrupted", parts, [("COMMAND", s) for s in seqs if s != 7],
        crc_errors=1, seq_gaps=2, frames_lost=3)
    add("bad headers", [
        (_raw_frame(2, T["ACK"], 0, b"\x00\x07"), "version"),
        (_raw_frame(1, 0x7E, 1, b"\x01\x02", schema=0), "unknown type"),
        (b"\x00" + cobs.encode(b"\x01\x07\x02\x00") + b"\x00", "too short"),
        (_raw_frame(1, T["COMMAND"], 3, b"\x02\x00\x00\x00"), "COMMAND one byte short"),
        (_raw_frame(1, T["ACK"], 4, b"\x01\x02\x03"), "ACK one byte long"),
        (_raw_frame(1, T["ACK"], 5, b"\x05\x07", schema=messages.SCHEMA[T["NACK"]]), "wrong schema"),
        (b"\x00\x00\x00", "empty chunks"),
        (ack(6), "ACK"),
    ], [("ACK", 6)], version_errors=1, unknown_types=1, length_errors=3, crc_errors=1)
    _sequence_streams(add, cmd, ack, log)
    return streams


def _check_stream(s: dict) -> None:
    dec = framing.FrameDecoder()
    got = [[messages.NAMES[t], seq] for t, seq, _p in dec.decode_all(bytes.fromhex(s["stream"]))]
    if got != s["decoded"] or dec.stats() != s["counters"]:
        raise AssertionError("stream {!r}: decoder gives {} {}, expected {} {}".format(
            s["name"], got, dec.stats(), s["decoded"], s["counters"]))


def build() -> dict:
    """The golden document, deterministically."""
    rng = random.Random(SEED)
    cases = []
    for name, msg_type, seq, fields in _edge_cases(rng):
        cases.append({"name": name, "type": messages.NAMES[msg_type], "seq": seq, "fields": fields,
                      "frame": _frame(msg_type, seq, fields).hex()})
    streams = _streams(rng)
    for s in streams:
        _check_stream(s)
    return {"format": FORMAT_VERSION, "protocol_version": messages.PROTOCOL_VERSION,
            "generator": "tests/data/make_golden_vectors.py", "cases": cases, "streams": streams}


def render(doc: dict) -> str:
    """JSON text with one case / stream per line."""
    def one(obj: object) -> str:
        return json.dumps(obj, ensure_ascii=True, separators=(", ", ": "))

    head = ", ".join("{}: {}".format(json.dumps(k), one(doc[k])) for k in ("format", "protocol_version", "generator"))
    lines = ["{" + head + ","]
    for key, last in (("cases", False), ("streams", True)):
        lines.append(' "{}": ['.format(key))
        items = doc[key]
        for i, item in enumerate(items):
            lines.append("  " + one(item) + ("," if i + 1 < len(items) else ""))
        lines.append(" ]" + ("" if last else ","))
    lines.append("}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    out = Path(args[0]) if args else OUTPUT
    doc = build()
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render(doc), encoding="ascii")
    print("wrote {} cases and {} streams to {}".format(len(doc["cases"]), len(doc["streams"]), out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
