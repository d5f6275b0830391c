"""Unit tests of the protocol building blocks: CRC, COBS, payload layouts, framing size.

Each test checks one documented property of protocol/ against an outside
reference (the published CRC check value, the PyPI `cobs` package, struct's
ranges) or against the other code path (CPython fast vs MicroPython pure).
"""
from __future__ import annotations

import struct

import pytest
from cobs import cobs as ref
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import cobs, crc16, framing, messages

SETTINGS = settings(deadline=None, max_examples=250)

# (minimum, maximum) of every struct code the layouts use.
RANGES = {
    "B": (0, 0xFF), "b": (-0x80, 0x7F), "H": (0, 0xFFFF), "h": (-0x8000, 0x7FFF),
    "I": (0, 0xFFFFFFFF), "i": (-0x80000000, 0x7FFFFFFF),
}
FIXED_TYPES = [t for t, _n, _f in messages.LAYOUTS if not messages.VARIABLE[t]]
ALL_TYPES = [t for t, _n, _f in messages.LAYOUTS]


def _fields(msg_type: int, pick) -> dict:
    """Fields of msg_type with each integer chosen by pick(code, k)."""
    out: dict = {}
    for fname, code, count in messages._layout(msg_type):
        if count == 0:
            out[fname] = pick("s", 0)
        elif count == 1:
            out[fname] = pick(code, 0)
        else:
            out[fname] = tuple(pick(code, k) for k in range(count))
    return out


# --------------------------------------------------------------------- CRC


@pytest.mark.parametrize("fn", [crc16.crc16_update, crc16.crc16_update_pure], ids=["fast", "pure"])
def test_crc_check_value(fn) -> None:
    """Both CRC paths are CRC-16/MCRF4XX: check value 0x6F91 for b"123456789"."""
    assert fn(crc16.CRC_INIT, b"123456789", 0, 9) == 0x6F91
    assert fn(crc16.CRC_INIT, bytearray(b"xx123456789yy"), 2, 11) == 0x6F91
    assert crc16.crc16(b"123456789") == 0x6F91


def test_crc_empty_and_byte() -> None:
    """An empty range leaves the CRC alone; crc16_byte is the one-byte update."""
    for fn in (crc16.crc16_update, crc16.crc16_update_pure):
        assert fn(0x1234, b"abc", 1, 1) == 0x1234
    for crc in (0, 0xFFFF, 0x1234, 0x8001):
        for b in (0, 1, 0x80, 0xFF, 0x5A):
            assert crc16.crc16_byte(crc, b) == crc16.crc16_update_pure(crc, bytes([b]), 0, 1)


@SETTINGS
@given(st.binary(max_size=600), st.integers(0, 0xFFFF), st.data())
def test_crc_fast_equals_pure(data: bytes, init: int, draw) -> None:
    """The C-backed CRC (crc_hqx on bit-reversed bytes) equals the bitwise one on any range."""
    start = draw.draw(st.integers(0, len(data)))
    end = draw.draw(st.integers(start, len(data)))
    for buf in (data, bytearray(data)):
        assert crc16.crc16_update(init, buf, start, end) == crc16.crc16_update_pure(init, buf, start, end)


# -------------------------------------------------------------------- COBS


@SETTINGS
@given(st.binary(max_size=600))
def test_cobs_matches_reference_package(data: bytes) -> None:
    """encode/decode agree byte for byte with the PyPI `cobs` package, any length 0..600."""
    enc = cobs.encode(data)
    assert enc == ref.encode(data)
    assert 0 not in enc
    assert cobs.decode(enc) == data
    assert ref.decode(enc) == data


@pytest.mark.parametrize("n", [0, 1, 253, 254, 255, 507, 508, 509, 600])
@pytest.mark.parametrize("fill", [0x00, 0x01, 0xFF])
def test_cobs_block_boundaries(n: int, fill: int) -> None:
    """Runs of exactly 254 non-zero bytes (the 0xFF code) and of zeros match the reference."""
    data = bytes([fill]) * n
    assert cobs.encode(data) == ref.encode(data)
    assert cobs.decode(ref.encode(data)) == data


@SETTINGS
@given(st.binary(max_size=254))
def test_cobs_encoded_length_is_n_plus_one(data: bytes) -> None:
    """A block of at most 254 bytes grows by exactly one byte (so MAX_ENCODED = 255)."""
    assert len(cobs.encode(data)) == len(data) + 1
    dst = bytearray(framing.MAX_ENCODED)
    assert cobs.encode_into(data, len(data), dst, 0) == len(data) + 1


def _cobs_byte_loop(src: bytes, n: int, dst: bytearray, dpos: int) -> int:
    """COBS a byte at a time, the textbook loop: the reference for the firmware's run-at-a-time encoder."""
    code_pos, out, code = dpos, dpos + 1, 1
    for i in range(n):
        if src[i] == 0:
            dst[code_pos] = code
            code_pos, out, code = out, out + 1, 1
            continue
        dst[out] = src[i]
        out += 1
        code += 1
        if code == 0xFF:
            dst[code_pos] = code
            code_pos, code = out, 1
            if i + 1 == n:
                return out
            out += 1
    dst[code_pos] = code
    return out


@SETTINGS
@given(st.lists(st.sampled_from([0, 1, 0xFF]), max_size=40), st.integers(0, 600), st.integers(0, 3))
def test_cobs_by_runs_is_the_byte_loop(pattern: list[int], extra: int, dpos: int) -> None:
    """The firmware's COBS encoder (runs found with find()) writes the same bytes and ends at the same place
    as the byte loop, for any data: zeros anywhere, runs of 253, 254 and 255 non-zero bytes, a prefix of src."""
    runs = [b"\x00" if p == 0 else bytes([7]) * (253 + p % 3) if p == 0xFF else b"\x05" for p in pattern]
    data = (b"".join(runs) + bytes(range(1, 256)) * 3)[: len(b"".join(runs)) + extra]
    for n in {len(data), len(data) // 2, 0}:
        expected, got, fast = (bytearray(n + n // 254 + 8) for _ in range(3))
        end = _cobs_byte_loop(data, n, expected, dpos)
        assert cobs.encode_into_pure(bytearray(data), n, got, dpos) == end and got == expected
        assert cobs.encode_into(memoryview(data), n, fast, dpos) == end and fast == expected


def _both_decoders(src: bytes, start: int, end: int, cap: int) -> tuple[int, bytes, int, bytes]:
    d1 = bytearray(cap)
    d2 = bytearray(cap)
    m1 = cobs.decode_into(src, start, end, d1)
    m2 = cobs.decode_into_pure(src, start, end, d2)
    return m1, bytes(d1[: max(m1, 0)]), m2, bytes(d2[: max(m2, 0)])


@SETTINGS
@given(st.binary(max_size=300), st.integers(0, 8), st.integers(0, 8), st.integers(-3, 3))
def test_decode_into_fast_equals_pure_valid(data: bytes, pre: int, post: int, slack: int) -> None:
    """On valid COBS blocks (anywhere in a buffer, any destination size) fast == pure."""
    enc = cobs.encode(data)
    src = b"\x07" * pre + enc + b"\x09" * post
    cap = max(0, len(data) + slack)
    m1, out1, m2, out2 = _both_decoders(src, pre, pre + len(enc), cap)
    assert m1 == m2
    assert out1 == out2
    if slack >= 0:
        assert m1 == len(data) and out1 == data
    elif len(data) > cap:
        assert m1 == -1


@SETTINGS
@given(st.binary(min_size=0, max_size=300).map(lambda b: bytes(x or 1 for x in b)), st.integers(0, 320))
def test_decode_into_fast_equals_pure_random(src: bytes, cap: int) -> None:
    """On arbitrary zero-free input (mostly invalid) fast and pure return the same result."""
    m1, out1, m2, out2 = _both_decoders(src, 0, len(src), cap)
    assert m1 == m2
    assert out1 == out2


def test_decode_rejects_zero_and_overrun() -> None:
    """decode() refuses a block holding 0x00 or whose code byte runs past the end."""
    with pytest.raises(ValueError):
        cobs.decode(b"\x02\x00")
    with pytest.raises(ValueError):
        cobs.decode(b"\x05\x01\x02")
    assert cobs.decode_into_pure(b"\x05\x01\x02", 0, 3, bytearray(10)) == -1
    assert cobs.decode_into(b"\x05\x01\x02", 0, 3, bytearray(10)) == -1


# ---------------------------------------------------------------- payloads


@pytest.mark.parametrize("msg_type", ALL_TYPES, ids=[messages.NAMES[t] for t in ALL_TYPES])
@pytest.mark.parametrize("edge", ["zero", "min", "max", "minus_one"])
def test_pack_unpack_round_trip_edges(msg_type: int, edge: str) -> None:
    """Every layout round-trips at zero, the minimum, the maximum and -1/0xFF.. of each code."""

    def pick(code: str, k: int):
        if code == "s":
            return {"zero": "", "min": "", "max": "x" * (messages.MAX_PAYLOAD - 1), "minus_one": "\x7f"}[edge]
        lo, hi = RANGES[code]
        if edge == "zero":
            return 0
        if edge == "min":
            return lo
        if edge == "max":
            return hi
        return -1 if lo < 0 else hi  # all 0xFF bytes

    fields = _fields(msg_type, pick)
    payload = messages.pack_payload(msg_type, fields)
    size = messages.PAYLOAD_SIZE[msg_type]
    assert len(payload) >= size
    if edge == "minus_one":
        assert payload[:size] == b"\xff" * size
    if edge == "zero":
        assert payload[:size] == b"\x00" * size
    assert messages.unpack_payload(msg_type, payload) == fields


@SETTINGS
@given(st.sampled_from(ALL_TYPES), st.data())
def test_pack_unpack_round_trip_random(msg_type: int, data) -> None:
    """Random in-range values round-trip; the payload is struct.pack of FORMATS plus text."""

    def pick(code: str, k: int):
        if code == "s":
            return data.draw(st.text(max_size=60))
        lo, hi = RANGES[code]
        return data.draw(st.integers(lo, hi))

    fields = _fields(msg_type, pick)
    payload = messages.pack_payload(msg_type, fields)
    assert messages.unpack_payload(msg_type, payload) == fields
    flat: list = []
    for fname, _code, count in messages._layout(msg_type):
        if count == 1:
            flat.append(fields[fname])
        elif count > 1:
            flat.extend(fields[fname])
    text = fields.get("text", "").encode() if messages.VARIABLE[msg_type] else b""
    assert payload == struct.pack(messages.FORMATS[msg_type], *flat) + text


def _telemetry() -> dict:
    return _fields(messages.TELEMETRY, lambda code, k: 0 if code == "s" else 1)


def test_pack_error_names_array_element() -> None:
    """An out-of-range array element is reported as MESSAGE.field[index]."""
    f = _telemetry()
    f["ir_on"] = (0, 1, 2, 70000, 4, 5, 6, 7)
    with pytest.raises(ValueError, match=r"TELEMETRY\.ir_on\[3\]") as exc:
        messages.pack_payload(messages.TELEMETRY, f)
    assert "70000" in str(exc.value) and "0..65535" in str(exc.value)


def test_pack_error_names_scalar_field() -> None:
    """An out-of-range scalar is reported as MESSAGE.field with the code's range."""
    with pytest.raises(ValueError, match=r"COMMAND\.left = -40000 .*-32768\.\.32767"):
        messages.pack_payload(messages.COMMAND, {"mode": 0, "left": -40000, "right": 0})
    with pytest.raises(ValueError, match=r"PARAM_SET\.value"):
        messages.pack_payload(messages.PARAM_SET, {"param": 1, "value": 2**31})
    with pytest.raises(ValueError, match=r"HELLO\.board"):
        messages.pack_payload(messages.HELLO, {"protocol": 1, "fw_major": 0, "fw_minor": 0, "fw_patch": 0,
                                               "board": -1, "sensors": 8})


def test_pack_error_missing_field() -> None:
    """A missing field is named."""
    f = _telemetry()
    del f["vbat_mv"]
    with pytest.raises(ValueError, match=r"TELEMETRY: missing field 'vbat_mv'"):
        messages.pack_payload(messages.TELEMETRY, f)


def test_pack_error_unknown_field() -> None:
    """An extra, unknown field is named (not silently dropped)."""
    f = _telemetry()
    f["bogus"] = 3
    with pytest.raises(ValueError, match=r"TELEMETRY: unknown field\(s\) bogus"):
        messages.pack_payload(messages.TELEMETRY, f)


def test_pack_error_wrong_count() -> None:
    """An array with the wrong number of values, or a scalar for an array, names the field."""
    f = _telemetry()
    f["ir_amb"] = [1] * 7
    with pytest.raises(ValueError, match=r"TELEMETRY\.ir_amb: expected 8 values, got 7"):
        messages.pack_payload(messages.TELEMETRY, f)
    f["ir_amb"] = 5
    with pytest.raises(ValueError, match=r"TELEMETRY\.ir_amb: expected 8 values"):
        messages.pack_payload(messages.TELEMETRY, f)


def test_pack_error_float_for_int() -> None:
    """A float where an integer belongs is refused, scalar or array element."""
    with pytest.raises(ValueError, match=r"COMMAND\.mode: expected an integer"):
        messages.pack_payload(messages.COMMAND, {"mode": 1.0, "left": 0, "right": 0})
    f = _telemetry()
    f["ir_on"] = [0, 0, 1.5, 0, 0, 0, 0, 0]
    with pytest.raises(ValueError, match=r"TELEMETRY\.ir_on\[2\]"):
        messages.pack_payload(messages.TELEMETRY, f)


def test_pack_error_text() -> None:
    """LOG text must be text, and at most MAX_PAYLOAD - 1 bytes."""
    with pytest.raises(ValueError, match=r"LOG\.text"):
        messages.pack_payload(messages.LOG, {"level": 1, "text": 5})
    messages.pack_payload(messages.LOG, {"level": 1, "text": "a" * (messages.MAX_PAYLOAD - 1)})
    with pytest.raises(ValueError, match=r"LOG: payload of 250 bytes exceeds 249"):
        messages.pack_payload(messages.LOG, {"level": 1, "text": "a" * messages.MAX_PAYLOAD})


def test_unpack_wrong_size() -> None:
    """unpack_payload refuses a payload of the wrong size for a fixed type, or too short for LOG."""
    with pytest.raises(ValueError, match="COMMAND"):
        messages.unpack_payload(messages.COMMAND, b"\x00" * 4)
    with pytest.raises(ValueError, match="COMMAND"):
        messages.unpack_payload(messages.COMMAND, b"\x00" * 6)
    with pytest.raises(ValueError, match="LOG"):
        messages.unpack_payload(messages.LOG, b"")


# ------------------------------------------------------------------ schema


@pytest.mark.parametrize("layout", messages.LAYOUTS, ids=[n for _t, n, _f in messages.LAYOUTS])
def test_schema_value_is_crc_of_schema_text(layout) -> None:
    """SCHEMA[type] is the CRC-16 of schema_text (16 bits), as documented,
    and PAYLOAD_SIZE[type] is the struct size of the layout (the numbers the firmware uses
    agree with the layouts the host uses)."""
    msg_type, name, fields = layout
    text = messages.schema_text(name, fields)
    assert text.startswith(name + " ")
    crc = crc16.crc16_update_pure(crc16.CRC_INIT, text.encode(), 0, len(text.encode()))
    assert messages.SCHEMA[msg_type] == crc == messages.schema_value(name, fields)
    assert messages.PAYLOAD_SIZE[msg_type] == struct.calcsize(messages.FORMATS[msg_type])


@pytest.mark.parametrize("layout", messages.LAYOUTS, ids=[n for _t, n, _f in messages.LAYOUTS])
def test_schema_text_sees_every_change(layout) -> None:
    """Renaming a field, changing its struct code or its count changes the schema text."""
    _msg_type, name, fields = layout
    base = messages.schema_text(name, fields)
    seen = {base}
    for k, (fname, code, count) in enumerate(fields):
        variants = [(fname + "x", code, count), (fname, "q" if code != "q" else "Q", count),
                    (fname, code, count + 2)]
        for v in variants:
            changed = fields[:k] + (v,) + fields[k + 1:]
            text = messages.schema_text(name, changed)
            assert text != base, (name, v)
            seen.add(text)
    assert messages.schema_text(name + "2", fields) != base
    # Dropping or reordering fields changes it too.
    assert messages.schema_text(name, fields[:-1]) != base
    if len(fields) > 1:
        assert messages.schema_text(name, fields[::-1]) != base


def test_schema_values_are_distinct() -> None:
    """No two message types share a schema value (a layout cannot pass for another's)."""
    values = [messages.SCHEMA[t] for t in ALL_TYPES]
    assert len(set(values)) == len(values)
    assert all(v != 0 for v in values)


def test_renamed_layouts_change_the_schema_value() -> None:
    """None of 900 renamed variants of COMMAND's fields shares the schema value of COMMAND or of
    any other type (with an 8-bit schema byte, 2 of them collided with TELEMETRY's).  A random
    change escapes with probability 2**-16, the CRC-16 of the layout text."""
    _t, name, fields = next(lay for lay in messages.LAYOUTS if lay[1] == "COMMAND")
    base = messages.schema_value(name, fields)
    values = set()
    for k in range(900):
        renamed = tuple((f + str(k), c, n) if i == k % len(fields) else (f, c, n)
                        for i, (f, c, n) in enumerate(fields))
        values.add(messages.schema_value(name, renamed))
    assert base not in values
    assert not values & {messages.SCHEMA[t] for t in ALL_TYPES}


@pytest.mark.parametrize("msg_type", FIXED_TYPES, ids=[messages.NAMES[t] for t in FIXED_TYPES])
def test_other_schema_value_is_rejected(msg_type: int) -> None:
    """A frame built with a different schema value (other message definitions: every value one
    byte away, and every other type's) fails the CRC."""
    size = messages.PAYLOAD_SIZE[msg_type]
    body = bytearray([messages.PROTOCOL_VERSION, msg_type, 0]) + bytes(range(1, size + 1))
    own = messages.SCHEMA[msg_type]
    others = {(own & 0xFF00) | k for k in range(256)} | {(own & 0xFF) | (k << 8) for k in range(256)}
    others |= {messages.SCHEMA[t] for t in ALL_TYPES}
    for schema in sorted(others):
        crc = crc16.crc16_byte(crc16.crc16_byte(crc16.crc16(body), schema & 0xFF), schema >> 8)
        frame = b"\x00" + cobs.encode(body + bytes([crc & 0xFF, crc >> 8])) + b"\x00"
        dec = framing.FrameDecoder()
        got = dec.decode_all(frame)
        if schema == own:
            assert len(got) == 1
        else:
            assert got == [] and dec.crc_errors == 1


# ----------------------------------------------------------------- framing


@pytest.mark.parametrize("msg_type", FIXED_TYPES, ids=[messages.NAMES[t] for t in FIXED_TYPES])
@pytest.mark.parametrize("fill", [0x00, 0x5A, 0xFF])
def test_frame_overhead_fixed_types(msg_type: int, fill: int) -> None:
    """Every fixed-size frame is exactly payload + OVERHEAD (8) bytes, whatever the bytes,
    and begins and ends with 0x00 (nothing before it can spoil it)."""
    assert framing.OVERHEAD == 8
    size = messages.PAYLOAD_SIZE[msg_type]
    frame = framing.FrameEncoder().encode(msg_type, bytes([fill]) * size)
    assert len(frame) == size + framing.OVERHEAD
    assert frame[0] == 0 and frame[-1] == 0 and 0 not in frame[1:-1]


def test_frame_overhead_log_all_lengths() -> None:
    """LOG frames of every text length 0..248 are payload + 8 bytes; the longest is 257 bytes."""
    enc = framing.FrameEncoder()
    for n in range(messages.MAX_PAYLOAD):
        frame = enc.encode(messages.LOG, b"\x02" + b"\xff" * n)
        assert len(frame) == 1 + n + framing.OVERHEAD
    assert len(frame) == framing.MAX_ENCODED + 2 == framing.MAX_FRAME
    with pytest.raises(ValueError):
        enc.encode(messages.LOG, b"\x02" + b"a" * messages.MAX_PAYLOAD)


def test_encoder_sequence_wraps() -> None:
    """The sequence byte counts 0..255 and wraps to 0."""
    enc = framing.FrameEncoder()
    dec = framing.FrameDecoder()
    seqs = []
    for _ in range(300):
        for _t, s, _p in dec.decode_all(enc.encode(messages.PARAM_GET, b"\x01")):
            seqs.append(s)
    assert seqs == [k & 0xFF for k in range(300)]
    assert dec.seq_gaps == 0 and dec.frames_lost == 0


# ------------------------------------------------------------------ fields


@pytest.mark.parametrize("value", [0, 1, -1, 255, 256, -256, 0x7FFFFFFF, -0x80000000, 123456789, -987654321])
def test_field_readers_match_struct(value: int) -> None:
    """protocol.fields reads what struct packs, at any offset, signs included; a 32-bit field is read
    saturated (read_i31) or modulo 2**30 (read_u30, read_wrap30), never past the RP2040's small ints."""
    from protocol import fields

    buf = bytearray(3) + struct.pack("<i", value) + bytearray(2)
    assert fields.read_i31(buf, 3) == max(-2 ** 30, min(2 ** 30 - 1, value))
    assert fields.read_u30(buf, 3) == value % 2 ** 30
    assert fields.read_wrap30(buf, 3) == (value + 2 ** 29) % 2 ** 30 - 2 ** 29
    v16 = value & 0xFFFF
    buf16 = bytearray(1) + struct.pack("<H", v16)
    assert fields.read_u16(buf16, 1) == v16
    assert fields.read_i16(buf16, 1) == struct.unpack("<h", struct.pack("<H", v16))[0]


def test_wire_parameter_limits_match_messages() -> None:
    """The firmware's flat PARAM_LIMITS (min, max, default at 3p..3p+2) and the hosts'
    messages.PARAMS agree, id by id, and id 0 does not exist."""
    from protocol import wire

    limits = list(wire.PARAM_LIMITS)
    assert len(limits) == 3 * (len(messages.PARAMS) + 1) and limits[:3] == [0, 0, 0]
    for pid, _name, lo, hi, default, _unit in messages.PARAMS:
        assert limits[3 * pid : 3 * pid + 3] == [lo, hi, default], pid
