"""Wheel-speed loops: encoder ticks -> speed -> PI -> current reference.

The paper's motor driver regulates current, so the loop's output is a
current reference.  Each wheel has a PI with a clamped output and two
anti-windup measures: integration stops while the output is saturated in
the direction of the error, and the integral is clamped so that its term
alone can never exceed the current limit.  All in integers:

    v    [mm/s]  = dticks * um_per_tick / dt_ms, rounded
    e    [mm/s]  = setpoint - v
    P    [mA]    = kp * e / 1000                  (kp: 1/1000 mA per mm/s)
    acc  [um]   += e * dt_ms
    I    [mA]    = ki * acc / 1_000_000           (ki: 1/1000 mA per mm)
    iref [mA]    = clamp(P + I, -limit, +limit)
"""


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
        d = ticks - self._last
        self._last = ticks
        den = dt_ms << 8
        self.speed = (2 * d * self.um_per_tick_q8 + den) // (2 * den)

    def control(self, setpoint: int, dt_ms: int) -> int:
        """PI step towards setpoint (mm/s); returns the current reference, mA."""
        self.setpoint = setpoint
        e = setpoint - self.speed
        limit = self.limit
        p = (self.kp * e) // 1000
        acc = self.acc + e * dt_ms
        ki = self.ki
        if ki:
            acc_max = (limit * 1000000) // ki
            if acc > acc_max:
                acc = acc_max
            elif acc < -acc_max:
                acc = -acc_max
            i_term = (ki * acc) // 1000000
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
