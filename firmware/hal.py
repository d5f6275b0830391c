"""The hardware abstraction layer: all that the firmware asks of a board (docs/firmware.md).

Implemented by hal_rp2040.Rp2040Hal (the robot), hal_sim_link.SimLinkHal (the virtual
board, whose electrical I/O travels as HW_SENSE / HW_ACTUATE frames to a simulator) and,
in-process, the simulator's SIL mode; the firmware cannot tell them apart.  Every method
is called once or twice per control cycle and must not allocate on the heap.
"""
from protocol.compat import const

TICK_MASK = const(0x3FFFFFFF)  # clocks wrap modulo 2**30 ms, as MicroPython's ticks_ms
_HALF_WRAP = const(0x20000000)


def count_delta(new: int, old: int) -> int:
    """new - old for encoder counts that may wrap within [-2**29, 2**29) (the RP2040 HAL's)."""
    d = new - old
    if d >= _HALF_WRAP:
        d = d - _HALF_WRAP - _HALF_WRAP
    elif d < -_HALF_WRAP:
        d = d + _HALF_WRAP + _HALF_WRAP
    return d


class Hal:
    """Interface, with the units every implementation uses."""

    board = 0  # protocol.messages.BOARD_* kind, reported in HELLO
    overrun = False  # set by wait_cycle when the last cycle overran its period
    repl_link = False  # the host link is the USB REPL port (mpremote may break in)

    def wait_cycle(self, period_ms: int) -> int:
        """Block until the next control cycle starts; return its tick, ms (mod 2**30).

        A board with a hardware watchdog feeds it here: a loop that stalls
        stops being fed and the watchdog stops the motors."""
        raise NotImplementedError

    def set_emitters(self, pct: int) -> None:
        """IR emitter pulse width in % (0 = off)."""
        raise NotImplementedError

    def read_ir(self, out: list[int]) -> None:
        """Write the 8 phototransistor ADC counts (12-bit) into out[0..7]."""
        raise NotImplementedError

    def read_encoders(self, out: list[int]) -> None:
        """Write the cumulative encoder ticks: out[0] left, out[1] right."""
        raise NotImplementedError

    def battery_mv(self) -> int:
        raise NotImplementedError

    def set_currents(self, left_ma: int, right_ma: int) -> None:
        """Current references for the motor drivers, mA (sign = direction)."""
        raise NotImplementedError

    def host_read(self, buf: bytearray) -> int:
        """Copy what the host sent into buf without blocking; return the count."""
        raise NotImplementedError

    def host_write(self, buf: bytearray, n: int) -> None:
        """Send buf[:n] to the host (MicroPython streams: write(buf, n), no allocation)."""
        raise NotImplementedError

    def end_cycle(self) -> None:
        """The cycle's outputs are set (the virtual board sends HW_ACTUATE here)."""
        raise NotImplementedError

    def close(self) -> None:
        """The firmware stops: outputs off, links released."""
