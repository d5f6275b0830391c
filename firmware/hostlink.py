"""The host link over the board's USB serial port (sys.stdin / sys.stdout; docs/firmware.md).

The same code on the RP2040 (USB CDC) and on the virtual board (stdin/stdout wired to a
pseudo-terminal).  Reads never block and, like writes, allocate nothing.  Ctrl-C must reach
the protocol as a byte, so keyboard interrupts are off while the firmware runs.
"""
import select
import sys

import micropython


class StdioLink:
    def __init__(self) -> None:
        self._in = sys.stdin.buffer
        self._out = sys.stdout.buffer
        self._poll = select.poll()
        self._poll.register(sys.stdin, select.POLLIN)
        self._one = bytearray(1)
        self.closed = False  # the host side hung up (virtual board only)

    def open(self) -> None:
        micropython.kbd_intr(-1)

    def close(self) -> None:
        micropython.kbd_intr(3)

    def read(self, buf: bytearray) -> int:
        """Copy up to len(buf) waiting bytes into buf; return the count."""
        n = 0
        one = self._one
        cap = len(buf)
        while n < cap:
            ready = False
            for _obj, event in self._poll.ipoll(0):
                if event & (select.POLLHUP | select.POLLERR):
                    self.closed = True
                if event & select.POLLIN:
                    ready = True
            # One byte at a time: on bare-metal ports a longer read blocks
            # until the buffer is full.
            if not ready or not self._in.readinto(one):
                return n
            buf[n] = one[0]
            n += 1
        return n

    def write(self, buf: bytearray, n: int) -> None:
        self._out.write(buf, n)


class UartLink:
    """The host link over a UART (a radio module, a USB-serial adapter)."""

    def __init__(self, uart_id: int, tx: int, rx: int, baudrate: int) -> None:
        from machine import UART, Pin

        self.uart = UART(uart_id, baudrate=baudrate, tx=Pin(tx), rx=Pin(rx), rxbuf=1024)
        self.closed = False

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def read(self, buf: bytearray) -> int:
        n = self.uart.readinto(buf)
        return n if n else 0

    def write(self, buf: bytearray, n: int) -> None:
        self.uart.write(buf, n)  # type: ignore[call-arg]  # streams take (buf, max_len); the stubs do not say
