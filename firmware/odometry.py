"""Dead reckoning from the wheel encoders: three approximations, in integers.

Per cycle the wheels move dL, dR; the centre moves s = (dL + dR) / 2 and
turns dth = (dR - dL) / W.  The approximations differ in the heading the
step is taken along:

    EULER     x += s cos(th)                   (heading at the start)
    MIDPOINT  x += s cos(th + dth/2)           (second order)
    EXACT     x += s sinc(dth/2) cos(th + dth/2)   (the arc's chord: exact
              for a constant-curvature step)

Position in micrometres, heading in 1/2**30 turn (wrapped, so it stays a
small int on 32-bit boards); the heading is a sum of exact integer steps, so
it does not drift by rounding.  Every port gives the same pose bit for bit.
"""
from firmware.trig import cos_q14, sin_q14, sinc_q14
from protocol.compat import const

EULER = const(0)
MIDPOINT = const(1)
EXACT = const(2)

HEADING_TURN = const(1 << 30)  # heading units per turn
_PI_NUM = const(355)  # pi ~ 355/113, error 8.5e-8
_PI_DEN = const(113)


class Odometry:
    """Pose (x_um, y_um, heading) from cumulative encoder ticks; no allocation per update."""

    def __init__(self, wheel_diameter_um: int, wheel_base_um: int, ticks_per_rev: int, method: int = EXACT) -> None:
        # micrometres per tick, Q8
        self.um_per_tick_q8 = (_PI_NUM * wheel_diameter_um * 256 + _PI_DEN * ticks_per_rev // 2) // (
            _PI_DEN * ticks_per_rev)
        # heading units per tick of difference (dR - dL): D / (2 * TPR * W) of a turn
        self.heading_per_tick = ((wheel_diameter_um << 30) + ticks_per_rev * wheel_base_um) // (
            2 * ticks_per_rev * wheel_base_um)
        self.method = method
        self.x_um = 0
        self.y_um = 0
        self.heading = 0
        self._last_l = 0
        self._last_r = 0
        self._started = False

    def reset(self, x_um: int = 0, y_um: int = 0, heading: int = 0) -> None:
        self.x_um = x_um
        self.y_um = y_um
        self.heading = heading & (HEADING_TURN - 1)
        self._started = False

    def update(self, enc_l: int, enc_r: int) -> None:
        if not self._started:
            self._last_l = enc_l
            self._last_r = enc_r
            self._started = True
            return
        dl = enc_l - self._last_l
        dr = enc_r - self._last_r
        self._last_l = enc_l
        self._last_r = enc_r
        self.step(dl, dr)

    def step(self, dl: int, dr: int) -> None:
        """Advance by dl, dr encoder ticks."""
        q8 = self.um_per_tick_q8
        s = ((dl + dr) * q8 + 256) >> 9  # centre distance, um (rounded)
        dth = (dr - dl) * self.heading_per_tick
        th = self.heading
        method = self.method
        if method == EULER:
            a = th >> 14  # binary angle, 65536 per turn
        else:
            a = (th + (dth >> 1)) >> 14
            if method == EXACT and dth:
                s = (s * sinc_q14(dth >> 7) + 8192) >> 14
        self.x_um += (s * cos_q14(a) + 8192) >> 14
        self.y_um += (s * sin_q14(a) + 8192) >> 14
        self.heading = (th + dth) & (HEADING_TURN - 1)
