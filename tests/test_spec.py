"""SPEC.md says what the code does: layouts, schema bytes, parameters, example."""
from __future__ import annotations

import re
from pathlib import Path

from protocol import messages as M
from protocol.framing import FrameEncoder, OVERHEAD

SPEC = (Path(__file__).resolve().parent.parent / "protocol" / "SPEC.md").read_text()


def section(title: str) -> str:
    start = SPEC.index(title)
    nxt = SPEC.find("\n### ", start + 1)
    return SPEC[start: nxt if nxt > 0 else None]


def table_rows(text: str) -> list[list[str]]:
    rows = []
    for line in text.splitlines():
        if line.startswith("|") and not line.startswith("|---"):
            rows.append([c.strip() for c in line.strip("|").split("|")])
    return rows[1:]  # without the header


def test_message_table_matches_code():
    rows = {r[1]: r for r in table_rows(section("| type | name |"))}
    for msg_type, name, _fields in M.LAYOUTS:
        row = rows[name]
        assert int(row[0], 16) == msg_type
        assert row[2].split()[0] == str(M.PAYLOAD_SIZE[msg_type])
        assert int(row[3], 16) == M.SCHEMA[msg_type], name


def test_every_layout_is_documented_field_by_field():
    codes = {"B": 1, "b": 1, "H": 2, "h": 2, "I": 4, "i": 4}
    for msg_type, name, fields in M.LAYOUTS:
        title = next(t for t in re.findall(r"^### .*$", SPEC, re.M) if re.search(rf"\b{name}\b \(0x", t))
        rows = [r for r in table_rows(section(title)) if r[0].isdigit()]
        documented = {r[1]: (int(r[0]), r[2]) for r in rows}
        offset = 0
        for fname, code, count in fields:
            assert fname in documented, f"{name}.{fname} missing from SPEC.md"
            doc_offset, doc_type = documented[fname]
            assert doc_offset == offset, f"{name}.{fname}: SPEC says offset {doc_offset}, code has {offset}"
            if count:
                assert doc_type == (f"{code}[{count}]" if count > 1 else code), f"{name}.{fname}"
                offset += codes[code] * count


def test_parameter_table_matches_code():
    rows = table_rows(section("| id | name | range |"))
    assert [(int(r[0]), r[1], r[2], int(r[3])) for r in rows] == [
        (p[0], p[1], f"{p[2]}..{p[3]}", p[4]) for p in M.PARAMS]


def test_worked_example_and_overhead():
    enc = FrameEncoder()
    frame = enc.encode(M.COMMAND, M.pack_payload(M.COMMAND, {"mode": M.MODE_HOST, "left": -300, "right": 250}))
    assert "wire              " + frame.hex(" ") in SPEC
    assert OVERHEAD == 8 and "Framing adds 8 bytes" in SPEC
