"""The plant's H-bridge: sign-magnitude PWM from the battery into a motor winding (R, L, back-EMF), solved exactly.

Each PWM cycle is a chain of exponentials: the on-phase across the battery, then the off-phase braking on the
low sides (slow decay) or coasting back through the diodes until the current dies (fast decay).  The plant
steps it cycle by cycle within each MuJoCo step.  docs/proving-ground.md, "Drives".
"""
from __future__ import annotations

import math

SETTLED = 1e-9  # A: a cycle ending where it began repeats itself to the end of the step
MAX_PIECES = 4  # an off-phase has at most a conducting piece, a zero crossing, then a generating piece


def after_deadband(duty: float, deadband: float) -> float:
    """The duty the bridge delivers for a commanded one: clipped to [-1, 1], the deadband taken off and the
    rest stretched back over [0, 1]."""
    m = min(abs(duty), 1.0)
    m = max(m - deadband, 0.0) / (1.0 - deadband)
    return -m if duty < 0 else m


def _piece(i0: float, target: float, tau: float, span: float) -> tuple[float, float]:
    """(current at the end, charge) of the winding relaxing from i0 towards target for span seconds."""
    if tau <= 0.0:
        return target, target * span
    decay = math.exp(-span / tau)
    return target + (i0 - target) * decay, target * span + (i0 - target) * tau * (1.0 - decay)


def _to_zero(i0: float, target: float, tau: float) -> float:
    """Seconds until a current relaxing from i0 towards target of the other sign reaches 0 (inf if it never)."""
    if i0 == 0.0 or target == 0.0 or (i0 > 0.0) == (target > 0.0):
        return math.inf
    return tau * math.log((i0 - target) / -target) if tau > 0.0 else 0.0


def _coast(i: float, emf: float, volts: float, res: float, tau: float, span: float) -> tuple[float, float, float]:
    """The off-phase with every switch off: (end current, charge through the motor, charge into the battery).
    A current flows back through the diodes against the supply until it dies; then the terminals show the
    back-EMF, unless that exceeds the supply and the motor generates through the diodes."""
    charge = battery = 0.0
    for _ in range(MAX_PIECES):
        if span <= 0.0:
            break
        if i == 0.0 and abs(emf) <= volts:
            break  # no path: no current until the next on-phase
        u = (-volts if i > 0.0 else volts) if i != 0.0 else (volts if emf > volts else -volts)
        target = (u - emf) / res
        crossing = _to_zero(i, target, tau)
        t = min(span, crossing)
        i, q = _piece(i, target, tau, t)
        if t == crossing:
            i = 0.0
        charge += q
        battery += u / volts * q  # lossless switches: the battery's current is u / V of the motor's
        span -= t
    return i, charge, battery


def cycle(i0: float, duty: float, emf: float, volts: float, res: float, henry: float, period: float,
          brake: bool) -> tuple[float, float, float]:
    """One PWM cycle from current i0 at signed duty: (end current, charge through the motor, charge drawn from
    the battery).  A negative duty is the mirror image of a positive one."""
    if duty < 0.0:
        i, q, qb = cycle(-i0, -duty, -emf, volts, res, henry, period, brake)
        return -i, -q, qb
    tau = henry / res
    on = duty * period
    i1, q_on = _piece(i0, (volts - emf) / res, tau, on)
    if brake:  # both low sides on: the winding is shorted across its back-EMF, the battery idle
        i2, q_off = _piece(i1, -emf / res, tau, period - on)
        return i2, q_on + q_off, q_on
    i2, q_off, back = _coast(i1, emf, volts, res, tau, period - on)
    return i2, q_on + q_off, q_on + back


def step(i0: float, duty: float, emf: float, volts: float, res: float, henry: float, frequency: float,
         brake: bool, span: float) -> tuple[float, float, float]:
    """The whole PWM cycles of `span` seconds (at least one, stretched to fit), emf and volts held:
    (end current, mean current, mean battery current)."""
    n = max(1, round(span * frequency))
    period = span / n
    i, charge, battery = i0, 0.0, 0.0
    for k in range(n):
        i_end, q, qb = cycle(i, duty, emf, volts, res, henry, period, brake)
        repeats = n - k if abs(i_end - i) < SETTLED else 1  # periodic already: the rest are the same cycle
        charge += q * repeats
        battery += qb * repeats
        i = i_end
        if repeats > 1:
            break
    return i, charge / span, battery / span
