"""Golden vectors (tests/data/protocol_golden.json) pin the wire format on both interpreters.

The frames are checked against an independent reference too (PyPI `cobs`, a
CRC-16/MCRF4XX written here from its textbook definition), so the file is not
only a snapshot of whatever protocol/ happens to do.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from cobs import cobs as ref

from protocol import framing, messages
from tests.data import make_golden_vectors
from host_sim.board.micropython_runner import run_micropython

HERE = Path(__file__).resolve().parent
GOLDEN = HERE / "data" / "protocol_golden.json"
CHECKER = HERE / "mp" / "golden_check.py"
DOC = json.loads(GOLDEN.read_text())
CASES = DOC["cases"]
STREAMS = DOC["streams"]


def ref_crc(data: bytes) -> int:
    """CRC-16/MCRF4XX by its definition: reflected poly 0x8408, init 0xFFFF, no xorout."""
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
    return crc


def _as_struct(fields: dict) -> dict:
    return {k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()}


def test_file_is_what_the_generator_writes() -> None:
    """The checked-in file equals tests/data/make_golden_vectors.py's output now (regenerate with
    `python -m tests.data.make_golden_vectors` after a deliberate protocol change)."""
    assert GOLDEN.read_text() == make_golden_vectors.render(make_golden_vectors.build())


def test_coverage() -> None:
    """Every message type, seq 0 and 255, empty and 248-byte LOG text, 60..120 cases."""
    assert 60 <= len(CASES) <= 120
    assert {c["type"] for c in CASES} == set(messages.TYPES)
    assert {0, 255} <= {c["seq"] for c in CASES}
    texts = [len(c["fields"]["text"].encode()) for c in CASES if c["type"] == "LOG"]
    assert 0 in texts and messages.MAX_PAYLOAD - 1 in texts
    frames = [bytes.fromhex(c["frame"]) for c in CASES]
    assert max(len(f) for f in frames) == framing.MAX_FRAME
    assert len({c["name"] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c["name"] for c in CASES])
def test_case_encodes_and_decodes(case: dict) -> None:
    """Encoding the fields with seq set gives exactly the frame; decoding gives the fields back;
    the frame agrees with the reference COBS and CRC."""
    msg_type = messages.TYPES[case["type"]]
    frame = bytes.fromhex(case["frame"])
    enc = framing.FrameEncoder()
    enc.seq = case["seq"]
    assert enc.encode(msg_type, messages.pack_payload(msg_type, case["fields"])) == frame
    assert enc.seq == (case["seq"] + 1) & 0xFF

    dec = framing.FrameDecoder()
    [(t, seq, payload)] = dec.decode_all(frame)
    assert (t, seq) == (msg_type, case["seq"])
    assert messages.unpack_payload(msg_type, payload) == _as_struct(case["fields"])

    assert frame[0] == 0 and frame[-1] == 0
    body = ref.decode(frame[1:-1])
    assert body[:3] == bytes([messages.PROTOCOL_VERSION, msg_type, case["seq"]])
    schema = messages.SCHEMA[msg_type]
    crc = ref_crc(body[:-2] + bytes([schema & 0xFF, schema >> 8]))
    assert body[-2:] == bytes([crc & 0xFF, crc >> 8])


@pytest.mark.parametrize("stream", STREAMS, ids=[s["name"] for s in STREAMS])
def test_stream_counters(stream: dict) -> None:
    """Each stream decodes to the listed frames with exactly the listed counters,
    whether fed at once or byte by byte."""
    data = bytes.fromhex(stream["stream"])
    dec = framing.FrameDecoder()
    got = [[messages.NAMES[t], s] for t, s, _p in dec.decode_all(data)]
    assert got == stream["decoded"]
    assert dec.stats() == stream["counters"]
    dec = framing.FrameDecoder()
    for k in range(len(data)):
        dec.feed(data, k, k + 1)
    assert dec.stats() == stream["counters"]


def test_micropython_golden() -> None:
    """The real MicroPython encodes every case byte for byte (struct.pack_into + finish),
    decodes the fields back and reproduces the stream counters."""
    r = run_micropython(CHECKER, str(GOLDEN), timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert re.fullmatch(r"golden: (\d+) cases ok\n", r.stdout), r.stdout
    assert int(r.stdout.split()[1]) == len(CASES)


def test_micropython_golden_detects_mismatch(tmp_path: Path) -> None:
    """The MicroPython checker fails, naming the case, when one frame byte is wrong."""
    doc = json.loads(GOLDEN.read_text())
    case = doc["cases"][17]
    frame = bytearray.fromhex(case["frame"])
    frame[4] ^= 0x01 if frame[4] != 1 else 0x02
    case["frame"] = frame.hex()
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    r = run_micropython(CHECKER, str(bad), timeout=60)
    assert r.returncode == 1
    assert case["name"] in r.stdout
