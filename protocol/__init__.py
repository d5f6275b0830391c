"""twinbot serial protocol: one pure-Python implementation for robot and host (protocol/SPEC.md).

Runs unchanged on CPython and MicroPython.  Modules, in the order bytes flow through
them: crc16 (the frame checksum), cobs (frames end at the only 0x00), messages (types,
layouts, parameter and mode numbers; wire holds what the firmware needs of them),
framing (FrameEncoder / FrameDecoder, streaming and counting) and fields (reading a
decoded body without allocating).
"""
