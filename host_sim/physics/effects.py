"""The library of effects: physics the nominal twin leaves out, each one entry of LIBRARY.

An entry declares everything about its effect but the physics: its kind, the
RobotParams fields it sets, their units, fitting bounds and absent values, the
values a parameter file may give them, and the optional parts of the step it
needs.  params.py, drivetrain_effects.FIELDS, batch.step_parts, the fit and the
bench's scorer derive from it.  Reference: docs/effects.md.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import TypeVar

WHEEL_SITES = ("left", "right", "both")
KINDS = ("drive", "robot", "sensor", "ring")
# The optional parts of the robot's step an effect sets going while present (batch.step_parts): the drive
# with effects (drivetrain_effects.py), the gear's play (backlash.py), the delayed current reference.
STEP_PARTS = ("drivetrain_effects", "backlash", "delayed_reference")
# The drives (params.DRIVES) an effect applies to; an effect that does not say applies to them all.
ALL_DRIVES = ("current", "voltage", "duty", "wheel_speed")
BRIDGE_DRIVES = ("voltage", "duty", "wheel_speed")  # an H-bridge drives the motor (docs/motors.md "Drives")
STRICT_MARGIN = 1e-6  # of a parameter's declared range: how far inside an excluded end its fit bounds stay

RobotLike = TypeVar("RobotLike")  # a RobotParams (this module sits below params.py, which checks through it)


@dataclass(frozen=True)
class Admits:
    """The values a parameter file may give a field; params.params_from_dict refuses others, and a fit's
    bounds stay inside them (`bounds`).  The value checked is the field's, or for a delta the total
    `added_to` + field; its ends are multiples of the field `per` (if any) and excluded when `strict`."""

    lowest: float = -math.inf
    highest: float = math.inf
    strict: bool = False
    added_to: str | None = None  # the nominal field a delta is added to
    per: str | None = None  # com_offset: its ends are multiples of body_radius
    says: str = ""  # the refusal's wording where the ends alone do not say it

    def ends(self, p: object) -> tuple[float, float]:
        """The values the field itself may hold in robot p (excluded ends when strict)."""
        scale = float(getattr(p, self.per)) if self.per else 1.0
        shift = float(getattr(p, self.added_to)) if self.added_to else 0.0
        return self.lowest * scale - shift, self.highest * scale - shift

    def refusal(self, field: str, p: object) -> str | None:
        """Why robot p's value of `field` is refused, or None."""
        value = float(getattr(p, field))
        total = float(getattr(p, self.added_to)) + value if self.added_to else value
        scale = float(getattr(p, self.per)) if self.per else 1.0
        lo, hi = self.lowest * scale, self.highest * scale
        if (lo < total < hi) if self.strict else (lo <= total <= hi):
            return None
        if self.added_to:
            return (f"'{field}' leaves {self.added_to} + {field} = {total:g}, which must be "
                    f"{'positive' if self.strict else '>= 0'}")
        if self.says:
            return f"'{field}' must {self.says}, got {value}"
        if math.isfinite(hi):
            return f"'{field}' must be in {lo:g}..{hi:g}, got {value}"
        return f"'{field}' must be {'positive' if self.strict else '>= 0'}, got {value}"


ANY = Admits()
AT_LEAST_ZERO = Admits(0.0)
POSITIVE = Admits(0.0, strict=True)


def total_at_least_zero(nominal: str) -> Admits:
    return Admits(0.0, added_to=nominal)


def total_above(lowest: float, nominal: str) -> Admits:
    return Admits(lowest, strict=True, added_to=nominal)


@dataclass(frozen=True)
class Param:
    name: str  # as reported ("torque", "radius", ...)
    field: str  # RobotParams field; "{w}" is replaced by l / r for a drive effect
    unit: str
    lower: float  # declared bounds of the fitted value, in the field's own terms (`bounds` narrows them)
    upper: float
    absent: float | None = None  # None: the nominal robot's own value of the field
    admits: Admits = ANY
    in_proportion: tuple[str, ...] = ()  # fields scaled by the same ratio as this one (the body's inertia)


@dataclass(frozen=True)
class Effect:
    name: str
    kind: str  # "drive": at a wheel (left, right or both); "robot": the whole robot; "sensor": one IR pair
    # (0..7); "ring": all eight IR pairs at once
    params: tuple[Param, ...]
    doc: str
    step_parts: tuple[str, ...] = ()  # of STEP_PARTS: what the step needs while the effect is present
    drives: tuple[str, ...] = ALL_DRIVES  # the drives it belongs to: the library offers it for these only
    on_floor: bool = False  # it acts through the floor or the body (traction, caster, contact): not on a bench

    def sites(self) -> tuple[str | int, ...]:
        if self.kind == "drive":
            return WHEEL_SITES
        if self.kind == "sensor":
            return tuple(range(8))
        return ("both",)

    def fields(self, prm: Param) -> tuple[str, ...]:
        """The RobotParams fields the parameter sets: both wheels' for a drive effect."""
        return tuple(prm.field.format(w=w) for w in "lr") if self.kind == "drive" else (prm.field,)


def _drive(name: str, field: str, unit: str, lower: float, upper: float, doc: str, admits: Admits,
           step_parts: tuple[str, ...] = ("drivetrain_effects",), on_floor: bool = False) -> Effect:
    return Effect(name, "drive", (Param(name, field + "_{w}", unit, lower, upper, 0.0, admits),), doc, step_parts,
                  on_floor=on_floor)


def _robot(name: str, pname: str, field: str, unit: str, lower: float, upper: float, doc: str,
           admits: Admits, absent: float | None = 0.0, step_parts: tuple[str, ...] = (),
           drives: tuple[str, ...] = ALL_DRIVES, on_floor: bool = False) -> Effect:
    return Effect(name, "robot", (Param(pname, field, unit, lower, upper, absent, admits),), doc, step_parts, drives,
                  on_floor)


def _sensor(name: str, field: str, unit: str, lower: float, upper: float, absent: float, doc: str) -> Effect:
    return Effect(name, "sensor", (Param(name, field, unit, lower, upper, absent),), doc)


# The order is the fit's order of candidates: of effects the data cannot tell apart, the first is named
# (the plainer physics; fit._plainest).
LIBRARY: dict[str, Effect] = {e.name: e for e in (
    _drive("dry_friction", "coulomb_friction_delta", "N m", -1.5e-3, 1e-2,
           "dry (Coulomb) friction at the wheel's axle beyond the nominal", total_at_least_zero("coulomb_friction")),
    _drive("viscous_friction", "viscous_friction_delta", "N m s/rad", -2e-4, 2e-3,
           "viscous friction at the wheel's axle beyond the nominal", total_at_least_zero("viscous_friction")),
    _drive("wheel_radius", "wheel_radius_delta", "m", -3e-3, 3e-3, "the wheel's radius minus the nominal",
           total_above(0.0, "wheel_radius"), on_floor=True),
    _drive("torque_constant", "torque_constant_delta", "N m/A", -1.5e-3, 1.5e-3,
           "the motor's torque (= back-EMF) constant minus the nominal", total_above(0.0, "torque_constant")),
    _drive("encoder_scale", "ticks_per_rev_delta", "ticks", -150.0, 150.0,
           "encoder counts per wheel turn minus the nominal", total_above(0.5, "ticks_per_rev"), step_parts=()),
    _drive("backlash", "backlash", "rad", 0.0, 0.3, "play in the gear between the motor (and encoder) and the wheel",
           AT_LEAST_ZERO, step_parts=("drivetrain_effects", "backlash")),
    Effect("motor_resistance", "drive", (Param("resistance", "armature_resistance_delta_{w}", "ohm", -5.0, 20.0,
                                               0.0, total_above(0.0, "armature_resistance")),),
           "the motor's armature resistance minus the nominal", (), BRIDGE_DRIVES),
    _robot("track_width", "half_axle", "half_axle", "m", 0.035, 0.065,
           "half the distance between the wheels' contact points", POSITIVE, absent=None, on_floor=True),
    _robot("actuator_delay", "delay", "actuator_delay", "s", 0.0, 0.2,
           "a new command reaches the drivers this late", AT_LEAST_ZERO,
           step_parts=("delayed_reference",)),
    _robot("current_limit", "limit", "current_limit", "A", 0.01, 3.0, "the drivers' current limit",
           Admits(0.0, 1e3), absent=None, drives=("current",)),
    _robot("driver_deadband", "deadband", "driver_deadband", "-", 0.0, 0.5,
           "the fraction of full duty below which the bridge gives nothing", Admits(0.0, 0.95),
           drives=BRIDGE_DRIVES),
    _robot("speed_loop_kp", "kp", "speed_kp", "V s/rad", 0.0, 2.0, "the robot's own wheel-speed loop's "
           "proportional gain", AT_LEAST_ZERO, absent=None, drives=("wheel_speed",)),
    _robot("speed_loop_ki", "ki", "speed_ki", "V/rad", 0.0, 50.0, "the robot's own wheel-speed loop's integral "
           "gain", AT_LEAST_ZERO, absent=None, drives=("wheel_speed",)),
    _robot("battery_resistance", "resistance", "battery_resistance", "ohm", 0.0, 10.0,
           "the battery's internal resistance: its voltage sags with the current drawn", AT_LEAST_ZERO,
           step_parts=("drivetrain_effects",)),
    _robot("traction_limit", "mu", "wheel_friction", "-", 0.02, 2.0,
           "tyre-floor friction coefficient: beyond it the wheels slip", AT_LEAST_ZERO, absent=None, on_floor=True),
    _robot("caster_drag", "force", "caster_drag", "N", 0.0, 0.5, "the caster's drag, against the motion",
           AT_LEAST_ZERO, step_parts=("drivetrain_effects",), on_floor=True),
    _robot("turning_resistance", "torque", "turning_resistance", "N m", 0.0, 0.01,
           "the tyres' scrub torque, against turning", AT_LEAST_ZERO, step_parts=("drivetrain_effects",),
           on_floor=True),
    _robot("com_offset", "d", "com_offset", "m", -0.03, 0.05,
           "the centre of mass ahead of the axle centre (behind it: negative)",
           Admits(-1.0, 1.0, strict=True, per="body_radius",
                  says="lie inside the body, between -body_radius and body_radius (G ahead of C, or behind it "
                       "if negative)"), absent=None, on_floor=True),
    Effect("mass", "robot", (Param("mass", "body_mass", "kg", 0.2, 1.2, None, POSITIVE, ("body_inertia",)),),
           "the body's mass (its yaw inertia in proportion)", on_floor=True),
    _sensor("ir_offset", "ir_offset", "counts", -300.0, 300.0, 0.0, "added to the emitter-on reading"),
    _sensor("ir_gain", "ir_gain_scale", "-", 0.2, 3.0, 1.0, "the IR pair's optical efficiency, relative"),
    _sensor("ambient_leakage", "ambient_leakage", "-", -0.5, 0.5, 0.0,
            "fraction of the ambient light the emitter-on reading sees on top of the emitter-off one"),
    _sensor("ir_misalignment", "ir_misalignment", "rad", -0.5, 0.5, 0.0,
            "the IR pair's axis turned counter-clockwise from its bearing"),
    Effect("ir_latency", "ring", (Param("latency", "ir_latency", "s", 0.0, 0.2, 0.0),),
           "the IR readings describe the robot's pose this long ago"),
)}


def names_of_kind(*kinds: str) -> tuple[str, ...]:
    """The library's effects of these kinds, in its order."""
    return tuple(name for name, e in LIBRARY.items() if e.kind in kinds)


def offered(name: str, drive: str = "current", bench: bool = False) -> bool:
    """The library offers effect `name` to a robot with this drive (params.DRIVES), on a bench or not: one that
    belongs to its drive and, on a bench (the body held, the wheels off the floor), not one of the floor's."""
    effect = LIBRARY[name]
    return drive in effect.drives and not (bench and effect.on_floor)


@functools.cache
def fields_needing(part: str) -> tuple[str, ...]:
    """The RobotParams fields of the effects that need this part of the step (STEP_PARTS)."""
    return tuple(f for e in LIBRARY.values() if part in e.step_parts for prm in e.params for f in e.fields(prm))


def ranges() -> dict[str, tuple[float, float]]:
    """The fields whose admitted values are a plain closed range (params checks these with its own ranges)."""
    return {f: (prm.admits.lowest, prm.admits.highest) for e in LIBRARY.values() for prm in e.params
            for f in e.fields(prm) if prm.admits == Admits(prm.admits.lowest, prm.admits.highest)
            and math.isfinite(prm.admits.lowest) and math.isfinite(prm.admits.highest)}


def refusal(p: object) -> str | None:
    """Why robot p's effect fields are refused (the first reason, in the library's order), or None."""
    for effect in LIBRARY.values():
        for prm in effect.params:
            if prm.admits == ANY:
                continue
            for field in effect.fields(prm):
                if (why := prm.admits.refusal(field, p)) is not None:
                    return why
    return None


def bounds(name: str, base: object | None = None) -> tuple[list[float], list[float]]:
    """The fit's bounds of each parameter: the declared ones, narrowed for robot `base` to what its
    checks admit (Admits), so that a fitted twin always loads (tests/test_effects_library.py)."""
    lower, upper = [], []
    for prm in LIBRARY[name].params:
        lo, hi = prm.lower, prm.upper
        if base is not None and prm.admits != ANY:
            end_lo, end_hi = prm.admits.ends(base)
            margin = STRICT_MARGIN * (prm.upper - prm.lower) if prm.admits.strict else 0.0
            lo, hi = max(lo, end_lo + margin), min(hi, end_hi - margin)
        lower.append(lo)
        upper.append(hi)
    return lower, upper


def _fields(effect: Effect, site: str | int) -> list[tuple[Param, list[tuple[str, int | None]]]]:
    """Per parameter: the (field, tuple index) it sets at this site."""
    out: list[tuple[Param, list[tuple[str, int | None]]]] = []
    for prm in effect.params:
        if effect.kind == "drive":
            wheels = ("l", "r") if site == "both" else (str(site)[0],)
            out.append((prm, [(prm.field.format(w=w), None) for w in wheels]))
        elif effect.kind == "sensor":
            out.append((prm, [(prm.field, int(site))]))
        else:
            out.append((prm, [(prm.field, None)]))
    return out


def apply(p: RobotLike, name: str, site: str | int, values: list[float]) -> RobotLike:
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
        for other in prm.in_proportion:
            changes[other] = getattr(p, other) * float(value) / getattr(p, prm.field)
    return dataclasses.replace(p, **changes)  # type: ignore[type-var]


def targets(name: str, site: str | int) -> list[tuple[str, int | None]]:
    """The (field, tuple index) pairs effect `name` sets at this site."""
    return [target for _prm, fields in _fields(LIBRARY[name], site) for target in fields]


def values(p: object, name: str, site: str | int) -> list[float]:
    """The effect's parameter values in p at site (for "both" wheels: the left's)."""
    out = []
    for _prm, targets in _fields(LIBRARY[name], site):
        field, index = targets[0]
        v = getattr(p, field)
        out.append(float(v if index is None else v[index]))
    return out


def absent_values(p: object, name: str) -> list[float]:
    """The values meaning "not there": fixed ones, or the nominal robot's own."""
    return [prm.absent if prm.absent is not None else float(getattr(p, prm.field)) for prm in LIBRARY[name].params]
