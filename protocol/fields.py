"""Little-endian fields of a decoded frame body, read without allocating.

struct.unpack_from would build a tuple per call; the firmware reads the few
fields it needs with these instead (protocol/SPEC.md gives the offsets).
"""
from protocol.compat import const


def read_u16(b: bytearray, o: int) -> int:
    return b[o] | (b[o + 1] << 8)


def read_i16(b: bytearray, o: int) -> int:
    v = b[o] | (b[o + 1] << 8)
    return v - 65536 if v & 0x8000 else v


# The RP2040's small ints hold [-2**30, 2**30): read_i31 never builds a value beyond it, so a hostile
# 32-bit field costs no heap on the board (tests/mp/counters_check.py).
_SMALL_MAX = const(0x3FFFFFFF)
_SMALL_MIN = const(-0x40000000)


def read_i31(b: bytearray, o: int) -> int:
    """An i32 field saturated into [-2**30, 2**30 - 1]: out of every parameter's range either way."""
    hi = b[o + 3]
    if hi & 0x80:
        hi -= 256
    if hi >= 0x40:
        return _SMALL_MAX
    if hi < -0x40:
        return _SMALL_MIN
    return (hi << 24) | (b[o + 2] << 16) | (b[o + 1] << 8) | b[o]


def read_u30(b: bytearray, o: int) -> int:
    """A 32-bit field modulo 2**30, in [0, 2**30): a clock that wraps as MicroPython's ticks_ms."""
    return ((b[o + 3] & 0x3F) << 24) | (b[o + 2] << 16) | (b[o + 1] << 8) | b[o]


def read_wrap30(b: bytearray, o: int) -> int:
    """A 32-bit count modulo 2**30, in [-2**29, 2**29): encoder counts as the RP2040 HAL keeps them."""
    v = read_u30(b, o)
    if v >= 0x20000000:
        v = v - 0x20000000 - 0x20000000
    return v
