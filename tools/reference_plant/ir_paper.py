"""The paper's IR law (section 3.3), written afresh for the plant from docs/ir-sensor.md: the datasheet robot's
optics (PlantSpec.ir["law"] == "paper"), which pipeline tests record on; a drawn robot reads ir_law.py's curve.

reflected = C * P(L) * A(angle) * F(x) [ADC counts]; only the constants (datasheet_ir()) are shared with the
twin, not code.  docs/proving-ground.md, "Pipeline tests: the datasheet robot".
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from host_sim.physics.params import DEFAULT

FADE = 0.2  # fraction of the range over which the response fades out


def _clip01(u: float) -> float:
    return 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)


def _poly(coef: Sequence[float], a: float) -> float:
    v = 0.0
    for c in reversed(coef):
        v = v * a + c
    return v


def angle_factor(angle: float, c: dict[str, Any]) -> float:
    """A(angle), angle between the ray and the wall's normal (rad)."""
    a = abs(angle)
    lo, hi = c["angle_blend"]
    u = _clip01((a - lo) / (hi - lo))
    w = u * u * (3.0 - 2.0 * u)
    small = _poly(c["small_dome"], a)
    big = _poly(c["big_dome"], a)
    return max(0.0, small + w * (big - small))


def distance_factor(x: float, c: dict[str, Any]) -> float:
    """F(x) in 1/m^2 for a wall x metres from the sensor along its axis."""
    rng = float(c["range"])
    if x >= rng:
        return 0.0
    xp = float(c["near_peak"])
    k = float(c["blend"])
    x = max(x, 1e-6)
    lx = math.log(x / xp)
    u = _clip01((lx + math.log(k)) / (2.0 * math.log(k)))
    s = u * u * u * (u * (6.0 * u - 15.0) + 10.0)
    f = (x / xp) ** (2.0 - 4.0 * s) / (xp * xp)
    v = _clip01((rng - x) / (FADE * rng))
    return f * v * v * (3.0 - 2.0 * v)


def power_factor(pct: float, c: dict[str, Any]) -> float:
    return min(max(pct / 100.0, 0.0), float(c["saturation"]))


def reflected(x: float, angle: float, pct: float, gain: float, c: dict[str, Any]) -> float:
    """Reflected light (counts) from a wall at x (m) seen at angle (rad), emitters at pct %, sensor gain C."""
    if not math.isfinite(x):
        return 0.0
    return gain * power_factor(pct, c) * angle_factor(angle, c) * distance_factor(x, c)


def lamp_light(level: float, sensor_xy: tuple[float, float], axis: tuple[float, float],
               lamp_xy: tuple[float, float]) -> float:
    """A visible lamp's light at a sensor: level * max(0, cos) / max(d, 0.1 m)^2."""
    dx, dy = lamp_xy[0] - sensor_xy[0], lamp_xy[1] - sensor_xy[1]
    d = math.hypot(dx, dy)
    if d <= 0:
        return 0.0
    cos = (axis[0] * dx + axis[1] * dy) / d
    return level * max(0.0, cos) / max(d, 0.1) ** 2


def datasheet_ir() -> dict[str, Any]:
    """PlantSpec.ir for the paper's law with the datasheet's constants (read as numbers)."""
    p = DEFAULT
    return {"law": "paper", "gain": p.ir_gain, "near_peak": p.ir_near_peak, "blend": p.ir_blend,
            "saturation": p.ir_saturation, "range": p.sensor_range, "ambient": p.ir_ambient, "noise": p.ir_noise,
            "on_delay": p.ir_on_delay, "adc_max": float((1 << int(p.adc_bits)) - 1),
            "big_dome": tuple(p.ir_big_dome), "small_dome": tuple(p.ir_small_dome),
            "angle_blend": tuple(p.ir_angle_blend)}
