"""Allocation check under MicroPython: micropython [-X heapsize=64k] tests/mp/alloc_check.py

Once FrameEncoder / FrameDecoder exist and every path has run once, receiving and sending
must not touch the heap: the hot loops run inside micropython.heap_lock(), then again with
the GC disabled, comparing gc.mem_alloc().  Everything runs inside functions (a new module
global would allocate).  Prints 'alloc: ok' last; exits 1 on any allocation or wrong result.
tests/test_micropython_alloc.py runs it from source and compiled, in the default and a 64 kB heap.
"""
import gc
import struct
import sys

import micropython

from protocol import framing, wire  # what the firmware imports (not the host-side messages)

TELEMETRY = wire.TELEMETRY
COMMAND = wire.COMMAND
TELEMETRY_FMT = "<IBHii8H8HhhHhhiiiB"  # as firmware/robot.py; checked against wire.PAYLOAD_SIZE
CHUNKS = (1, 2, 3, 5, 8, 13, 64, 100, 255, 256, 300, 701)
PHASES = ("none", "byte by byte", "chunks", "encode", "probe")
SENT = 300
STREAM_CAP = 6144


def fail(msg):
    print("alloc: FAIL " + msg)
    sys.exit(1)


def build_stream(stream):
    """Fill stream with frames, garbage, corrupted and truncated frames, overflows; return
    its used length (setup, may allocate; parts are copied in so a small heap suffices)."""
    enc = framing.FrameEncoder()
    n = 0
    x = 12345
    for r in range(24):
        parts = []
        parts.append(enc.encode(COMMAND, struct.pack("<Bhh", 2, r * 7, -r)))
        tele = enc.encode(TELEMETRY, bytes((r + k) & 0xFF for k in range(wire.PAYLOAD_SIZE[TELEMETRY])))
        parts.append(tele)
        kind = r % 5
        if kind == 0:  # garbage, zeros included
            g = bytearray(37)
            for k in range(37):
                x = (x * 1103515245 + 12345) & 0x7FFFFFFF
                g[k] = (x >> 16) & 0xFF
            parts.append(bytes(g) + b"\x00")
        elif kind == 1:  # one bit flipped
            b = bytearray(tele)
            b[r % 50 + 1] ^= 0x04
            if b[r % 50 + 1] == 0:
                b[r % 50 + 1] = 0x55
            parts.append(bytes(b))
        elif kind == 2:  # overflow: a long run without 0x00
            parts.append(b"\x5a" * (256 + r * 3) + b"\x00")
        elif kind == 3:  # truncated
            parts.append(tele[: 10 + r] + b"\x00")
        else:  # a LOG and empty chunks
            parts.append(enc.encode(wire.LOG, b"\x01" + b"x" * r) + b"\x00\x00")
        for p in parts:
            for k in range(len(p)):
                stream[n + k] = p[k]
            n += len(p)
    return n


def receive(dec_bytes, dec_chunks, stream, n, result):
    """Feed the stream byte by byte into one decoder and in chunks into another."""
    result[0] = 1
    frames = 0
    for i in range(n):
        dec_bytes.feed(stream, i, i + 1)
        if dec_bytes.ready:
            frames += 1
    result[1] = frames
    result[0] = 2
    frames = 0
    i = 0
    k = 0
    nchunks = len(CHUNKS)
    while i < n:
        end = i + CHUNKS[k]
        if end > n:
            end = n
        while i < end:
            i = dec_chunks.feed(stream, i, end)
            if dec_chunks.ready:
                frames += 1
        k += 1
        if k == nchunks:
            k = 0
    result[2] = frames


def send(enc, dec, rx, count, result):
    """Encode TELEMETRY frames the firmware way and decode each one."""
    result[0] = 3
    size = wire.PAYLOAD_SIZE[TELEMETRY]
    fmt = TELEMETRY_FMT
    body = enc.body
    got = 0
    for s in range(count):
        struct.pack_into(fmt, body, 3, s * 40, 1, 0x0004, s, -s,
                         s, 1, 2, 3, 4, 5, 6, 65535, 0, 9, 10, 11, 12, 13, 14, s,
                         -s, s, 7400, s, -s, s * 1000, -s * 1000, s * 4000, 60)
        m = enc.finish(TELEMETRY, size)
        v = enc.frame  # the firmware writes (frame, m): no view is made
        for k in range(m):  # the "UART"
            rx[k] = v[k]
        dec.feed(rx, 0, m)
        if dec.ready and dec.msg_type == TELEMETRY and dec.payload_len == size:
            got += 1
    result[3] = got


def locked(dec_bytes, dec_chunks, enc, dec_tx, stream, n, rx, result):
    """Both hot paths with the heap locked; result[0] says which phase allocated."""
    micropython.heap_lock()
    try:
        receive(dec_bytes, dec_chunks, stream, n, result)
        send(enc, dec_tx, rx, SENT, result)
        result[0] = 0
    except MemoryError:
        pass  # result[0] still names the phase
    finally:
        micropython.heap_unlock()


def probe(result):
    """The harness catches an allocation (else a clean result would prove nothing)."""
    micropython.heap_lock()
    try:
        result[0] = 4
        result[4] = len(bytearray(8))
        result[0] = 0
    except MemoryError:
        pass
    finally:
        micropython.heap_unlock()


def measured(dec_bytes, dec_chunks, enc, dec_tx, stream, n, rx, result, alloc):
    """The same work with the GC off; alloc gets gc.mem_alloc() before and after."""
    gc.collect()
    gc.disable()
    alloc[0] = gc.mem_alloc()
    receive(dec_bytes, dec_chunks, stream, n, result)
    send(enc, dec_tx, rx, SENT, result)
    alloc[1] = gc.mem_alloc()
    gc.enable()


def warm_up(enc, decoders, stream, n, rx):
    """Run every path once: each decoder over frames and every kind of error,
    pack_into + finish + view (its memoryview is cached per length)."""
    for dec in decoders:
        i = 0
        while i < n:
            i = dec.feed(stream, i, n)
    res = [0, 0, 0, 0, 0]
    send(enc, decoders[2], rx, 2, res)


def delta(after, before):
    out = {}
    for key in after:
        out[key] = after[key] - before[key]
    return out


def check_counters(decs, before, want, want_frames, result, what):
    if result[1] != want_frames or result[2] != want_frames:
        fail("{}: frames {} / {} expected {}".format(what, result[1], result[2], want_frames))
    for k in (0, 1):
        d = delta(decs[k].stats(), before[k])
        if d != want:
            fail("{}: counters {} expected {}".format(what, d, want))
    d = delta(decs[2].stats(), before[2])
    if result[3] != SENT or d["frames"] != SENT or d["seq_gaps"] or d["frames"] != decs[2].frames - before[2]["frames"]:
        fail("{}: sent {} received {} ({})".format(what, SENT, result[3], d))
    for key in d:
        if key != "frames" and d[key]:
            fail("{}: sent frames gave {}".format(what, d))


def snapshot(decs):
    for d in decs[:2]:
        d.reset_sequence()
    return [d.stats() for d in decs]


def main():
    if struct.calcsize(TELEMETRY_FMT) != wire.PAYLOAD_SIZE[TELEMETRY]:
        fail("TELEMETRY format does not match wire.PAYLOAD_SIZE")
    print("alloc: protocol from {}, heap {} bytes free".format(framing.__file__, gc.mem_free()))
    stream = bytearray(STREAM_CAP)
    n = build_stream(stream)
    ref = framing.FrameDecoder()
    want_frames = 0
    i = 0
    while i < n:
        i = ref.feed(stream, i, n)
        if ref.ready:
            want_frames += 1
    want = ref.stats()  # per pass; each pass starts with reset_sequence(), as ref did
    if want["overflows"] < 5 or want["crc_errors"] + want["cobs_errors"] + want["length_errors"] < 10:
        fail("stream lacks trouble: {}".format(want))

    enc = framing.FrameEncoder()
    decs = [framing.FrameDecoder(), framing.FrameDecoder(), framing.FrameDecoder()]
    rx = bytearray(framing.MAX_FRAME)
    warm_up(enc, decs, stream, n, rx)

    result = [0, 0, 0, 0, 0]
    probe(result)
    if result[0] != 4:
        fail("heap_lock did not catch an allocation; the check proves nothing")
    result[0] = 0

    before = snapshot(decs)
    locked(decs[0], decs[1], enc, decs[2], stream, n, rx, result)
    if result[0]:
        fail("allocation (MemoryError under heap_lock) in phase '{}'".format(PHASES[result[0]]))
    check_counters(decs, before, want, want_frames, result, "heap locked")
    print("alloc: heap locked: {} bytes received twice (byte by byte, in chunks), {} frames and {} errors "
          "each, {} frames sent; no MemoryError".format(n, want_frames, ref.errors, SENT))

    before = snapshot(decs)
    alloc = [0, 0]
    measured(decs[0], decs[1], enc, decs[2], stream, n, rx, result, alloc)
    check_counters(decs, before, want, want_frames, result, "gc disabled")
    used = alloc[1] - alloc[0]
    if used != 0:
        fail("gc.mem_alloc grew by {} bytes over {} received bytes".format(used, 2 * n))
    print("alloc: {} bytes allocated per received byte (gc.mem_alloc delta {} over {} bytes)".format(
        used // (2 * n), used, 2 * n))
    print("alloc: ok")

main()
