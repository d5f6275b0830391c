"""The plant's own IR response: an inverse square with a near-field roll-off, a far fade and a Lambertian lobe.

reflected = G * P(L) * A(angle) * F(x) [ADC counts]; its form and constants (PlantSpec.ir) are the plant's,
fitted loosely to the datasheet's calibration points, not the twin's law (docs/proving-ground.md, "IR").
Plain floats: the plant reads eight sensors per control period.
"""
from __future__ import annotations

import math
from typing import Any

# The nominal constants: G fitted on the datasheet's 5, 15 and 25 cm points at L = 60 %; the rest are set by
# the optics (tests/test_proving_ground.py::test_the_ir_curve_is_the_plants_own).
NOMINAL = {"gain": 3.44, "setback": 0.003, "near_field": 0.011, "fade_range": 0.36, "fade_power": 4.0,
           "lambert_power": 2.0, "gloss": 0.15, "gloss_width": 0.10, "saturation": 0.85, "knee": 8.0,
           "range": 0.5}


def angle_factor(angle: float, c: dict[str, Any]) -> float:
    """A(angle): a Lambertian lobe (wall lit at cos, seen at cos) plus a Gaussian gloss near the normal."""
    a = min(abs(angle), 0.5 * math.pi)
    gloss = float(c["gloss"])
    width = float(c["gloss_width"])
    return (1.0 - gloss) * math.cos(a) ** float(c["lambert_power"]) + gloss * math.exp(-a * a / (2 * width * width))


def distance_factor(x: float, c: dict[str, Any]) -> float:
    """F(x) in 1/m^2: inverse square from the diodes (set back behind the window), times the emitter and
    receiver cones' overlap (grows as x^2 near the window), times a fade as the spot outgrows the wall."""
    if x >= float(c["range"]):
        return 0.0
    x = max(x, 0.0)
    overlap = 1.0 - math.exp(-(x / float(c["near_field"])) ** 2)
    fade = math.exp(-(x / float(c["fade_range"])) ** float(c["fade_power"]))
    return overlap * fade / (x + float(c["setback"])) ** 2


def power_factor(pct: float, c: dict[str, Any]) -> float:
    """The emitter's light against pulse width: linear, with a soft knee at `saturation`."""
    u = max(pct / 100.0, 0.0)
    s, k = float(c["saturation"]), float(c["knee"])
    return u / (1.0 + (u / s) ** k) ** (1.0 / k)


def reflected(x: float, angle: float, pct: float, gain: float, c: dict[str, Any]) -> float:
    """Reflected light (counts) from a wall at x (m) seen at angle (rad), emitters at pct %, sensor gain G."""
    if not math.isfinite(x):
        return 0.0
    return gain * power_factor(pct, c) * angle_factor(angle, c) * distance_factor(x, c)


def lamp_light(level: float, sensor_xy: tuple[float, float], axis: tuple[float, float],
               lamp_xy: tuple[float, float]) -> float:
    """A visible lamp's light at a sensor: level * cos^1.5 / (d^2 + (0.1 m)^2) (a receiver a little narrower than
    Lambertian, and a lamp of finite size near it)."""
    dx, dy = lamp_xy[0] - sensor_xy[0], lamp_xy[1] - sensor_xy[1]
    d = math.hypot(dx, dy)
    if d <= 0:
        return 0.0
    cos = (axis[0] * dx + axis[1] * dy) / d
    return level * max(0.0, cos) ** 1.5 / (d * d + 0.01)
