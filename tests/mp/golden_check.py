"""Golden vectors under MicroPython: micropython tests/mp/golden_check.py tests/data/protocol_golden.json

Encodes every case the firmware way (struct.pack_into into enc.body at
offset 3, then finish), compares the frame byte for byte, decodes it with
FrameDecoder and compares the fields, then replays the streams and compares
the decoder counters.  Prints 'golden: N cases ok'; exits 1 naming the first
case that differs.  Only MicroPython built-ins: json, binascii, struct, sys.
"""
import json
import struct
import sys
from binascii import unhexlify

from protocol import framing, messages


def fail(msg):
    print("golden: FAIL " + msg)
    sys.exit(1)


def flatten(msg_type, fields):
    """Fields in layout order, arrays flattened; (values, text bytes)."""
    values = []
    text = b""
    for fname, _code, count in messages._layout(msg_type):
        v = fields[fname]
        if count == 0:
            text = v.encode()
        elif count == 1:
            values.append(v)
        else:
            if len(v) != count:
                fail("field {} has {} values, expected {}".format(fname, len(v), count))
            values.extend(v)
    return values, text


def check_case(case, enc):
    name = case["name"]
    msg_type = messages.TYPES[case["type"]]
    values, text = flatten(msg_type, case["fields"])
    fmt = messages.FORMATS[msg_type]
    size = messages.PAYLOAD_SIZE[msg_type]
    enc.seq = case["seq"]
    struct.pack_into(fmt, enc.body, 3, *values)
    for k in range(len(text)):
        enc.body[3 + size + k] = text[k]
    n = enc.finish(msg_type, size + len(text))
    want = unhexlify(case["frame"])
    got = bytes(enc.view(n))
    if got != want:
        fail("case {!r}: encoded {} expected {}".format(name, got, want))

    dec = framing.FrameDecoder()
    i = dec.feed(want, 0, len(want))
    if not dec.ready or i != len(want):
        fail("case {!r}: frame not decoded ({})".format(name, dec.stats()))
    if dec.msg_type != msg_type or dec.seq != case["seq"] or dec.payload_len != size + len(text):
        fail("case {!r}: header type {} seq {} len {}".format(name, dec.msg_type, dec.seq, dec.payload_len))
    back = struct.unpack_from(fmt, dec.body, 3)
    if list(back) != values:
        fail("case {!r}: decoded {} expected {}".format(name, back, values))
    got_text = bytes(dec.body[3 + size : 3 + dec.payload_len])
    if got_text != text:
        fail("case {!r}: decoded text {} expected {}".format(name, got_text, text))


def check_stream(s):
    data = unhexlify(s["stream"])
    dec = framing.FrameDecoder()
    decoded = []
    i = 0
    while i < len(data):
        i = dec.feed(data, i, len(data))
        if dec.ready:
            decoded.append([messages.NAMES[dec.msg_type], dec.seq])
    if decoded != s["decoded"]:
        fail("stream {!r}: decoded {} expected {}".format(s["name"], decoded, s["decoded"]))
    stats = dec.stats()
    for key in s["counters"]:
        if stats[key] != s["counters"][key]:
            fail("stream {!r}: {} = {} expected {}".format(s["name"], key, stats[key], s["counters"][key]))
    # Byte by byte must give the same result.
    dec = framing.FrameDecoder()
    n = 0
    for k in range(len(data)):
        dec.feed(data, k, k + 1)
        if dec.ready:
            n += 1
    if n != len(s["decoded"]) or dec.stats() != stats:
        fail("stream {!r}: byte-by-byte feed differs".format(s["name"]))


def main(path):
    with open(path) as f:
        doc = json.load(f)
    if doc["protocol_version"] != messages.PROTOCOL_VERSION:
        fail("file is for protocol version {}".format(doc["protocol_version"]))
    enc = framing.FrameEncoder()
    n = 0
    for case in doc["cases"]:
        check_case(case, enc)
        n += 1
    for s in doc["streams"]:
        check_stream(s)
    if n == 0 or not doc["streams"]:
        fail("no cases")
    print("golden: {} cases ok".format(n))


if len(sys.argv) < 2:
    fail("usage: golden_check.py protocol_golden.json")
main(sys.argv[1])
