"""The plant's effects: named physics switched on inside the reference plant (never by editing its outputs).

Each effect sets one true value of the plant's PlantSpec, so that MuJoCo, the motors or the sensor law
produce its consequences; it has a site (wheel, robot, sensor, ring), an absent value and realistic ranges.

    spec = apply(nominal_spec(), "dry_friction", 4e-3, "left")

The table: docs/proving-ground.md, "Effects".
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from host_sim.physics.effects import LIBRARY
from host_sim.physics.params import DRIVES
from tools.reference_plant.robot_model import PlantSpec, nominal_spec

Where = str | int  # "left" | "right" | "both", or a sensor index


@dataclass(frozen=True)
class Effect:
    name: str
    applies_to: str  # "wheel" (left / right / both) | "one wheel" (left / right) | "robot" | "sensor" (0..7) |
    #                  "ring" (all eight)
    param: str  # the PlantSpec value it sets (its true physical value)
    unit: str
    absent: float  # the value meaning "no effect": the nominal plant's
    ranges: tuple[tuple[float, float], ...]  # realistic values away from absent: two when it may err either way
    doc: str
    setter: Callable[[PlantSpec, float, Where], PlantSpec]

    @property
    def in_library(self) -> bool:
        """The twin's library has an effect of this name (the scorer compares the two by name)."""
        return self.name in LIBRARY

    @property
    def drives(self) -> tuple[str, ...]:
        """The drives a case concealing it may have: the library effect's (a deadband needs a bridge), all for
        one outside the library."""
        return tuple(LIBRARY[self.name].drives) if self.in_library else DRIVES

    def draw(self, rng: np.random.Generator) -> float:
        lo, hi = self.ranges[int(rng.integers(len(self.ranges)))]
        return float(rng.uniform(lo, hi))

    def sites(self) -> list[Where]:
        """Where the effect can sit: wheels, or sensors, or the whole robot."""
        if self.applies_to == "wheel":
            return ["left", "right", "both"]
        if self.applies_to == "one wheel":
            return ["left", "right"]
        if self.applies_to == "sensor":
            return list(range(8))
        return ["both"]


def _wheels(pair: tuple[float, float], value: float, where: Where) -> tuple[float, float]:
    if where not in ("left", "right", "both"):
        raise ValueError(f"a wheel effect sits on 'left', 'right' or 'both', not {where!r}")
    return (value if where in ("left", "both") else pair[0], value if where in ("right", "both") else pair[1])


def _sensor(values: tuple[float, ...], value: float, where: Where) -> tuple[float, ...]:
    if not isinstance(where, int) or not 0 <= where < 8:
        raise ValueError(f"an IR sensor effect sits on a sensor 0..7, not {where!r}")
    return tuple(value if i == where else v for i, v in enumerate(values))


def _wheel_field(name: str) -> Callable[[PlantSpec, float, Where], PlantSpec]:
    return lambda s, v, w: s.replace(**{name: _wheels(getattr(s, name), v, w)})


def _sensor_field(name: str) -> Callable[[PlantSpec, float, Where], PlantSpec]:
    return lambda s, v, w: s.replace(**{name: _sensor(getattr(s, name), v, w)})


def _robot_field(name: str) -> Callable[[PlantSpec, float, Where], PlantSpec]:
    return lambda s, v, w: s.replace(**{name: v})


def _mass(s: PlantSpec, v: float, w: Where) -> PlantSpec:
    """A heavier or lighter body of the same shape: the yaw inertia scales with the mass."""
    return s.replace(body_mass=v, body_inertia=s.body_inertia * v / s.body_mass)


_N = nominal_spec()
EFFECTS: dict[str, Effect] = {e.name: e for e in (
    Effect("dry_friction", "wheel", "coulomb_friction", "N m", _N.coulomb_friction[0],
           ((0.4e-3, 0.9e-3), (2.2e-3, 3.5e-3)),
           "dry friction torque at the axle (MuJoCo joint frictionloss: holds below breakaway)",
           _wheel_field("coulomb_friction")),
    Effect("viscous_friction", "wheel", "viscous_friction", "N m s/rad", _N.viscous_friction[0],
           ((0.5e-4, 1.2e-4), (3.0e-4, 5e-4)), "viscous friction at the axle (joint damping)",
           _wheel_field("viscous_friction")),
    Effect("wheel_radius", "wheel", "wheel_radius", "m", _N.wheel_radius[0],
           ((0.0198, 0.0206), (0.0214, 0.0222)), "the tyre's radius (worn, or another tyre)",
           _wheel_field("wheel_radius")),
    Effect("track_width", "robot", "half_axle", "m", _N.half_axle, ((0.0445, 0.0465), (0.0495, 0.0515)),
           "half the distance between the wheels' contact points", _robot_field("half_axle")),
    Effect("actuator_delay", "robot", "actuator_delay", "s", 0.0, ((0.01, 0.06),),
           "a new current reference reaches the drivers this late", _robot_field("actuator_delay")),
    Effect("torque_constant", "wheel", "torque_constant", "N m/A", _N.torque_constant[0],
           ((0.0029, 0.0035), (0.0041, 0.0047)),
           "the motor's torque constant (= its back-EMF constant)", _wheel_field("torque_constant")),
    Effect("current_limit", "robot", "current_limit", "A", _N.current_limit, ((0.025, 0.045),),
           "the drivers' current limit set low (a wrong current-sense resistor): shows when the references "
           "exceed it", _robot_field("current_limit")),
    Effect("motor_resistance", "wheel", "armature_resistance", "ohm", _N.armature_resistance[0],
           ((7.0, 8.5), (12.0, 16.0)), "the winding's resistance (another motor, a hot one, worn brushes): "
           "under a bridge it sets the current a duty drives", _wheel_field("armature_resistance")),
    Effect("driver_deadband", "robot", "driver_deadband", "-", 0.0, ((0.02, 0.06),),
           "the share of full duty the bridge swallows (its dead time, a driver's threshold)",
           _robot_field("driver_deadband")),
    Effect("speed_loop_kp", "robot", "speed_kp", "V s/rad", _N.speed_kp, ((0.04, 0.07), (0.15, 0.3)),
           "the robot's own wheel-speed loop's proportional gain", _robot_field("speed_kp")),
    Effect("speed_loop_ki", "robot", "speed_ki", "V/rad", _N.speed_ki, ((0.3, 0.6), (1.8, 3.5)),
           "the robot's own wheel-speed loop's integral gain", _robot_field("speed_ki")),
    Effect("battery_resistance", "robot", "battery_resistance", "ohm", 0.0, ((0.5, 3.0),),
           "the battery's internal resistance: the voltage sags with the current drawn",
           _robot_field("battery_resistance")),
    Effect("traction_limit", "robot", "floor_friction", "-", _N.floor_friction, ((0.08, 0.25),),
           "tyre/floor friction coefficient: the wheels slip when pushed harder", _robot_field("floor_friction")),
    Effect("caster_drag", "robot", "caster_friction", "-", 0.0, ((0.01, 0.04),),
           "the caster's sliding friction coefficient on the floor", _robot_field("caster_friction")),
    Effect("turning_resistance", "robot", "torsional_friction", "m", 0.0, ((0.0002, 0.001),),
           "spin (scrub) friction of the tyres' contact patches: torque = this x normal force",
           _robot_field("torsional_friction")),
    Effect("com_offset", "robot", "com_offset", "m", _N.com_offset, ((0.0, 0.008), (0.022, 0.032)),
           "the body's centre of mass ahead of the axle centre C", _robot_field("com_offset")),
    Effect("mass", "robot", "body_mass", "kg", _N.body_mass, ((0.34, 0.41), (0.52, 0.62)),
           "the body's mass (its yaw inertia in proportion)", _mass),
    Effect("encoder_scale", "wheel", "ticks_per_rev", "ticks", _N.ticks_per_rev[0],
           ((1150.0, 1185.0), (1215.0, 1250.0)), "encoder counts per wheel turn",
           _wheel_field("ticks_per_rev")),
    Effect("backlash", "wheel", "backlash", "rad", 0.0, ((0.03, 0.12),),
           "play in the gear between the motor (and its encoder) and the wheel", _wheel_field("backlash")),
    Effect("ir_gain", "sensor", "ir_gain_scale", "-", 1.0, ((0.55, 0.8), (1.25, 1.6)),
           "the IR pair's optical efficiency relative to the nominal sensor", _sensor_field("ir_gain_scale")),
    Effect("ir_misalignment", "sensor", "ir_misalignment", "rad", 0.0, ((-0.3, -0.08), (0.08, 0.3)),
           "the IR pair's axis turned counter-clockwise from its nominal bearing",
           _sensor_field("ir_misalignment")),
    Effect("ir_offset", "sensor", "ir_offset", "counts", 0.0, ((-60.0, -15.0), (15.0, 60.0)),
           "the emitter's pulse coupling into the receiver: added to the emitter-on reading",
           _sensor_field("ir_offset")),
    Effect("ambient_leakage", "sensor", "ambient_leakage", "-", 0.0, ((-0.25, -0.06), (0.06, 0.25)),
           "fraction of the ambient light the emitter-on reading sees on top of the emitter-off one",
           _sensor_field("ambient_leakage")),
    Effect("ir_latency", "ring", "ir_latency", "s", 0.0, ((0.02, 0.1),),
           "the IR readings describe the robot's pose this long ago", _robot_field("ir_latency")),
    # --- outside the library (a diagnosis must not name a library effect for them)
    Effect("floor_slope", "robot", "floor_tilt", "rad", 0.0, ((0.005, 0.02),),
           "the floor slopes (gravity not normal to it); downhill direction drawn at random",
           lambda s, v, w: s.replace(floor_tilt=v)),
    Effect("adc_clipping", "ring", "adc_clip", "counts", 4095.0, ((1200.0, 2500.0),),
           "the IR readings clip at this level (the ADC's reference set too low)", _robot_field("adc_clip")),
    Effect("eccentric_wheel", "wheel", "eccentricity", "m", 0.0, ((0.0002, 0.0008),),
           "the tyre's centre sits this far off its axle: its rolling radius swings once per turn",
           _wheel_field("eccentricity")),
    Effect("cable_drag", "robot", "cable_drag", "N/m", 0.0, ((0.03, 0.1),),
           "a tether dragged over the floor from the start point: it pulls back with this times the distance",
           _robot_field("cable_drag")),
    Effect("encoder_drift", "one wheel", "encoder_drift", "counts/s", 0.0, ((-3.0, -0.8), (0.8, 3.0)),
           "spurious counts (a noisy channel) added to one encoder at a steady rate", _wheel_field("encoder_drift")),
    Effect("weakening_motor", "one wheel", "weak_fraction", "-", 0.0, ((0.1, 0.3),),
           "one motor loses this share of its torque constant at a drawn time (a hot winding, a cracked magnet)",
           lambda s, v, w: s.replace(weak_fraction=v, weak_wheel=0 if w == "left" else 1)),
)}


def apply(spec: PlantSpec, name: str, value: float, where: Where = "both") -> PlantSpec:
    """spec with effect `name` set to `value` at `where` (a wheel, a sensor index, or "both")."""
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r} (known: {', '.join(EFFECTS)})")
    effect = EFFECTS[name]
    if effect.applies_to == "one wheel" and where not in ("left", "right"):
        raise ValueError(f"{name} sits on one wheel ('left' or 'right'), not {where!r}")
    if effect.applies_to in ("robot", "ring") and where != "both":
        raise ValueError(f"{name} applies to the whole robot (where='both'), not {where!r}")
    if not math.isfinite(value):
        raise ValueError(f"{name}: value must be finite, got {value}")
    return effect.setter(spec, float(value), where)


def _at(spec: PlantSpec, effect: Effect, where: Where) -> list[float]:
    """The effect's parameter in spec at each of its sites (one value, or a wheel's, or both wheels')."""
    value = getattr(spec, effect.param)
    if not isinstance(value, tuple):
        return [float(value)]
    if effect.applies_to == "sensor":
        return [float(value[int(where)])]  # type: ignore[arg-type]
    return [float(value[k]) for k, side in enumerate(("left", "right")) if where in (side, "both")]


def apply_to_robot(spec: PlantSpec, name: str, value: float, where: Where = "both"
                   ) -> tuple[PlantSpec, list[float], list[float]]:
    """A drawn robot with effect `name` at `where`: a value given about the datasheet's (`absent`) scales the
    robot's own drawn value by value / absent (a worn tyre is worn from its own size), one about 0 is set.
    Returns (spec, the true values at each site, the drawn values there before)."""
    effect = EFFECTS[name]
    drawn = _at(spec, effect, where)
    if effect.absent == 0 or name == "adc_clipping":
        return apply(spec, name, value, where), [value] * len(drawn), drawn
    sides = [where] if where != "both" or effect.applies_to != "wheel" else ["left", "right"]
    true = [d * value / effect.absent for d in drawn]
    for side, v in zip(sides, true):
        spec = apply(spec, name, v, side)
    return spec, true, drawn
