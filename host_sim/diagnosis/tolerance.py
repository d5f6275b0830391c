"""The datasheet's tolerance: how far a robot built to its datasheet may lie from each value, and which
fitted effects lie beyond it.  A difference within the tolerance is the robot's own build, not a fault:
the diagnosis calibrates the twin within it first (calibrate.py) and names only what lies beyond it.
Reference: docs/diagnosis.md, "Within the datasheet's tolerance".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from host_sim.physics import effects as E
from host_sim.physics.params import RobotParams, read_json

# Relative ± bands, the tolerance a datasheet states for a batch of robots (the reasons: docs/diagnosis.md).
BANDS: dict[str, float] = {
    "wheel_radius": 0.015,  # a moulded tyre, ±0.3 mm on 21 mm
    "torque_constant": 0.06,  # magnets of one batch
    "armature_resistance": 0.09,  # winding and temperature
    "coulomb_friction": 0.12,  # grease and assembly
    "viscous_friction": 0.15,  # grease
    "half_axle": 0.015,  # a machined chassis
    "com_offset": 0.15,  # where the battery sits
    "body_mass": 0.06,
    "current_limit": 0.06,  # the sense resistor
    "battery_voltage": 0.15,  # the state of charge: a 2S pack's 6.4-8.4 V about 7.4 V
    "ir_gain": 0.15,  # an optical pair's efficiency, each pair its own
    "stiction": 0.4,  # a greased gear train's breakaway friction, 0-40 % above its dry friction
    "ir_misalignment": 0.035,  # rad: an IR pair's axis within 2 degrees of its bearing, as its holder is moulded
    "stribeck_speed": 0.5,  # the speed over which a breakaway falls to the dry friction: the grease's, a factor of 2
    "caster_drag": 0.025,  # N: a ball caster's rolling drag, a coefficient up to 0.01 on up to half the weight (5 N)
}
# Bands of a quantity the datasheet gives as absent (0): the band is the value itself, in its unit, not a
# fraction of the datasheet's (calibrate.set_values, calibrate.bounds).
ABSOLUTE = ("stiction", "ir_misalignment", "caster_drag")
UNIT_OF = {"ir_misalignment": "rad", "caster_drag": "N"}  # the ABSOLUTE ones not a fraction: said in their unit
ONE_SIDED = ("stiction", "caster_drag")  # a breakaway is never below the dry friction, nor a drag below none
# Quantities a datasheet states only loosely, as a factor either way: a band b reaches from (1 - b) times the
# value to 1 / (1 - b) times it (0.5: half to twice), not to (1 + b) times (calibrate.bounds).
FACTOR = ("stribeck_speed",)
# The effect parameter fields whose value is a change from a datasheet value (a wheel's delta), by the
# datasheet field it changes; the others set the datasheet field itself (half_axle) or a relative scale
# (ir_gain_scale, about 1).
DELTA_OF = {"coulomb_friction_delta": "coulomb_friction", "viscous_friction_delta": "viscous_friction",
            "wheel_radius_delta": "wheel_radius", "torque_constant_delta": "torque_constant",
            "armature_resistance_delta": "armature_resistance"}
SCALE_OF = {"ir_gain_scale": "ir_gain"}


class ToleranceError(ValueError):
    """A tolerance file that cannot be used; the message says what and where."""


@dataclass(frozen=True)
class Tolerance:
    """The datasheet robot and its bands (relative, by datasheet field)."""

    datasheet: RobotParams
    bands: dict[str, float]

    def deviation(self, field: str, value: float) -> tuple[str, float] | None:
        """(the datasheet quantity, the value's relative departure from it) of an effect's field (its
        "{w}" left in for a wheel's), or None where the datasheet states no tolerance for it."""
        base = field.replace("_{w}", "")
        if base in DELTA_OF:
            of = DELTA_OF[base]
            nominal = float(getattr(self.datasheet, of))
            return (of, value / nominal) if of in self.bands and nominal else None
        if base in SCALE_OF:
            return (SCALE_OF[base], value - 1.0) if SCALE_OF[base] in self.bands else None
        if base in ABSOLUTE:
            return (base, value) if base in self.bands else None
        if base in self.bands:
            nominal = float(getattr(self.datasheet, base))
            return (base, value / nominal - 1.0) if nominal else None
        return None

    def within(self, effect: str, values: list[float]) -> bool:
        """True when every parameter of a fitted effect lies within its band of the datasheet value: the
        robot as built, not a fault (tests/test_tolerance.py::test_an_effect_within_tolerance_is_not_named)."""
        inside = []
        for prm, value in zip(E.LIBRARY[effect].params, values):
            dev = self.deviation(prm.field, value)
            inside.append(dev is not None and abs(dev[1]) <= self.bands[dev[0]])
        return bool(inside) and all(inside)

    def reaches(self, effect: str, intervals: list[tuple[float, float]]) -> bool:
        """True when every parameter's interval (its 95 % interval with the twin's model error) meets its band:
        the robot as built may hold that value, so the fit does not show a fault
        (tests/test_tolerance.py::test_an_effect_whose_interval_reaches_the_tolerance_is_not_named)."""
        meets = []
        for prm, (lo, hi) in zip(E.LIBRARY[effect].params, intervals):
            a, b = self.deviation(prm.field, lo), self.deviation(prm.field, hi)
            band = self.bands[a[0]] if a is not None and b is not None else None
            meets.append(band is not None and min(a[1], b[1]) <= band and max(a[1], b[1]) >= -band)
        return bool(meets) and all(meets)


def relative_bounds(quantities: list[str], band: np.ndarray, reach: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Each quantity's (lower, upper) bound relative to the datasheet, `reach` bands out: -band..band; 0..band
    for a one-sided one (ONE_SIDED), which a build has or lacks but never holds below none; and for one stated
    as a factor either way (FACTOR), (1 - band) - 1 .. 1 / (1 - band) - 1, the factor to the power `reach`
    (tests/test_tolerance.py::test_a_quantity_stated_as_a_factor_reaches_as_far_each_way)."""
    one = np.array([q in ONE_SIDED for q in quantities], dtype=bool)
    factor = np.array([q in FACTOR for q in quantities], dtype=bool)
    down = (1.0 - band) ** reach  # a band is below 1 (load_bands)
    lo = np.where(one, 0.0, np.where(factor, down - 1.0, -reach * band))
    return lo, np.where(factor, 1.0 / down - 1.0, reach * band)


def load_bands(path: str | Path) -> dict[str, float]:
    """BANDS with those a JSON file gives ({"wheel_radius": 0.01, ...}: relative ± bands, the value itself for
    those ABSOLUTE; 0 turns one off)."""
    data = read_json(path, "tolerance file", ToleranceError)
    if not isinstance(data, dict):
        raise ToleranceError(f"{path}: a tolerance file is a JSON object of relative bands by datasheet value")
    bands = dict(BANDS)
    for key, value in data.items():
        if key not in BANDS:
            raise ToleranceError(f"{path}: '{key}' has no tolerance (one of: {', '.join(BANDS)})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not 0 <= value < 1:
            raise ToleranceError(f"{path}: '{key}' must be a band in 0..1 "
                                 f"({'the value itself' if key in ABSOLUTE else 'relative'}), got {value!r}")
        bands[key] = float(value)
    return bands
