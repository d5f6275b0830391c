"""The robot's main loop: one control cycle after another, on any HAL (docs/firmware.md).

Each cycle: IR acquisition -> encoders -> odometry and wheel speeds -> host messages ->
the mode's wheel setpoints (the fuzzy explorer behind the stall guard, the host's
COMMAND, or zero) -> wheel PI -> current references -> TELEMETRY.  No path allocates once
the robot is built (tests/test_firmware_budgets.py); an exception in a cycle stops the
motors and sets FAULT but never ends the loop.  mpremote's 0x0D 0x03 stops the firmware
only after a whole silent cycle.
"""
import struct

from firmware import config
from firmware.fuzzy import FuzzyController
from firmware.hal import TICK_MASK
from firmware.ir import IRArray
from firmware.odometry import Odometry
from firmware.stall import StallGuard
from firmware.wheels import WheelLoop
from protocol import wire as M
from protocol.compat import const
from protocol.fields import read_i16, read_i31
from protocol.framing import FrameDecoder, FrameEncoder

# Parameter ids (protocol/SPEC.md).
_P_EMITTER = const(1)
_P_AVERAGING = const(2)
_P_WINDOW = const(3)
_P_RULE_SET = const(4)
_P_WATCHDOG = const(5)
_P_CYCLE = const(6)
_P_KP = const(7)
_P_KI = const(8)
_P_ODOMETRY = const(9)
_P_MAX_SPEED = const(10)
_P_CURRENT_LIMIT = const(11)
_P_WHEEL_DIAMETER = const(12)
_P_WHEEL_BASE = const(13)
_P_TICKS_PER_REV = const(14)
_P_STALL = const(15)
_P_PUSH = const(16)
_N_PARAMS = const(17)
_MAX_RX_PER_CYCLE = const(4096)  # bytes a cycle: 100 KB/s at 25 Hz; bounds the cycle time under a flood
_RX_CHUNK = const(32)  # bytes read from the link at a time (heap: tests/test_firmware_budgets.py)
_SATURATED = const(0x3FFFFFFF)  # counters stop at 2**30 - 1: past it every increment would allocate
_MAX_DT_MS = const(2000)  # a longer gap (a stalled board) counts as this much: keeps the PI in range

_TELEMETRY_FMT = "<IBHii8H8HhhHhhiiiB"
_TELEMETRY_SIZE = const(70)
_PARAM_FMT = "<Bi"
_HELLO_FMT = "<6BIIH"
_HELLO_SIZE = const(16)
_NACK_FMT = "<3B"

# The fault LOG names the exception without allocating: names in one blob
# (RAM is scarce), ended by '|', in the order of the classes tried.
_FAULT_CLASSES = (OSError, ZeroDivisionError, IndexError, KeyError, TypeError, ValueError,
                  AttributeError, MemoryError, RuntimeError, Exception)
_FAULT_TEXT = (b"fault # in cycle : OSError|ZeroDivisionError|IndexError|KeyError|TypeError|ValueError|"
               b"AttributeError|MemoryError|RuntimeError|Exception|")


def geometry_defaults() -> tuple[int, int, int]:
    """(wheel diameter um, wheel base um, ticks per turn): robot_geometry.py if the board has
    one (written at flash time), else config's defaults."""
    try:
        import robot_geometry as g  # type: ignore[import-not-found]
    except ImportError:
        g = config
    return (g.WHEEL_DIAMETER_UM, g.WHEEL_BASE_UM, g.TICKS_PER_REV)


class BreakToRepl(Exception):
    """The host asked for the REPL (mpremote's Ctrl-C on the protocol port)."""


class Robot:
    """Firmware state and the control cycle."""

    def __init__(self, hal: object) -> None:
        self.hal = hal
        self.params = [0] * _N_PARAMS
        for pid in range(1, _N_PARAMS):
            self.params[pid] = M.PARAM_LIMITS[3 * pid + 2]
        p = self.params
        geometry = geometry_defaults()
        for k in range(3):
            pid = _P_WHEEL_DIAMETER + k
            lo = M.PARAM_LIMITS[3 * pid]
            hi = M.PARAM_LIMITS[3 * pid + 1]
            if not lo <= geometry[k] <= hi:
                raise ValueError("robot_geometry: parameter {} = {} is outside {}..{}".format(pid, geometry[k], lo, hi))
            p[pid] = geometry[k]
        self.ir = IRArray(hal, p[_P_EMITTER], p[_P_AVERAGING], p[_P_WINDOW])
        self.fuzzy = FuzzyController(p[_P_RULE_SET], p[_P_MAX_SPEED])
        self.stall = StallGuard(p[_P_STALL], p[_P_PUSH], p[_P_MAX_SPEED])
        self.odometry = Odometry(p[_P_WHEEL_DIAMETER], p[_P_WHEEL_BASE], p[_P_TICKS_PER_REV], p[_P_ODOMETRY])
        q8 = self.odometry.um_per_tick_q8
        self.wheel_l = WheelLoop(q8, p[_P_KP], p[_P_KI], p[_P_CURRENT_LIMIT])
        self.wheel_r = WheelLoop(q8, p[_P_KP], p[_P_KI], p[_P_CURRENT_LIMIT])
        self.enc = [0, 0]
        self.mode = M.MODE_STOP
        self.cmd_left = 0
        self.cmd_right = 0
        self.setpoint_l = 0
        self.setpoint_r = 0
        self.tick = 0
        self._last_tick = -1
        self.last_command = 0  # tick of the last valid COMMAND
        self.watchdog_tripped = False
        self.fault_pending = False
        self.faults = 0  # exceptions caught since start
        self.cycles = 0
        self.vbat = 0
        self.flags = 0
        self.tx = FrameEncoder()
        self.rx = FrameDecoder()
        self._rx_one = bytearray(1)
        self._rx_chunk = bytearray(_RX_CHUNK)
        self._digits = bytearray(12)
        # Breaks are honoured only on the USB REPL port, never on a UART.
        self.repl_link = bool(getattr(hal, "repl_link", False))
        self._silent = True  # no byte arrived in the last whole cycle
        self._break_armed = False  # a 0x0D began the first burst after silence

    # -- the cycle -------------------------------------------------------

    def cycle(self) -> None:
        hal = self.hal
        tick = hal.wait_cycle(self.params[_P_CYCLE])  # type: ignore[attr-defined]
        self.tick = tick
        dt = 0 if self._last_tick < 0 else (tick - self._last_tick) & TICK_MASK
        if dt > _MAX_DT_MS:
            dt = _MAX_DT_MS
        self._last_tick = tick
        self.ir.acquire()
        enc = self.enc
        hal.read_encoders(enc)  # type: ignore[attr-defined]
        self.vbat = hal.battery_mv()  # type: ignore[attr-defined]
        self.odometry.update(enc[0], enc[1])
        self.wheel_l.measure(enc[0], dt)
        self.wheel_r.measure(enc[1], dt)
        self.read_host()
        self.decide(dt)
        if self.mode == M.MODE_STOP or self.watchdog_tripped:
            self.wheel_l.reset()
            self.wheel_r.reset()
            il = 0
            ir = 0
        else:
            il = self.wheel_l.control(self.setpoint_l, dt)
            ir = self.wheel_r.control(self.setpoint_r, dt)
        hal.set_currents(il, ir)  # type: ignore[attr-defined]
        self.flags = self.make_flags()
        self.fault_pending = False
        self.send_telemetry(il, ir)
        hal.end_cycle()  # type: ignore[attr-defined]
        if self.cycles < _SATURATED:  # saturates: a counter past 2**30 would allocate every cycle
            self.cycles += 1

    def decide(self, dt: int) -> None:
        mode = self.mode
        if mode == M.MODE_AUTONOMOUS:
            fuzzy = self.fuzzy
            guard = self.stall
            fuzzy.infer(self.ir.value)
            phase = guard.state
            wl = self.wheel_l
            wr = self.wheel_r
            guard.steer(fuzzy.left, fuzzy.right, wl.speed, wr.speed, wl.current, wr.current, dt, self.ir.value)
            if guard.state != phase:
                # The integrals hold the push the guard just ended (wound up to the current limit against
                # the wall): cleared, the back-out reverses the wheels at once instead of unwinding them.
                wl.acc = 0
                wr.acc = 0
            self.setpoint_l = guard.left
            self.setpoint_r = guard.right
            self.watchdog_tripped = False
        elif mode == M.MODE_HOST or mode == M.MODE_TELEOP:
            if (self.tick - self.last_command) & TICK_MASK > self.params[_P_WATCHDOG]:
                self.watchdog_tripped = True
            if self.watchdog_tripped:
                self.setpoint_l = 0
                self.setpoint_r = 0
            else:
                self.setpoint_l = self.cmd_left
                self.setpoint_r = self.cmd_right
        else:
            self.setpoint_l = 0
            self.setpoint_r = 0
            self.watchdog_tripped = False
        if mode != M.MODE_AUTONOMOUS:
            self.stall.reset()

    def make_flags(self) -> int:
        f = 0
        if self.watchdog_tripped:
            f |= M.FLAG_WATCHDOG
        if self.ir.saturated:
            f |= M.FLAG_IR_SATURATED
        if self.hal.overrun:  # type: ignore[attr-defined]
            f |= M.FLAG_OVERRUN
        if self.fault_pending:
            f |= M.FLAG_FAULT
        if self.wheel_l.clamped or self.wheel_r.clamped:
            f |= M.FLAG_CURRENT_LIMIT
        if 0 < self.vbat < config.LOW_BATTERY_MV:
            f |= M.FLAG_LOW_BATTERY
        if self.stall.state:  # not WATCHING: backing out
            f |= M.FLAG_STALL
        return f

    def run(self, cycles: int = -1) -> None:
        """Run cycles forever (or that many); only BreakToRepl ends it."""
        while cycles != 0:
            if cycles > 0:
                cycles -= 1
            try:
                self.cycle()
            except BreakToRepl:
                self.safe_state()
                raise
            except Exception as exc:  # noqa: BLE001 - a robot must keep running
                self.on_fault(exc)

    def safe_state(self) -> None:
        """Motors to zero at once, then STOP."""
        try:
            self.hal.set_currents(0, 0)  # type: ignore[attr-defined]
        except Exception:  # noqa: BLE001
            pass
        self.mode = M.MODE_STOP
        self.setpoint_l = 0
        self.setpoint_r = 0
        self.wheel_l.reset()
        self.wheel_r.reset()

    def on_fault(self, exc: Exception) -> None:
        if self.faults < _SATURATED:
            self.faults += 1
        self.fault_pending = True
        self.safe_state()
        try:
            self.log_fault(exc)
        except Exception:  # noqa: BLE001 - the link itself may be what failed
            pass

    def log_fault(self, exc: Exception) -> None:
        """LOG ERROR "fault #N in cycle C: Name [first int argument]", without allocating."""
        body = self.tx.body
        body[3] = M.LOG_ERROR
        t = _FAULT_TEXT
        k = _put(body, 4, t, 0, 7)  # "fault #"
        k = self._put_int(body, k, self.faults)
        k = _put(body, k, t, 7, 17)  # " in cycle "
        k = self._put_int(body, k, self.cycles)
        k = _put(body, k, t, 17, 19)  # ": "
        start = 19
        for cls in _FAULT_CLASSES:
            end = start
            while t[end] != 0x7C:  # '|'
                end += 1
            if isinstance(exc, cls):
                k = _put(body, k, t, start, end)
                break
            start = end + 1
        args = exc.args
        if len(args) and isinstance(args[0], int) and -1000000000 < args[0] < 1000000000:
            body[k] = 0x20
            k = self._put_int(body, k + 1, args[0])
        self._send(M.LOG, k - 3)

    def _put_int(self, body: bytearray, k: int, value: int) -> int:
        """Decimal digits of value at body[k:]; the end position."""
        if value < 0:
            body[k] = 0x2D
            k += 1
            value = -value
        d = self._digits
        n = 0
        while True:
            d[n] = 0x30 + value % 10
            n += 1
            value //= 10
            if not value:
                break
        while n:
            n -= 1
            body[k] = d[n]
            k += 1
        return k

    # -- host messages ---------------------------------------------------

    def read_host(self) -> None:
        """Take every byte the host sent since the last cycle (at most _MAX_RX_PER_CYCLE), in order.

        Draining the link each cycle lets a STOP or a new COMMAND act on the cycle it arrives in under
        a flood (tests/test_virtual_board.py::test_stop_acts_within_two_periods_under_a_junk_flood).
        On the REPL link, 0x0D 0x03 as the first bytes after a silent cycle is mpremote's break: those
        bytes are read one at a time, so nothing after the break is consumed (the REPL must see the
        Ctrl-A that follows it).  A partial frame that gets no byte for a whole cycle is dropped.
        """
        hal = self.hal
        dec = self.rx
        one = self._rx_one
        watch = self.repl_link and (self._silent or self._break_armed)
        got = 0
        while got < _MAX_RX_PER_CYCLE:
            buf = one if watch else self._rx_chunk
            n = hal.host_read(buf)  # type: ignore[attr-defined]
            if n <= 0:
                break
            if watch:
                if self._break_armed:
                    if one[0] == 0x03:
                        raise BreakToRepl()
                    self._break_armed = False
                    watch = False
                elif got == 0 and one[0] == 0x0D:
                    self._break_armed = True
                else:
                    watch = False
            got += n
            i = 0
            while i < n:
                i = dec.feed(buf, i, n)
                if dec.ready:
                    self.handle(dec.msg_type, dec.seq, dec.body)
        self._silent = not got
        if not got:
            dec.abandon_partial()

    def handle(self, msg_type: int, seq: int, b: bytearray) -> None:
        if msg_type == M.COMMAND:
            mode = b[3]
            if mode > M.MODE_TELEOP:
                self.nack(seq, msg_type, M.ERR_BAD_MODE)
                return
            limit = self.params[_P_MAX_SPEED]
            left = read_i16(b, 4)
            right = read_i16(b, 6)
            self.cmd_left = limit if left > limit else -limit if left < -limit else left
            self.cmd_right = limit if right > limit else -limit if right < -limit else right
            if mode != self.mode:
                self.wheel_l.reset()
                self.wheel_r.reset()
                self.mode = mode
            self.last_command = self.tick
            self.watchdog_tripped = False
        elif msg_type == M.PARAM_SET:
            pid = b[3]
            err = self.set_param(pid, read_i31(b, 4))  # 2**30 and past: out of range, no big int
            if err:
                self.nack(seq, msg_type, err)
            else:
                self.send_param(pid)
        elif msg_type == M.PARAM_GET:
            pid = b[3]
            if 0 < pid < _N_PARAMS:
                self.send_param(pid)
            else:
                self.nack(seq, msg_type, M.ERR_UNKNOWN_PARAM)
        elif msg_type == M.HELLO:
            self.send_hello()
        else:  # TELEMETRY, PARAM_VALUE, ACK, NACK, LOG, HW_*: not for the robot
            self.nack(seq, msg_type, M.ERR_UNSUPPORTED)

    def set_param(self, pid: int, value: int) -> int:
        """Apply a parameter; 0 or a NACK error code."""
        if not 0 < pid < _N_PARAMS:
            return M.ERR_UNKNOWN_PARAM
        limits = M.PARAM_LIMITS
        if not limits[3 * pid] <= value <= limits[3 * pid + 1]:
            return M.ERR_OUT_OF_RANGE
        p = self.params
        p[pid] = value
        if pid == _P_EMITTER or pid == _P_AVERAGING or pid == _P_WINDOW:
            self.ir.configure(p[_P_EMITTER], p[_P_AVERAGING], p[_P_WINDOW])
        elif pid == _P_RULE_SET or pid == _P_MAX_SPEED or pid == _P_STALL or pid == _P_PUSH:
            self.fuzzy.configure(p[_P_RULE_SET], p[_P_MAX_SPEED])
            self.stall.stall_ms = p[_P_STALL]
            self.stall.push_ma = p[_P_PUSH]
            self.stall.max_speed = p[_P_MAX_SPEED]
        elif pid == _P_ODOMETRY:
            self.odometry.method = value
        elif pid == _P_KP or pid == _P_KI or pid == _P_CURRENT_LIMIT:
            for k in range(2):
                w = self.wheel_r if k else self.wheel_l
                w.kp = p[_P_KP]
                w.ki = p[_P_KI]
                w.limit = p[_P_CURRENT_LIMIT]
        elif _P_WHEEL_DIAMETER <= pid <= _P_TICKS_PER_REV:
            odo = self.odometry
            odo.configure(p[_P_WHEEL_DIAMETER], p[_P_WHEEL_BASE], p[_P_TICKS_PER_REV])
            self.wheel_l.um_per_tick_q8 = odo.um_per_tick_q8
            self.wheel_r.um_per_tick_q8 = odo.um_per_tick_q8
        return 0

    # -- frames to the host ----------------------------------------------

    def _send(self, msg_type: int, payload_len: int) -> None:
        n = self.tx.finish(msg_type, payload_len)
        self.hal.host_write(self.tx.frame, n)  # type: ignore[attr-defined]

    def send_telemetry(self, il: int, ir: int) -> None:
        on = self.ir.on
        am = self.ir.ambient
        enc = self.enc
        odo = self.odometry
        struct.pack_into(
            _TELEMETRY_FMT, self.tx.body, 3, self.tick, self.mode, self.flags, enc[0], enc[1],
            on[0], on[1], on[2], on[3], on[4], on[5], on[6], on[7],
            am[0], am[1], am[2], am[3], am[4], am[5], am[6], am[7],
            il, ir, self.vbat, self.setpoint_l, self.setpoint_r,
            odo.x_um, odo.y_um, odo.heading, self.ir.power)
        self._send(M.TELEMETRY, _TELEMETRY_SIZE)

    def send_param(self, pid: int) -> None:
        struct.pack_into(_PARAM_FMT, self.tx.body, 3, pid, self.params[pid])
        self._send(M.PARAM_VALUE, 5)

    def send_hello(self) -> None:
        v = config.FIRMWARE_VERSION
        p = self.params
        struct.pack_into(_HELLO_FMT, self.tx.body, 3, M.PROTOCOL_VERSION, v[0], v[1], v[2],
                         self.hal.board, 8, p[_P_WHEEL_DIAMETER], p[_P_WHEEL_BASE],  # type: ignore[attr-defined]
                         p[_P_TICKS_PER_REV])
        self._send(M.HELLO, _HELLO_SIZE)

    def nack(self, seq: int, msg_type: int, error: int) -> None:
        struct.pack_into(_NACK_FMT, self.tx.body, 3, seq, msg_type, error)
        self._send(M.NACK, 3)


def _put(body: bytearray, k: int, src: bytes, start: int, end: int) -> int:
    """Copy src[start:end] to body[k:]; the end position (no slice: no allocation)."""
    for i in range(start, end):
        body[k] = src[i]
        k += 1
    return k
