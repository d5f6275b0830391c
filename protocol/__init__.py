"""twinbot serial protocol: one pure-Python implementation for robot and host.

Runs unchanged on CPython and MicroPython.  See SPEC.md beside this file for the
wire format.  Modules, in the order bytes flow through them:

    crc16     CRC-16/MCRF4XX (the checksum every frame carries)
    cobs      Consistent Overhead Byte Stuffing (frames end at the only 0x00)
    messages  message types, payload layouts, parameter and mode numbers
    framing   FrameEncoder / FrameDecoder (streaming, bounded, counting)
    fields    reading a decoded body's fields without allocating (firmware)
"""
