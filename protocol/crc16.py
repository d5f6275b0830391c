"""CRC-16/MCRF4XX: poly 0x1021 reflected, init 0xFFFF, no final xor (protocol/SPEC.md).

MAVLink's X.25 "crc_accumulate"; check value 0x6F91 for b"123456789".  The bitwise
update below needs no table (RAM matters on a microcontroller).  On CPython,
binascii.crc_hqx gives the same result on bit-reversed bytes, about 50x faster;
tests/test_protocol_units.py proves both paths equal.
"""
from protocol.compat import IS_MICROPYTHON, const

CRC_INIT = const(0xFFFF)


def crc16_update(crc: int, data: bytes | bytearray | memoryview, start: int, end: int) -> int:
    """Fold data[start:end] into crc; allocation-free."""
    for i in range(start, end):
        tmp = (data[i] ^ crc) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        # Every term is below 2**16 (crc is), so the XOR is: no mask, two bytecodes fewer a byte.
        crc = (crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)
    return crc


def crc16_byte(crc: int, byte: int) -> int:
    """Fold one byte into crc (used for the per-message schema byte)."""
    tmp = (byte ^ crc) & 0xFF
    tmp = (tmp ^ (tmp << 4)) & 0xFF
    return ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF


crc16_update_pure = crc16_update

if not IS_MICROPYTHON:
    from binascii import crc_hqx  # type: ignore[attr-defined]  # CPython only

    _REV8 = bytes(int("{:08b}".format(i)[::-1], 2) for i in range(256))

    def _crc16_update_fast(crc: int, data: bytes | bytearray | memoryview, start: int, end: int) -> int:
        # A reflected CRC equals the bit-reversed plain CRC of bit-reversed input.
        rev = _REV8
        c = (rev[crc & 0xFF] << 8) | rev[crc >> 8]
        c = int(crc_hqx(data[start:end].translate(rev), c))  # type: ignore[union-attr]
        return (rev[c & 0xFF] << 8) | rev[c >> 8]

    crc16_update = _crc16_update_fast


def crc16(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/MCRF4XX of a whole buffer."""
    return crc16_update(CRC_INIT, data, 0, len(data))
