"""Message types, payload layouts and the numbers both ends agree on (protocol/SPEC.md).

Every payload is a fixed little-endian struct, except LOG whose text runs to the end of
the payload.  Each layout also yields a schema byte, folded into the frame CRC (as
MAVLink's CRC_EXTRA), so two ends built from different message definitions reject each
other's frames instead of misreading them.  SPEC.md documents every field with its unit.
"""
import struct

from protocol.crc16 import crc16
from protocol.framing import FrameEncoder
from protocol.wire import *  # noqa: F403  (the numbers, re-exported for hosts)

# (type, name, ((field, struct code, count), ...)); count 0 = rest of payload.
LAYOUTS = (
    (HELLO, "HELLO", (("protocol", "B", 1), ("fw_major", "B", 1), ("fw_minor", "B", 1),
                      ("fw_patch", "B", 1), ("board", "B", 1), ("sensors", "B", 1),
                      ("wheel_diameter_um", "I", 1), ("wheel_base_um", "I", 1), ("ticks_per_rev", "H", 1))),
    (TELEMETRY, "TELEMETRY", (("tick_ms", "I", 1), ("mode", "B", 1), ("flags", "H", 1),
                              ("enc_l", "i", 1), ("enc_r", "i", 1),
                              ("ir_on", "H", 8), ("ir_amb", "H", 8),
                              ("i_ref_l_ma", "h", 1), ("i_ref_r_ma", "h", 1),
                              ("vbat_mv", "H", 1), ("sp_l", "h", 1), ("sp_r", "h", 1),
                              ("odo_x", "i", 1), ("odo_y", "i", 1), ("odo_heading", "i", 1),
                              ("emitter_pct", "B", 1))),
    (COMMAND, "COMMAND", (("mode", "B", 1), ("left", "h", 1), ("right", "h", 1))),
    (PARAM_SET, "PARAM_SET", (("param", "B", 1), ("value", "i", 1))),
    (PARAM_GET, "PARAM_GET", (("param", "B", 1),)),
    (PARAM_VALUE, "PARAM_VALUE", (("param", "B", 1), ("value", "i", 1))),
    (ACK, "ACK", (("ack_seq", "B", 1), ("ack_type", "B", 1))),
    (NACK, "NACK", (("ack_seq", "B", 1), ("ack_type", "B", 1), ("error", "B", 1))),
    (HW_SENSE, "HW_SENSE", (("tick_ms", "I", 1), ("adc_off", "H", 8), ("adc_on", "H", 8),
                            ("enc_l", "i", 1), ("enc_r", "i", 1), ("vbat_mv", "H", 1))),
    (HW_ACTUATE, "HW_ACTUATE", (("tick_ms", "I", 1), ("i_ref_l_ma", "h", 1),
                                ("i_ref_r_ma", "h", 1), ("emitter_pct", "B", 1))),
    (LOG, "LOG", (("level", "B", 1), ("text", "s", 0))),
)

MODE_NAMES = ("STOP", "AUTONOMOUS", "HOST", "TELEOP")
BOARD_NAMES = ("UNKNOWN", "HOST", "VIRTUAL", "RP2040")
FLAG_NAMES = ("WATCHDOG", "IR_SATURATED", "OVERRUN", "FAULT", "CURRENT_LIMIT", "LOW_BATTERY", "STALL")
ERROR_NAMES = ("OK", "UNKNOWN_PARAM", "OUT_OF_RANGE", "BAD_MODE", "UNSUPPORTED", "BUSY")
LOG_LEVEL_NAMES = ("DEBUG", "INFO", "WARNING", "ERROR")

# Parameters: (id, name, minimum, maximum, default, unit and meaning).
PARAMS = (
    (1, "emitter_pct", 0, 100, 60, "% IR emitter pulse width (light power L)"),
    (2, "ir_averaging", 0, 3, 0, "0 none, 1 moving average, 2 exponential, 3 median of 3"),
    (3, "ir_window", 1, 16, 4, "samples in the moving average / 2^k weight of the exponential"),
    (4, "rule_set", 0, 1, 1, "0 first (front/left/back/right), 1 refined (per sensor)"),
    (5, "watchdog_ms", 20, 10000, 200, "ms without a valid COMMAND before HOST/TELEOP stop"),
    (6, "cycle_ms", 10, 1000, 40, "ms per control cycle"),
    (7, "speed_kp", 0, 100000, 400, "wheel-speed PI gain, 1/1000 mA per mm/s"),
    (8, "speed_ki", 0, 100000, 2000, "wheel-speed PI gain, 1/1000 mA per mm"),
    (9, "odometry", 0, 2, 2, "0 Euler, 1 midpoint, 2 exact arc"),
    (10, "max_speed", 0, 1000, 200, "mm/s wheel-speed setpoint limit"),
    (11, "current_limit", 0, 3000, 500, "mA current reference limit"),
    (12, "wheel_diameter_um", 10000, 200000, 42000, "um wheel diameter (odometry, wheel speeds)"),
    (13, "wheel_base_um", 20000, 1000000, 96000, "um between the wheel contact points (odometry)"),
    (14, "ticks_per_rev", 100, 16000, 1200, "encoder ticks per wheel revolution"),
    (15, "stall_ms", 0, 10000, 1500, "ms a wheel may stall (under 1/4 of its setpoint) before the explorer backs out; 0 off"),
    (16, "push_ma", 0, 3000, 150, "mA: a wheel's current reference above this counts towards stall_ms too (a wall pushed, wheels spinning); 0 off"),
)

VARIABLE = bytearray(N_TYPES)  # 1 where the payload's last field runs to its end
VARIABLE[VARIABLE_TYPE] = 1
NAMES: dict[int, str] = {}  # type -> name
TYPES: dict[str, int] = {}  # name -> type
FORMATS: dict[int, str] = {}  # type -> struct format of the fixed part


def schema_text(name: str, fields: tuple[tuple[str, str, int], ...]) -> str:
    """The canonical text of a layout; its CRC gives the schema byte."""
    parts = [name]
    for fname, code, count in fields:
        parts.append("{}:{}[{}]".format(fname, code, count) if count != 1 else "{}:{}".format(fname, code))
    return " ".join(parts)


def schema_value(name: str, fields: tuple[tuple[str, str, int], ...]) -> int:
    """The 16-bit value folded into every frame's CRC, low byte first (SPEC.md section 1)."""
    return crc16(schema_text(name, fields).encode())


def _build() -> None:
    for msg_type, name, fields in LAYOUTS:
        fmt = "<"
        for _fname, code, count in fields:
            if count:
                fmt += (str(count) if count > 1 else "") + code
        NAMES[msg_type] = name
        TYPES[name] = msg_type
        FORMATS[msg_type] = fmt


_build()


def geometry_frames(encoder: "FrameEncoder", wheel_diameter_um: int, wheel_base_um: int, ticks_per_rev: int) -> list[bytes]:
    """The three PARAM_SET frames that give a robot its geometry (parameters 12..14).

    ValueError names a value outside its range.  encoder: a framing.FrameEncoder."""
    out = []
    for name, value in (("wheel_diameter_um", wheel_diameter_um), ("wheel_base_um", wheel_base_um),
                        ("ticks_per_rev", ticks_per_rev)):
        pid, _name, lo, hi, _default, unit = param_by_name(name)
        if not isinstance(value, int) or not lo <= value <= hi:
            raise ValueError("{} = {!r} is outside {}..{} ({})".format(name, value, lo, hi, unit))
        out.append(encoder.encode(PARAM_SET, pack_payload(PARAM_SET, {"param": pid, "value": value})))
    return out


def is_known(msg_type: int) -> bool:
    return 0 <= msg_type < N_TYPES and PAYLOAD_SIZE[msg_type] != UNKNOWN


def param_by_name(name: str) -> tuple[int, str, int, int, int, str]:
    for p in PARAMS:
        if p[1] == name:
            return p
    raise KeyError(name)


def param_by_id(param_id: int) -> tuple[int, str, int, int, int, str]:
    for p in PARAMS:
        if p[0] == param_id:
            return p
    raise KeyError(param_id)


def _layout(msg_type: int) -> tuple[tuple[str, str, int], ...]:
    for t, _name, fields in LAYOUTS:
        if t == msg_type:
            return fields
    raise ValueError("unknown message type 0x{:02x}".format(msg_type))


_RANGES = {  # struct code -> (minimum, maximum, description)
    "B": (0, 255, "uint8, 0..255"), "b": (-128, 127, "int8, -128..127"),
    "H": (0, 65535, "uint16, 0..65535"), "h": (-32768, 32767, "int16, -32768..32767"),
    "I": (0, 4294967295, "uint32, 0..4294967295"), "i": (-2147483648, 2147483647, "int32, -2147483648..2147483647"),
}


def pack_payload(
    msg_type: int, fields: dict[str, int | str | bytes | tuple[int, ...] | list[int]]
) -> bytes:
    """Fields by name -> payload bytes.  ValueError names the field at fault.

    Ranges are checked here, not left to struct (MicroPython's wraps them).
    """
    layout = _layout(msg_type)
    name = NAMES[msg_type]
    if len(fields) > len(layout):  # with every layout field present (checked below), extras are this
        known = [f[0] for f in layout]
        unknown = [k for k in fields if k not in known]
        raise ValueError("{}: unknown field(s) {}".format(name, ", ".join(sorted(unknown))))
    values: list[int] = []
    text = b""
    for fname, code, count in layout:
        if fname not in fields:
            raise ValueError("{}: missing field '{}'".format(name, fname))
        value = fields[fname]
        if count == 0:
            if isinstance(value, int):
                raise ValueError("{}.{}: expected text, got {!r}".format(name, fname, value))
            text = value.encode() if isinstance(value, str) else bytes(value)
            continue
        lo, hi, what = _RANGES[code]
        if count == 1:
            if not isinstance(value, int):
                raise ValueError("{}.{}: expected an integer, got {!r}".format(name, fname, value))
            if not lo <= value <= hi:
                raise ValueError("{}.{} = {!r} does not fit a '{}' field ({})".format(
                    name, fname, value, code, what))
            values.append(value)
            continue
        if isinstance(value, (int, str, bytes)):
            raise ValueError("{}.{}: expected {} values, got {!r}".format(name, fname, count, value))
        items = list(value)
        if len(items) != count:
            raise ValueError("{}.{}: expected {} values, got {}".format(name, fname, count, len(items)))
        for k, item in enumerate(items):
            if not isinstance(item, int):
                raise ValueError("{}.{}[{}]: expected an integer, got {!r}".format(name, fname, k, item))
            if not lo <= item <= hi:
                raise ValueError("{}.{}[{}] = {!r} does not fit a '{}' field ({})".format(
                    name, fname, k, item, code, what))
        values.extend(items)
    payload = struct.pack(FORMATS[msg_type], *values) + text
    if len(payload) > MAX_PAYLOAD:
        raise ValueError("{}: payload of {} bytes exceeds {}".format(name, len(payload), MAX_PAYLOAD))
    return payload


_PLANS: dict[int, tuple[tuple[str, int, int], ...]] = {}  # type -> ((field, first index, count), ...), built on first use


def _plan(msg_type: int) -> tuple[tuple[str, int, int], ...]:
    plan = _PLANS.get(msg_type)
    if plan is None:
        k = 0
        items = []
        for fname, _code, count in _layout(msg_type):
            items.append((fname, k, count))
            k += count
        plan = tuple(items)
        _PLANS[msg_type] = plan
    return plan


def unpack_payload(msg_type: int, payload: bytes | bytearray | memoryview) -> dict[str, object]:
    """Payload bytes -> fields by name (arrays as tuples).  ValueError if malformed."""
    plan = _plan(msg_type)
    size = PAYLOAD_SIZE[msg_type]
    n = len(payload)
    if n != size and not (msg_type == VARIABLE_TYPE and n >= size):
        raise ValueError("{}: payload of {} bytes, expected {}".format(NAMES[msg_type], n, size))
    flat = struct.unpack_from(FORMATS[msg_type], payload, 0)
    out: dict[str, object] = {}
    for fname, k, count in plan:
        if count == 1:
            out[fname] = flat[k]
        elif count:
            out[fname] = flat[k : k + count]
        else:
            out[fname] = _text(bytes(payload[size:]))
    return out


def _text(data: bytes) -> str:
    """UTF-8 text, bad bytes replaced (MicroPython's decode has no 'replace')."""
    try:
        return data.decode("utf-8")
    except UnicodeError:
        return "".join(chr(b) if b < 0x80 else "\ufffd" for b in data)
