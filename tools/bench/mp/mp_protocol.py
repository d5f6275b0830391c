"""The MicroPython side of `twinbot bench protocol`: the firmware's view of the protocol.

    micropython tools/bench/mp/mp_protocol.py [FRAMES [REPEATS [CHUNK_OUT]]]

Times the allocation-free encode path and the feed() loop, with and without
unpacking, and the bytes they allocate; prints one JSON line last.  It must
stay importable on CPython, which builds the same frames from
telemetry_values() to check them byte for byte.  Figures: docs/benchmarks.md.
"""
import gc
import struct
import sys
import time

from protocol.framing import FrameDecoder, FrameEncoder
from protocol.messages import FORMATS, PAYLOAD_SIZE, TELEMETRY

N_VALUES = 30  # flat TELEMETRY values: tick, mode, flags, enc_l, enc_r, 8 ir_on, 8 ir_amb, 2 i_ref, vbat,
# 2 set-points, odometry x, y, heading, emitter power
# As on a board, RAM holds a bounded buffer fed again and again (frame k carries the values of frame
# k % CHUNK_FRAMES): with megabytes live, MicroPython's allocator, scanning from the first free block
# for every multi-block object (unpack_from's 24-item tuple is 14 blocks), would add tens of us each.
CHUNK_FRAMES = 1024  # frames held in RAM; a multiple of 256, so the wrapping sequence runs on across passes


def _wrap_i32(x):
    return ((x + 0x80000000) & 0xFFFFFFFF) - 0x80000000


def telemetry_values(k):
    """The k-th TELEMETRY frame's values, flat, in struct order (deterministic).

    A robot driving at 25 Hz: the tick grows by 40 ms; the left encoder
    counts up through zero, the right one down through zero (both within
    the first 1024 frames); IR readings span 0..4095 (ambient 100..611, plus
    a reflection that grows and saturates as obstacles come and go,
    differently per sensor); current references swing between -500 and
    500 mA; the battery sags.  mode is never 0, so MAVLink 2 (whose last
    payload byte is this field after its field reordering) never truncates
    the payload.
    """
    tick = (1000 + 40 * k) & 0xFFFFFFFF
    mode = 1 + (k // 500) % 3
    flags = (k // 97) & 0x3F
    enc_l = _wrap_i32(37 * k - 20000)
    enc_r = _wrap_i32(12000 - 23 * k - (k % 50))
    on = []
    amb = []
    for j in range(8):
        h = ((k * 8 + j + 1) * 2654435761) & 0xFFFFFFFF
        a = 100 + (h >> 23)
        s = ((k + 300 * j) % 1000) * 5
        amb.append(a)
        on.append(a + s if a + s < 4095 else 4095)
    if k % 211 == 0:
        on[k % 8] = 0  # an occasional dead reading
    il = (k * 7) % 1001 - 500
    ir = 500 - (k * 11) % 1001
    vbat = 8400 - (k * 3 // 100) % 1200
    sp_l = (k * 5) % 401 - 200
    sp_r = 200 - (k * 3) % 401
    odo_x = _wrap_i32(1500 * k - 700000)
    odo_y = _wrap_i32(350000 - 900 * k)
    heading = (k * 2654435) & 0x3FFFFFFF
    return tuple([tick, mode, flags, enc_l, enc_r] + on + amb + [il, ir, vbat, sp_l, sp_r, odo_x, odo_y, heading, 60])


def _encode_loop(enc, vals, n_frames, chunk, fmt, mtype, plen):
    # Frame k carries the values of frame k % chunk (see the module docstring).
    pack_into = struct.pack_into
    body = enc.body
    finish = enc.finish
    wrap = chunk * N_VALUES
    total = 0
    b = 0
    for _k in range(n_frames):
        v = vals
        pack_into(fmt, body, 3, v[b], v[b + 1], v[b + 2], v[b + 3], v[b + 4], v[b + 5], v[b + 6],
                  v[b + 7], v[b + 8], v[b + 9], v[b + 10], v[b + 11], v[b + 12], v[b + 13], v[b + 14],
                  v[b + 15], v[b + 16], v[b + 17], v[b + 18], v[b + 19], v[b + 20], v[b + 21],
                  v[b + 22], v[b + 23], v[b + 24], v[b + 25], v[b + 26], v[b + 27], v[b + 28], v[b + 29])
        total += finish(mtype, plen)
        b += N_VALUES
        if b == wrap:
            b = 0
    return total


def _feed_loop(dec, stream, ends, n_frames, chunk):
    # Feeds the chunk of frames again and again until n_frames went through,
    # the last pass stopping at a frame boundary.
    frames = 0
    left = n_frames
    while left > 0:
        end = ends[chunk - 1] if left >= chunk else ends[left - 1]
        left -= chunk
        i = 0
        while i < end:
            i = dec.feed(stream, i, end)
            if dec.ready:
                frames += 1
    return frames


def _feed_unpack_loop(dec, stream, ends, n_frames, chunk, fmt):
    unpack_from = struct.unpack_from
    body = dec.body
    frames = 0
    acc = 0
    left = n_frames
    while left > 0:
        end = ends[chunk - 1] if left >= chunk else ends[left - 1]
        left -= chunk
        i = 0
        while i < end:
            i = dec.feed(stream, i, end)
            if dec.ready:
                f = unpack_from(fmt, body, 3)
                acc ^= f[0]  # use a field, so that the unpacking is not dead code
                frames += 1
    return frames


def _progress(text):
    print("[mp_bench_protocol] " + text, file=sys.stderr)


def _median(xs):
    s = sorted(xs)
    n = len(s)
    return s[n // 2] if n % 2 else (s[n // 2 - 1] + s[n // 2]) / 2


def main(argv):
    n_frames = int(argv[1]) if len(argv) > 1 else 20000
    repeats = int(argv[2]) if len(argv) > 2 else 5
    stream_out = argv[3] if len(argv) > 3 else None
    chunk = n_frames if n_frames < CHUNK_FRAMES else CHUNK_FRAMES
    mtype = TELEMETRY
    fmt = FORMATS[mtype]
    plen = PAYLOAD_SIZE[mtype]

    vals = _chunk_values(chunk)
    stream, ends = _encode_chunk(vals, chunk, fmt, mtype, plen)
    end = ends[chunk - 1]
    if stream_out:
        with open(stream_out, "wb") as f:
            f.write(memoryview(stream)[:end])
    _check_round_trip(stream, ends, vals, n_frames, chunk, fmt, mtype, plen)
    wire_bytes = _wire_bytes(ends, n_frames, chunk)
    enc_us, dec_us, feed_us, enc_bytes = _time_loops(vals, stream, ends, n_frames, chunk, fmt, mtype, plen,
                                                     repeats)
    alloc_enc_1, alloc_enc, alloc_feed, alloc_unpack = _measure_alloc(vals, stream, ends, n_frames, chunk,
                                                                      fmt, mtype, plen)
    out = {
        "implementation": sys.implementation.name,
        "version": ".".join([str(x) for x in sys.implementation.version[:3]]),
        "sys_version": sys.version,
        "machine": getattr(sys.implementation, "_machine", ""),
        "frames": n_frames,
        "repeats": repeats,
        "chunk_frames": chunk,
        "payload_bytes": plen,
        "wire_bytes": wire_bytes,
        "heap_bytes": gc.mem_alloc() + gc.mem_free(),
        "encode": _rates(enc_us, enc_bytes, n_frames),
        "decode": _rates(dec_us, wire_bytes, n_frames),
        "decode_feed": _rates(feed_us, wire_bytes, n_frames),
        "alloc_encode_bytes": alloc_enc,
        "alloc_encode_frames": n_frames,
        "alloc_encode_one_frame_bytes": alloc_enc_1,
        "alloc_encode_per_frame": (alloc_enc - alloc_enc_1) / (n_frames - 1) if n_frames > 1 else 0.0,
        "alloc_feed_bytes": alloc_feed,
        "alloc_feed_stream_bytes": wire_bytes,
        "alloc_feed_per_byte": alloc_feed / wire_bytes,
        "alloc_unpack_bytes": alloc_unpack,
        "alloc_unpack_stream_bytes": end,
        "alloc_unpack_per_byte": alloc_unpack / end,
    }
    import json

    print(json.dumps(out))


def _chunk_values(chunk):
    # The values of one chunk of frames, preallocated (not timed).
    import array

    vals = array.array("i", bytearray(4 * N_VALUES * chunk))
    for k in range(chunk):
        t = telemetry_values(k)
        b = k * N_VALUES
        for j in range(N_VALUES):
            vals[b + j] = t[j]
    return vals


def _encode_chunk(vals, chunk, fmt, mtype, plen):
    # The chunk of frames to decode, as this port encodes them (not timed);
    # returns the stream and the end offset of each frame in it.
    import array

    enc = FrameEncoder()
    stream = bytearray(chunk * (plen + 8))
    ends = array.array("I", bytearray(4 * chunk))
    end = 0
    for k in range(chunk):
        b = k * N_VALUES
        struct.pack_into(fmt, enc.body, 3, *vals[b:b + N_VALUES])
        n = enc.finish(mtype, plen)
        stream[end:end + n] = enc.view(n)
        end += n
        ends[k] = end
    return stream, ends


def _check_round_trip(stream, ends, vals, n_frames, chunk, fmt, mtype, plen):
    # Correctness (not timed): every frame of every pass back, every field equal.
    dec = FrameDecoder()
    got = 0
    bad = 0
    left = n_frames
    while left > 0:
        stop = ends[chunk - 1] if left >= chunk else ends[left - 1]
        left -= chunk
        i = 0
        k = 0
        while i < stop:
            i = dec.feed(stream, i, stop)
            if dec.ready:
                f = struct.unpack_from(fmt, dec.body, 3)
                b = k * N_VALUES
                if dec.msg_type != mtype or dec.payload_len != plen or tuple(vals[b:b + N_VALUES]) != f:
                    bad += 1
                k += 1
                got += 1
    if got != n_frames or bad or dec.errors or dec.frames_lost:
        raise SystemExit("round trip failed: {} of {} frames, {} mismatched, {} errors, {} lost".format(
            got, n_frames, bad, dec.errors, dec.frames_lost))


def _wire_bytes(ends, n_frames, chunk):
    # Bytes of n_frames frames fed as the chunk again and again.
    wire_bytes = 0
    left = n_frames
    while left > 0:
        wire_bytes += ends[chunk - 1] if left >= chunk else ends[left - 1]
        left -= chunk
    return wire_bytes


def _time_loops(vals, stream, ends, n_frames, chunk, fmt, mtype, plen, repeats):
    # Microseconds per run, time.ticks_us, of: encode (struct.pack_into of the values into enc.body,
    # then enc.finish(), from a preallocated array as the firmware reads its state); decode (feed()
    # over the stream and struct.unpack_from() of every frame delivered); feed() alone (framing, COBS,
    # CRC, type, length and sequence checks).
    ticks_us = time.ticks_us
    ticks_diff = time.ticks_diff
    enc_us = []
    dec_us = []
    feed_us = []
    enc_bytes = 0
    for r in range(repeats):
        _progress("repeat {}/{}: encode, decode with unpack_from, feed() only".format(r + 1, repeats))
        e = FrameEncoder()
        gc.collect()
        t0 = ticks_us()
        enc_bytes = _encode_loop(e, vals, n_frames, chunk, fmt, mtype, plen)
        t1 = ticks_us()
        enc_us.append(ticks_diff(t1, t0))
        d = FrameDecoder()
        gc.collect()
        t0 = ticks_us()
        got = _feed_unpack_loop(d, stream, ends, n_frames, chunk, fmt)
        t1 = ticks_us()
        dec_us.append(ticks_diff(t1, t0))
        if got != n_frames:
            raise SystemExit("decode delivered {} of {} frames".format(got, n_frames))
        d = FrameDecoder()
        gc.collect()
        t0 = ticks_us()
        got = _feed_loop(d, stream, ends, n_frames, chunk)
        t1 = ticks_us()
        feed_us.append(ticks_diff(t1, t0))
        if got != n_frames:
            raise SystemExit("feed() delivered {} of {} frames".format(got, n_frames))
    return enc_us, dec_us, feed_us, enc_bytes


def _measure_alloc(vals, stream, ends, n_frames, chunk, fmt, mtype, plen):
    # Allocation: untimed passes with the garbage collector off.  The encode
    # loop is measured for 1 frame and for all, to tell a per-call cost (the
    # loop function's own state) from a per-frame one.  Written out pass by
    # pass: a helper taking the loop as an argument would add its own call.
    mem_alloc = gc.mem_alloc
    e = FrameEncoder()
    gc.collect()
    gc.disable()
    a0 = mem_alloc()
    _encode_loop(e, vals, 1, chunk, fmt, mtype, plen)
    alloc_enc_1 = mem_alloc() - a0
    gc.enable()
    e = FrameEncoder()
    gc.collect()
    gc.disable()
    a0 = mem_alloc()
    _encode_loop(e, vals, n_frames, chunk, fmt, mtype, plen)
    alloc_enc = mem_alloc() - a0
    gc.enable()
    d = FrameDecoder()
    gc.collect()
    gc.disable()
    a0 = mem_alloc()
    _feed_loop(d, stream, ends, n_frames, chunk)
    alloc_feed = mem_alloc() - a0
    gc.enable()
    d = FrameDecoder()
    gc.collect()
    gc.disable()
    a0 = mem_alloc()
    _feed_unpack_loop(d, stream, ends, chunk, chunk, fmt)  # one pass: the tuples stay until the gc runs
    alloc_unpack = mem_alloc() - a0
    gc.enable()
    return alloc_enc_1, alloc_enc, alloc_feed, alloc_unpack


def _rates(us_list, nbytes, n_frames):
    m = _median(us_list)
    return {
        "us": us_list,
        "median_s": m / 1e6,
        "frames_per_s": n_frames * 1e6 / m,
        "mb_per_s": nbytes / m,  # bytes per microsecond = MB (1e6 bytes) per second
    }


if __name__ == "__main__":
    main(sys.argv)
