"""Dead reckoning from the wheel encoders: Euler, midpoint or exact arc, in integers (docs/firmware.md).

Position in micrometres, heading in 1/2**30 turn (wrapped, so it stays a small int on
32-bit boards); the heading is a sum of exact integer steps, so it does not drift by
rounding, and every port gives the same pose bit for bit.  Every intermediate stays
within +-2**30 for a step under 2 m and a pose within 1 km of the origin, and configure()
allocates nothing (tests/test_micropython_32bit.py).
"""
from firmware.hal import count_delta
from firmware.trig import cos_q14, sin_q14, sinc_q14
from protocol.compat import const

EULER = const(0)
MIDPOINT = const(1)
EXACT = const(2)

HEADING_TURN = 1 << 30  # heading units per turn (a big int on 32-bit ports: not used per cycle)
HEADING_MASK = const(0x3FFFFFFF)
_HALF = const(0x20000000)  # half a turn
_POS_WRAP = const(0x20000000)  # um: x and y wrap at +-2**29
_PI_NUM = const(355)  # pi ~ 355/113, error 8.5e-8
_PI_DEN = const(113)


class Odometry:
    """Pose (x_um, y_um, heading) from cumulative encoder ticks; no allocation per update."""

    def __init__(self, wheel_diameter_um: int, wheel_base_um: int, ticks_per_rev: int, method: int = EXACT) -> None:
        self.um_per_tick_q8 = 0
        self.heading_per_tick = 0
        self.configure(wheel_diameter_um, wheel_base_um, ticks_per_rev)
        self.method = method
        self.x_um = 0
        self.y_um = 0
        self.heading = 0
        self._last_l = 0
        self._last_r = 0
        self._started = False

    def configure(self, wheel_diameter_um: int, wheel_base_um: int, ticks_per_rev: int) -> None:
        """Set the geometry (diameter up to 2**21 um, base up to 2**21 um, ticks per turn up to 2**16)."""
        # micrometres per tick, Q8: pi * D * 256 / TPR
        self.um_per_tick_q8 = div_round(_PI_NUM * wheel_diameter_um, 8, _PI_DEN, ticks_per_rev)
        # heading units per tick of difference (dR - dL): D / (2 * TPR * W) of a turn
        self.heading_per_tick = div_round(wheel_diameter_um, 29, ticks_per_rev, wheel_base_um)
        # the largest |dR - dL| whose turn stays below half a turn (then dth is a small int)
        self._dd_max = (_HALF - 1) // self.heading_per_tick if self.heading_per_tick else HEADING_MASK

    def reset(self, x_um: int = 0, y_um: int = 0, heading: int = 0) -> None:
        self.x_um = x_um
        self.y_um = y_um
        self.heading = heading & HEADING_MASK
        self._started = False

    def update(self, enc_l: int, enc_r: int) -> None:
        if not self._started:
            self._last_l = enc_l
            self._last_r = enc_r
            self._started = True
            return
        dl = count_delta(enc_l, self._last_l)
        dr = count_delta(enc_r, self._last_r)
        self._last_l = enc_l
        self._last_r = enc_r
        self.step(dl, dr)

    def step(self, dl: int, dr: int) -> None:
        """Advance by dl, dr encoder ticks."""
        q8 = self.um_per_tick_q8
        s = ((dl + dr) * q8 + 256) >> 9  # centre distance, um (rounded)
        dd = dr - dl
        hpt = self.heading_per_tick
        th = self.heading
        method = self.method
        if method == EULER:
            a = th >> 14  # binary angle, 65536 per turn
        else:
            # (th + dth/2) >> 14 modulo a turn, with dth/2 = dd * (hpt >> 1) + (dd >> 1) if hpt is odd;
            # both terms taken around the half turn to stay below 2**30
            half = mulmod_turn(dd, hpt >> 1)
            if hpt & 1:
                half = _add_turn(half, (dd >> 1) & HEADING_MASK)
            a = ((th - _HALF) + (half - _HALF)) >> 14
            if method == EXACT and dd and -self._dd_max <= dd <= self._dd_max:
                s = mul_q14(s, sinc_q14((dd * hpt) >> 7))
        self.x_um = _wrap_position(self.x_um + mul_q14(s, cos_q14(a)))
        self.y_um = _wrap_position(self.y_um + mul_q14(s, sin_q14(a)))
        self.heading = _add_turn(th, mulmod_turn(dd, hpt))


def _wrap_position(v: int) -> int:
    """x or y in um, wrapped into [-2**29, 2**29) (+-536.870912 m) alike on every interpreter: a step
    moves far less than 2**29 um, so no value passes 2**30 (tests/mp/counters_check.py)."""
    if v >= _POS_WRAP:
        return v - _POS_WRAP - _POS_WRAP
    if v < -_POS_WRAP:
        return v + _POS_WRAP + _POS_WRAP
    return v


def _add_turn(a: int, b: int) -> int:
    """(a + b) mod 2**30 for a, b in [0, 2**30), without passing 2**30."""
    h = (a - _HALF) + (b - _HALF)
    return h if h >= 0 else h + _HALF + _HALF


def mulmod_turn(d: int, f: int) -> int:
    """(d * f) mod 2**30 for |d| < 2**30 and 0 <= f < 2**30, every intermediate below 2**30.

    With d = dh * 2**15 + dl and f = fh * 2**15 + fl (15-bit digits), the
    dh * fh * 2**30 term vanishes modulo 2**30."""
    neg = d < 0
    if neg:
        d = -d
    dh = d >> 15
    dl = d & 0x7FFF
    fh = f >> 15
    fl = f & 0x7FFF
    mid = (((dl * fh) & 0x7FFF) + ((dh * fl) & 0x7FFF)) & 0x7FFF
    r = _add_turn(mid << 15, dl * fl)
    return HEADING_MASK - r + 1 if neg and r else r


def mul_q14(s: int, c: int) -> int:
    """(s * c + 8192) >> 14 for |c| <= 2**14, exactly, without a product beyond 2**30."""
    return (s >> 14) * c + (((s & 16383) * c + 8192) >> 14)


def div_round(x: int, shift: int, m1: int, m2: int) -> int:
    """round(x * 2**shift / (m1 * m2)), half up, with every intermediate a small int.

    x >= 0 below 2**30, m1 and m2 >= 1 below 2**29, result below 2**30.  Long
    division one bit at a time; the remainder is kept as a * m2 + b (a < m1,
    b < m2) so that the product m1 * m2 is never formed.
    """
    q = 0
    a = 0
    b = 0
    nbits = 0
    v = x
    while v:
        nbits += 1
        v >>= 1
    for k in range(nbits + shift - 1, -1, -1):
        bit = (x >> (k - shift)) & 1 if k >= shift else 0
        b = 2 * b + bit
        a = 2 * a
        if b >= m2:
            b -= m2
            a += 1
        q = 2 * q
        if a >= m1:
            a -= m1
            q += 1
    # round half up: add one if 2 * remainder >= m1 * m2
    b = 2 * b
    a = 2 * a
    if b >= m2:
        a += 1
    return q + 1 if a >= m1 else q
