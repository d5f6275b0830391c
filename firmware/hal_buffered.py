"""A HAL fed one cycle at a time with what a simulator sensed (docs/firmware.md).

A HW_SENSE frame's values (tick, ADC readings with emitters off and on, encoder counts,
battery) are loaded before each cycle; the outputs are collected as a HW_ACTUATE.  The
virtual board (hal_sim_link.SimLinkHal) moves them as frames, the simulator's SIL mode
in-process: both share this class, so SIL and PIL behave the same bit for bit.
"""
from firmware.hal import Hal
from protocol import wire


class BufferedHal(Hal):
    board = wire.BOARD_VIRTUAL

    def __init__(self) -> None:
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

    def begin(self) -> None:
        """A new cycle's readings are loaded."""
        self.power_used = 0

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
