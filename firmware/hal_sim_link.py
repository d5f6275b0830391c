"""The virtual board's HAL: its electrical I/O travels to a simulator (docs/firmware.md).

Runs under the MicroPython unix port.  Each control cycle begins when the simulator's
HW_SENSE frame arrives over TCP on 127.0.0.1 and ends by sending HW_ACTUATE back, so the
simulator owns time and a fixed-step run is exactly repeatable.  The host link is the
board's stdin/stdout, as on the RP2040.
"""
import select
import socket
import struct

from firmware.hal_buffered import BufferedHal
from firmware.hostlink import StdioLink
from protocol import wire
from protocol.fields import read_u16, read_u30, read_wrap30
from protocol.framing import FrameDecoder, FrameEncoder

_ACTUATE_FMT = "<IhhB"


class HardwareGone(SystemExit):
    """The simulator closed the hardware link: the board powers off."""


class SimLinkHal(BufferedHal):
    """BufferedHal whose readings arrive as HW_SENSE frames and whose outputs leave as HW_ACTUATE.

    Its host link is stdin/stdout, the board's REPL port.  Its watchdog is on
    the simulator's side (host_sim/board/pil.py): HW_ACTUATE overdue, motors off."""

    repl_link = True

    def __init__(self, host: str, port: int) -> None:
        BufferedHal.__init__(self)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.connect(socket.getaddrinfo(host, port)[0][-1])
        # Non-blocking, waited on with poll: a blocking readinto() would wait
        # until its whole buffer is full, not for one frame.
        self.sock.setblocking(False)
        self._poll = select.poll()
        self._poll.register(self.sock, select.POLLIN)
        self.link = StdioLink()
        self.tx = FrameEncoder()
        self.rx = FrameDecoder()
        self._buf = bytearray(128)
        self._n = 0
        self._i = 0

    def wait_cycle(self, period_ms: int) -> int:
        dec = self.rx
        buf = self._buf
        while True:
            if self._i >= self._n:
                for _obj, _event in self._poll.ipoll(-1):
                    pass
                try:
                    got = self.sock.readinto(buf)
                except OSError:
                    got = 0
                if got is None:  # woken without data
                    continue
                if not got:
                    raise HardwareGone()
                self._n = got
                self._i = 0
            self._i = dec.feed(buf, self._i, self._n)
            if dec.ready and dec.msg_type == wire.HW_SENSE:
                self.begin()
                b = dec.body
                self.tick = read_u30(b, 3)  # the clock modulo 2**30 (firmware/hal.py TICK_MASK)
                for k in range(8):
                    self.adc_off[k] = read_u16(b, 7 + 2 * k)
                    self.adc_on[k] = read_u16(b, 23 + 2 * k)
                self.enc[0] = read_wrap30(b, 39)  # counts wrap in [-2**29, 2**29), as the RP2040 HAL's
                self.enc[1] = read_wrap30(b, 43)
                self.vbat = read_u16(b, 47)
                return self.tick

    def host_read(self, buf: bytearray) -> int:
        return self.link.read(buf)

    def host_write(self, buf: bytearray, n: int) -> None:
        self.link.write(buf, n)

    def close(self) -> None:
        self.sock.close()

    def end_cycle(self) -> None:
        """Send HW_ACTUATE: the currents and the emitter power this cycle used.

        The simulator computes the next HW_SENSE's "on" readings at that
        power, so a change of L shows one cycle later.
        """
        struct.pack_into(_ACTUATE_FMT, self.tx.body, 3, self.tick, self.i_left, self.i_right, self.power_used)
        n = self.tx.finish(wire.HW_ACTUATE, 9)
        self.sock.write(self.tx.frame, n)  # type: ignore[call-arg]  # streams take (buf, max_len)
