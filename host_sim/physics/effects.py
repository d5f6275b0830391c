"""The library of effects: physics the nominal twin leaves out, each a set of robot parameters.

An effect is real physics inside the twin (host_sim's motors, dynamics,
contact and sensor models read these parameters on the single-robot and the
batch path alike), not a correction of its outputs.  Every effect is absent
by default: its parameters hold the value that means "not there", so the
nominal twin is unchanged.  A parameter file (host_sim/physics/params.py) can set
any of them; `twinbot diagnose --write-params` writes the ones it fitted.

    p = apply(DEFAULT, "dry_friction", "left", [0.002])   # 2 mN m more at the left axle
    values(p, "dry_friction", "left")                      # [0.002]

Each effect: its name (as diagnosis reports it), where it sits ("wheel":
left/right/both, "sensor": 0..7, "robot", "ring": all eight sensors), and its
parameters: the RobotParams field each one sets (per wheel: *_l / *_r; per
sensor: an element of an 8-tuple), unit, bounds for fitting, and the absent
value.  docs/effects.md gives the equation of each.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from host_sim.physics.params import RobotParams

WHEEL_SITES = ("left", "right", "both")


@dataclass(frozen=True)
class Param:
    name: str  # as reported ("torque", "radius", ...)
    field: str  # RobotParams field; "{w}" is replaced by l / r for a wheel effect
    unit: str
    lower: float  # bounds of the fitted value, in the field's own terms
    upper: float
    absent: float | None = None  # None: the nominal robot's own value of the field


@dataclass(frozen=True)
class Effect:
    name: str
    site: str  # "wheel" | "sensor" | "robot" | "ring"
    params: tuple[Param, ...]
    doc: str

    def sites(self) -> tuple[str | int, ...]:
        if self.site == "wheel":
            return WHEEL_SITES
        if self.site == "sensor":
            return tuple(range(8))
        return ("both",)


def _wheel(name: str, field: str, unit: str, lower: float, upper: float, doc: str) -> Effect:
    return Effect(name, "wheel", (Param(name, field + "_{w}", unit, lower, upper, 0.0),), doc)


def _robot(name: str, pname: str, field: str, unit: str, lower: float, upper: float, doc: str,
           absent: float | None = 0.0) -> Effect:
    return Effect(name, "robot", (Param(pname, field, unit, lower, upper, absent),), doc)


def _sensor(name: str, field: str, unit: str, lower: float, upper: float, absent: float, doc: str) -> Effect:
    return Effect(name, "sensor", (Param(name, field, unit, lower, upper, absent),), doc)


LIBRARY: dict[str, Effect] = {e.name: e for e in (
    _wheel("dry_friction", "coulomb_friction_delta", "N m", -1.5e-3, 1e-2,
           "dry (Coulomb) friction at the wheel's axle beyond the nominal (smoothed like it over 0.1 rad/s: "
           "no stick-slip yet, docs/effects.md)"),
    _wheel("viscous_friction", "viscous_friction_delta", "N m s/rad", -2e-4, 2e-3,
           "viscous friction at the wheel's axle beyond the nominal"),
    _wheel("wheel_radius", "wheel_radius_delta", "m", -3e-3, 3e-3, "the wheel's radius minus the nominal"),
    _wheel("torque_constant", "torque_constant_delta", "N m/A", -1.5e-3, 1.5e-3,
           "the motor's torque (= back-EMF) constant minus the nominal"),
    _wheel("encoder_scale", "ticks_per_rev_delta", "ticks", -150.0, 150.0,
           "encoder counts per wheel turn minus the nominal"),
    _wheel("backlash", "backlash", "rad", 0.0, 0.3, "play in the gear between the motor (and encoder) and "
                                                  "the wheel"),
    _robot("track_width", "half_axle", "half_axle", "m", 0.035, 0.065,
           "half the distance between the wheels' contact points", absent=None),
    _robot("actuator_delay", "delay", "actuator_delay", "s", 0.0, 0.2,
           "a new current reference reaches the drivers this late"),
    _robot("current_limit", "limit", "current_limit", "A", 0.01, 3.0, "the drivers' current limit", absent=None),
    _robot("battery_resistance", "resistance", "battery_resistance", "ohm", 0.0, 10.0,
           "the battery's internal resistance: its voltage sags with the current drawn"),
    _robot("traction_limit", "mu", "wheel_friction", "-", 0.02, 2.0,
           "tyre-floor friction coefficient: beyond it the wheels slip", absent=None),
    _robot("caster_drag", "force", "caster_drag", "N", 0.0, 0.5, "the caster's drag, against the motion"),
    _robot("turning_resistance", "torque", "turning_resistance", "N m", 0.0, 0.01,
           "the tyres' scrub torque, against turning"),
    _robot("com_offset", "d", "com_offset", "m", -0.03, 0.05, "the centre of mass ahead of the axle centre (behind it: negative)",
           absent=None),
    _robot("mass", "mass", "body_mass", "kg", 0.2, 1.2, "the body's mass (its yaw inertia in proportion)",
           absent=None),
    _sensor("ir_gain", "ir_gain_scale", "-", 0.2, 3.0, 1.0, "the IR pair's optical efficiency, relative"),
    _sensor("ir_misalignment", "ir_misalignment", "rad", -0.5, 0.5, 0.0,
            "the IR pair's axis turned counter-clockwise from its bearing"),
    _sensor("ir_offset", "ir_offset", "counts", -300.0, 300.0, 0.0, "added to the emitter-on reading"),
    _sensor("ambient_leakage", "ambient_leakage", "-", -0.5, 0.5, 0.0,
            "fraction of the ambient light the emitter-on reading sees on top of the emitter-off one"),
    Effect("ir_latency", "ring", (Param("latency", "ir_latency", "s", 0.0, 0.2, 0.0),),
           "the IR readings describe the robot's pose this long ago"),
)}


def _fields(effect: Effect, site: str | int) -> list[tuple[Param, list[tuple[str, int | None]]]]:
    """Per parameter: the (field, tuple index) it sets at this site."""
    out = []
    for prm in effect.params:
        if effect.site == "wheel":
            wheels = ("l", "r") if site == "both" else (str(site)[0],)
            out.append((prm, [(prm.field.format(w=w), None) for w in wheels]))
        elif effect.site == "sensor":
            out.append((prm, [(prm.field, int(site))]))
        else:
            out.append((prm, [(prm.field, None)]))
    return out


def apply(p: RobotParams, name: str, site: str | int, values: list[float]) -> RobotParams:
    """p with effect `name` at `site` set to `values` (one per parameter)."""
    effect = LIBRARY[name]
    if len(values) != len(effect.params):
        raise ValueError(f"{name}: {len(effect.params)} values expected, got {len(values)}")
    changes: dict[str, object] = {}
    for (prm, targets), value in zip(_fields(effect, site), values):
        for field, index in targets:
            if index is None:
                changes[field] = float(value)
            else:
                current = list(changes.get(field, getattr(p, field)))  # type: ignore[call-overload]
                current[index] = float(value)
                changes[field] = tuple(current)
    if name == "mass":
        changes["body_inertia"] = p.body_inertia * float(values[0]) / p.body_mass
    return dataclasses.replace(p, **changes)  # type: ignore[arg-type]


def values(p: RobotParams, name: str, site: str | int) -> list[float]:
    """The effect's parameter values in p at site (for "both" wheels: the left's)."""
    out = []
    for _prm, targets in _fields(LIBRARY[name], site):
        field, index = targets[0]
        v = getattr(p, field)
        out.append(float(v if index is None else v[index]))
    return out


def absent_values(p: RobotParams, name: str) -> list[float]:
    """The values meaning "not there": fixed ones, or the nominal robot's own."""
    return [prm.absent if prm.absent is not None else float(getattr(p, prm.field)) for prm in LIBRARY[name].params]


def bounds(name: str) -> tuple[list[float], list[float]]:
    params = LIBRARY[name].params
    return [q.lower for q in params], [q.upper for q in params]
