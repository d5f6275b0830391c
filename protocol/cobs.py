"""Consistent Overhead Byte Stuffing (Cheshire & Baker, 1999): frames end at the only 0x00.

For a block of at most 254 bytes COBS adds exactly one byte; a final block of 254
non-zero bytes gets no trailing code byte (as the PyPI `cobs` package does).
`encode_into` / `decode_into` work between preallocated buffers and allocate nothing on
MicroPython; `encode` / `decode` are the convenient host forms (protocol/SPEC.md).
"""
from protocol.compat import IS_MICROPYTHON


def _copy_bytes(dst: bytearray, dpos: int, src: bytes | bytearray | memoryview, spos: int, n: int) -> None:
    # Byte by byte: a slice would allocate on MicroPython.
    for k in range(n):
        dst[dpos + k] = src[spos + k]


if not IS_MICROPYTHON:

    def _copy_slice(dst: bytearray, dpos: int, src: bytes | bytearray | memoryview, spos: int, n: int) -> None:
        dst[dpos : dpos + n] = src[spos : spos + n]

    _copy_bytes = _copy_slice


def encode_into(src: bytes | bytearray, n: int, dst: bytearray, dpos: int = 0) -> int:
    """COBS-encode src[:n] into dst at dpos; return the end position in dst.

    dst needs n + n // 254 + 1 free bytes.  No delimiter is written.  A run at a time: find() (in C)
    locates the next zero and the run is copied with one index sum a byte, half the bytecodes a byte of a
    byte-by-byte loop (tests/test_protocol_units.py::test_cobs_by_runs_is_the_byte_loop).
    """
    code_pos = dpos
    out = dpos + 1
    i = 0
    while True:
        j = src.find(b"\x00", i, n)
        stop = n if j < 0 else j
        if stop - i > 254:
            stop = i + 254
        off = out - i
        for k in range(i, stop):
            dst[k + off] = src[k]
        out += stop - i
        if stop - i == 254:  # a full block: code 0xFF, and no zero follows it in the data
            dst[code_pos] = 0xFF
            if stop == n:
                return out  # a full final block needs no code byte after it
            i = stop
        else:
            dst[code_pos] = stop - i + 1
            if j < 0:
                return out
            i = stop + 1
        code_pos = out
        out += 1


encode_into_pure = encode_into

if not IS_MICROPYTHON:

    def _encode_into_fast(src: bytes | bytearray | memoryview, n: int, dst: bytearray, dpos: int = 0) -> int:
        # Split at the zeros (in C) and prefix each run with its length + 1;
        # runs of 254 and more need the 0xFF code: the byte loop does those.
        out = bytearray()
        for run in bytes(src[:n]).split(b"\x00"):
            if len(run) >= 254:
                return encode_into_pure(bytes(src[:n]), n, dst, dpos)
            out.append(len(run) + 1)
            out += run
        m = len(out)
        dst[dpos : dpos + m] = out
        return dpos + m

    encode_into = _encode_into_fast


def decode_into(src: bytes | bytearray | memoryview, start: int, end: int, dst: bytearray) -> int:
    """COBS-decode src[start:end] into dst; return the decoded length.

    The block must hold no 0x00 (a frame decoder splits on them).  Returns -1
    if a code byte runs past the end or the result would not fit in dst.
    Never raises.
    """
    cap = len(dst)
    out = 0
    pos = start
    while pos < end:
        code = src[pos]
        run = code - 1
        if code == 0 or pos + code > end or out + run > cap:
            return -1
        _copy_bytes(dst, out, src, pos + 1, run)
        out += run
        pos += code
        if code < 0xFF and pos < end:
            if out >= cap:
                return -1
            dst[out] = 0
            out += 1
    return out


decode_into_pure = decode_into

if not IS_MICROPYTHON:

    def _decode_into_fast(src: bytes | bytearray | memoryview, start: int, end: int, dst: bytearray) -> int:
        # Without 0xFF codes, every code byte but the first decodes to a zero
        # in place: one slice copy, then a walk along the codes.
        n = end - start
        if n == 0:
            return 0
        block = src[start:end]
        pos = block[0]
        if pos == 0xFF or pos == 0 or n - 1 > len(dst):
            return decode_into_pure(src, start, end, dst)
        dst[0 : n - 1] = block[1:]
        while pos < n:
            code = block[pos]
            if code == 0xFF or code == 0:
                return decode_into_pure(src, start, end, dst)
            dst[pos - 1] = 0
            pos += code
        return n - 1 if pos == n else -1

    decode_into = _decode_into_fast


def encode(data: bytes | bytearray | memoryview) -> bytes:
    """COBS-encode a whole block (any length); no delimiter."""
    src = data if isinstance(data, (bytes, bytearray)) else bytes(data)  # encode_into needs find()
    n = len(src)
    dst = bytearray(n + n // 254 + 1)
    m = encode_into(src, n, dst)
    return bytes(dst[:m])


def decode(data: bytes | bytearray | memoryview) -> bytes:
    """COBS-decode one block (without its 0x00 delimiter); ValueError if invalid."""
    if 0 in bytes(data):
        raise ValueError("invalid COBS block: contains 0x00")
    dst = bytearray(len(data))
    m = decode_into(data, 0, len(data), dst)
    if m < 0:
        raise ValueError("invalid COBS block")
    return bytes(dst[:m])
