"""Little-endian fields of a decoded frame body, read without allocating.

struct.unpack_from would build a tuple per call; the firmware reads the few
fields it needs with these instead (protocol/SPEC.md gives the offsets).
"""


def read_u16(b: bytearray, o: int) -> int:
    return b[o] | (b[o + 1] << 8)


def read_i16(b: bytearray, o: int) -> int:
    v = b[o] | (b[o + 1] << 8)
    return v - 65536 if v & 0x8000 else v


def read_i32(b: bytearray, o: int) -> int:
    hi = b[o + 3]
    if hi & 0x80:  # sign first: no int beyond 31 bits on a 32-bit port
        hi -= 256
    return (hi << 24) | (b[o + 2] << 16) | (b[o + 1] << 8) | b[o]
