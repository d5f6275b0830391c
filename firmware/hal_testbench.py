"""A board for tests and benchmarks: a HAL with a plain plant, on CPython and MicroPython alike.

IR: ambient + reflection * emitter power / 100, capped at the ADC ceiling.  Wheels: a
crude motor, 2 mA a tick a cycle (110 mm/s takes some 80 mA, as a free-running wheel,
never the stall guard's push current).  Host link: bytes queued with give(), frames sent
collected in `out`.  No method allocates once the buffers exist (docs/firmware.md, Budgets).
"""
from firmware.hal import TICK_MASK


class TestHal:
    board = 2  # BOARD_VIRTUAL
    overrun = False
    repl_link = True  # as the USB port; a test sets False for a UART

    def __init__(self, in_size: int = 2048, out_size: int = 8192) -> None:
        self.t = 0
        self.emitters = 0
        self.ambient = [100] * 8
        self.reflection = [0] * 8  # at 100 % emitter power
        self.encs = [0, 0]
        self.current = [0, 0]
        self.inbox = bytearray(in_size)
        self.in_len = 0
        self.in_pos = 0
        self.out = bytearray(out_size)
        self.out_len = 0
        self.vbat = 7400

    def wait_cycle(self, period: int) -> int:
        self.t += period
        return self.t & TICK_MASK

    def set_emitters(self, pct: int) -> None:
        self.emitters = pct

    def read_ir(self, out: list[int]) -> None:
        # Attributes read once into locals: the bench's cycle counts this HAL's own bytecodes too.
        ambient, reflection, emitters = self.ambient, self.reflection, self.emitters
        for i in range(8):
            v = ambient[i] + (reflection[i] * emitters) // 100
            out[i] = v if v < 4095 else 4095

    def read_encoders(self, out: list[int]) -> None:
        out[0] = self.encs[0]
        out[1] = self.encs[1]

    def battery_mv(self) -> int:
        return self.vbat

    def set_currents(self, left: int, right: int) -> None:
        self.current[0] = left
        self.current[1] = right
        self.encs[0] += left // 2
        self.encs[1] += right // 2

    def host_read(self, buf: bytearray) -> int:
        n = self.in_len - self.in_pos
        if n > len(buf):
            n = len(buf)
        for k in range(n):
            buf[k] = self.inbox[self.in_pos + k]
        self.in_pos += n
        return n

    def host_write(self, data: bytearray, n: int) -> None:
        if self.out_len + n > len(self.out):
            self.out_len = 0  # keep the newest frames
        out = self.out
        base = self.out_len
        for k in range(n):
            out[base + k] = data[k]
        self.out_len = base + n

    def end_cycle(self) -> None:
        pass

    def close(self) -> None:
        pass

    def give(self, data: bytes) -> None:
        """Queue bytes from the host (appended to what is still unread)."""
        rest = self.in_len - self.in_pos
        for k in range(rest):
            self.inbox[k] = self.inbox[self.in_pos + k]
        for k in range(len(data)):
            self.inbox[rest + k] = data[k]
        self.in_pos = 0
        self.in_len = rest + len(data)

    def take_output(self) -> bytes:
        data = bytes(self.out[:self.out_len])
        self.out_len = 0
        return data
