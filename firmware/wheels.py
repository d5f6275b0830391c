"""Wheel-speed loops: encoder ticks -> speed -> PI -> current reference, in integers (docs/firmware.md).

The paper's motor driver regulates current, so each wheel's PI gives a current reference,
clamped, with two anti-windup measures: integration stops while the output is saturated
in the error's direction, and the integral is capped (ACC_CAP) so that its term alone
stays under the current limit.  Every product stays within +-2**30 for every parameter
in its range (tests/test_micropython_32bit.py).
"""
from firmware.hal import count_delta
from protocol.compat import const

E_MAX = const(10000)  # mm/s: speed errors beyond are clamped (10 m/s)
ACC_CAP = const(0x20000000)  # um: the integral's bound whatever ki



class WheelLoop:
    """One wheel's speed estimate and PI; update() allocates nothing."""

    def __init__(self, um_per_tick_q8: int, kp: int, ki: int, limit_ma: int) -> None:
        self.um_per_tick_q8 = um_per_tick_q8
        self.kp = kp
        self.ki = ki
        self.limit = limit_ma
        self.speed = 0  # measured, mm/s
        self.setpoint = 0  # mm/s
        self.acc = 0  # integral of the error, um
        self.current = 0  # reference out, mA
        self.clamped = False
        self._last = 0
        self._started = False

    def reset(self) -> None:
        self.acc = 0
        self.current = 0
        self.speed = 0
        self._started = False

    def measure(self, ticks: int, dt_ms: int) -> None:
        if not self._started or dt_ms <= 0:
            self._last = ticks
            self._started = True
            self.speed = 0
            return
        d = count_delta(ticks, self._last)
        self._last = ticks
        # round(d * q8 / (256 * dt)), half up, with q8 = qh * 256 + ql split
        q8 = self.um_per_tick_q8
        self.speed = (2 * d * (q8 >> 8) + dt_ms + ((2 * d * (q8 & 255)) >> 8)) // (2 * dt_ms)

    def control(self, setpoint: int, dt_ms: int) -> int:
        """PI step towards setpoint (mm/s); returns the current reference, mA."""
        self.setpoint = setpoint
        e = setpoint - self.speed
        if e > E_MAX:
            e = E_MAX
        elif e < -E_MAX:
            e = -E_MAX
        limit = self.limit
        p = (self.kp * e) // 1000
        acc = self.acc + e * dt_ms
        ki = self.ki
        if ki:
            # floor(limit * 10**6 / ki) in two steps, capped at ACC_CAP
            q = (limit * 1000) // ki
            acc_max = ACC_CAP
            if q < ACC_CAP // 1000:
                acc_max = q * 1000 + ((limit * 1000 - q * ki) * 1000) // ki
            if acc_max > ACC_CAP:
                acc_max = ACC_CAP
            if acc > acc_max:
                acc = acc_max
            elif acc < -acc_max:
                acc = -acc_max
            # floor(ki * acc / 10**6), with acc = hi * 1000 + lo
            i_term = (ki * (acc // 1000) + (ki * (acc % 1000)) // 1000) // 1000
        else:
            acc = 0
            i_term = 0
        out = p + i_term
        clamped = False
        if out > limit:
            out = limit
            clamped = True
        elif out < -limit:
            out = -limit
            clamped = True
        # Conditional integration: keep the old integral if it would push
        # further into saturation.
        if not (clamped and (e > 0) == (out > 0)):
            self.acc = acc
        self.clamped = clamped
        self.current = out
        return out
