"""The numbers both ends of a link agree on: message types, sizes, schema bytes, modes,
flags, error codes and parameter limits (protocol/SPEC.md).

All the firmware needs of the message set, kept small for a microcontroller's RAM;
protocol/messages.py adds names, layouts and packing for hosts.  The sizes and schema
bytes here agree with those layouts
(tests/test_protocol_units.py::test_schema_value_is_crc_of_schema_text).
"""
from array import array

from protocol.compat import const

PROTOCOL_VERSION = const(1)
MAX_PAYLOAD = const(249)  # body (254) - version, type, seq (3) - CRC (2)

# Message types.
HELLO = const(0x01)
TELEMETRY = const(0x02)
COMMAND = const(0x03)
PARAM_SET = const(0x04)
PARAM_GET = const(0x05)
PARAM_VALUE = const(0x06)
ACK = const(0x07)
NACK = const(0x08)
HW_SENSE = const(0x10)
HW_ACTUATE = const(0x11)
LOG = const(0x20)

# type, payload size, schema value; LOG's size is that of its fixed part.
# The 16-bit schema value is the CRC of the layout's text (messages.py), and
# no two types share one (a test checks it).  A list, dropped once read: a
# tuple literal would stay in RAM as a constant.
_TYPES = [
    HELLO, 16, 0x170C,
    TELEMETRY, 70, 0xFD01,
    COMMAND, 5, 0xC361,
    PARAM_SET, 5, 0xC2F4,
    PARAM_GET, 1, 0xF33A,
    PARAM_VALUE, 5, 0x21FF,
    ACK, 2, 0x50EE,
    NACK, 3, 0x0F91,
    HW_SENSE, 46, 0x68D8,
    HW_ACTUATE, 9, 0xE344,
    LOG, 1, 0xD9A4,
]
N_TYPES = const(0x21)  # types are below this
UNKNOWN = const(0xFF)  # PAYLOAD_SIZE of a type that does not exist
VARIABLE_TYPE = const(0x20)  # LOG: its text runs to the end of the payload
PAYLOAD_SIZE = bytearray(b"\xff" * N_TYPES)
SCHEMA = array("H", bytes(2 * N_TYPES))  # 16-bit schema value per type (0: no such type)
for _k in range(0, len(_TYPES), 3):
    PAYLOAD_SIZE[_TYPES[_k]] = _TYPES[_k + 1]
    SCHEMA[_TYPES[_k]] = _TYPES[_k + 2]
del _TYPES, _k

# Modes (COMMAND.mode, TELEMETRY.mode).
MODE_STOP = const(0)
MODE_AUTONOMOUS = const(1)
MODE_HOST = const(2)
MODE_TELEOP = const(3)

# Board kinds (HELLO.board).
BOARD_UNKNOWN = const(0)
BOARD_HOST = const(1)
BOARD_VIRTUAL = const(2)
BOARD_RP2040 = const(3)

# TELEMETRY.flags bits.
FLAG_WATCHDOG = const(0x01)  # no valid COMMAND in time: motors forced to zero
FLAG_IR_SATURATED = const(0x02)  # at least one IR reading hit the ADC ceiling
FLAG_OVERRUN = const(0x04)  # the last cycle took longer than its period
FLAG_FAULT = const(0x08)  # an exception was caught in the last cycle
FLAG_CURRENT_LIMIT = const(0x10)  # a current reference was clamped
FLAG_LOW_BATTERY = const(0x20)
FLAG_STALL = const(0x40)  # the explorer is backing out of a stall (firmware/stall.py)

# NACK.error codes.
ERR_UNKNOWN_PARAM = const(1)
ERR_OUT_OF_RANGE = const(2)
ERR_BAD_MODE = const(3)
ERR_UNSUPPORTED = const(4)
ERR_BUSY = const(5)

# LOG.level.
LOG_DEBUG = const(0)
LOG_INFO = const(1)
LOG_WARNING = const(2)
LOG_ERROR = const(3)

# Parameters by id p: minimum at PARAM_LIMITS[3p], maximum at [3p + 1],
# default at [3p + 2]; id 0 does not exist.  Names and units are in
# messages.PARAMS (a test checks that the two agree).  A flat 32-bit array:
# a tuple of tuples would take four times the RAM.
PARAM_LIMITS = array("i", [
    0, 0, 0,
    0, 100, 60,  # 1 emitter_pct
    0, 3, 0,  # 2 ir_averaging
    1, 16, 4,  # 3 ir_window
    0, 1, 1,  # 4 rule_set
    20, 10000, 200,  # 5 watchdog_ms
    10, 1000, 40,  # 6 cycle_ms
    0, 100000, 400,  # 7 speed_kp
    0, 100000, 2000,  # 8 speed_ki
    0, 2, 2,  # 9 odometry
    0, 1000, 200,  # 10 max_speed
    0, 3000, 500,  # 11 current_limit
    10000, 200000, 42000,  # 12 wheel_diameter_um
    20000, 1000000, 96000,  # 13 wheel_base_um
    100, 16000, 1200,  # 14 ticks_per_rev
    0, 10000, 1500,  # 15 stall_ms
    0, 3000, 150,  # 16 push_ma
])
