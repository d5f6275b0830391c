"""The virtual board's HAL: its electrical I/O travels to a simulator.

Runs under the MicroPython unix port.  Each control cycle begins when the
simulator's HW_SENSE frame arrives (ADC readings with the emitters off and
on, encoder counts, battery) and ends by sending HW_ACTUATE (current
references, emitter power) back, over a TCP connection to 127.0.0.1.
The simulator thus owns time: in fixed-step mode a run is exactly
repeatable.  The host link is the board's stdin/stdout, as on the RP2040.
"""
import socket
import struct

from firmware.hal import TICK_MASK, Hal
from firmware.hostlink import StdioLink
from protocol import wire
from protocol.framing import FrameDecoder, FrameEncoder

_ACTUATE_FMT = "<IhhB"


def _u16(b: bytearray, o: int) -> int:
    return b[o] | (b[o + 1] << 8)


def _i32(b: bytearray, o: int) -> int:
    hi = b[o + 3]
    if hi & 0x80:
        hi -= 256
    return (hi << 24) | (b[o + 2] << 16) | (b[o + 1] << 8) | b[o]


class HardwareGone(SystemExit):
    """The simulator closed the hardware link: the board powers off."""


class VirtualHal(Hal):
    board = wire.BOARD_VIRTUAL

    def __init__(self, host: str, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.connect(socket.getaddrinfo(host, port)[0][-1])
        self.link = StdioLink()
        self.tx = FrameEncoder()
        self.rx = FrameDecoder()
        self._buf = bytearray(128)
        self._n = 0
        self._i = 0
        self.tick = 0
        self.adc_off = [0] * 8
        self.adc_on = [0] * 8
        self.enc = [0, 0]
        self.vbat = 0
        self.emitters = 0
        self.power_used = 0  # emitter power of this cycle's "on" reading
        self.i_left = 0
        self.i_right = 0
        self.overrun = False

    def wait_cycle(self, period_ms: int) -> int:
        dec = self.rx
        buf = self._buf
        while True:
            if self._i >= self._n:
                got = self.sock.readinto(buf)
                if not got:
                    raise HardwareGone()
                self._n = got
                self._i = 0
            self._i = dec.feed(buf, self._i, self._n)
            if dec.ready and dec.msg_type == wire.HW_SENSE:
                self.power_used = 0
                b = dec.body
                self.tick = _i32(b, 3) & TICK_MASK
                for k in range(8):
                    self.adc_off[k] = _u16(b, 7 + 2 * k)
                    self.adc_on[k] = _u16(b, 23 + 2 * k)
                self.enc[0] = _i32(b, 39)
                self.enc[1] = _i32(b, 43)
                self.vbat = _u16(b, 47)
                return self.tick

    def set_emitters(self, pct: int) -> None:
        self.emitters = pct

    def read_ir(self, out: list[int]) -> None:
        src = self.adc_off
        if self.emitters:
            src = self.adc_on
            self.power_used = self.emitters
        for k in range(8):
            out[k] = src[k]

    def read_encoders(self, out: list[int]) -> None:
        out[0] = self.enc[0]
        out[1] = self.enc[1]

    def battery_mv(self) -> int:
        return self.vbat

    def set_currents(self, left_ma: int, right_ma: int) -> None:
        self.i_left = left_ma
        self.i_right = right_ma

    def host_read(self, buf: bytearray) -> int:
        return self.link.read(buf)

    def host_write(self, data: memoryview) -> None:
        self.link.write(data)

    def close(self) -> None:
        self.sock.close()

    def end_cycle(self) -> None:
        """Send HW_ACTUATE: the currents and the emitter power this cycle used.

        The simulator computes the next HW_SENSE's "on" readings at that
        power, so a change of L shows one cycle later.
        """
        struct.pack_into(_ACTUATE_FMT, self.tx.body, 3, self.tick, self.i_left, self.i_right, self.power_used)
        n = self.tx.finish(wire.HW_ACTUATE, 9)
        self.sock.write(self.tx.view(n))
