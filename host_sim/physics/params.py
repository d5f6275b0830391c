"""The robot's parameters: one documented set, with units, and the checks of a parameter file.

Every layer reads them from here (identification sees them as a named vector:
`to_vector` / `from_vector`); firmware/config.py repeats the geometry it needs.
A parameter file is JSON {"name": value, ...} with any subset of the names
below.  References: docs/dynamics.md, docs/effects.md (the effects' fields).
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, TypeVar

from host_sim.physics import effects

T = TypeVar("T")

# The actuators a robot may have (docs/motors.md "Drives"); RobotParams holds the index, a parameter file the name.
DRIVES = ("current", "voltage", "duty", "wheel_speed")
DRIVE_UNITS = {"current": "A", "voltage": "V", "duty": "fraction", "wheel_speed": "rad/s"}
PWM_DECAYS = ("coast", "brake")
# Fields that hold an index into a list of names: a parameter file gives the name, to_json writes it back.
NAMED_FIELDS = {"drive": DRIVES, "pwm_decay": PWM_DECAYS}


def _p(default: float, unit: str, doc: str) -> Any:
    return field(default=default, metadata={"unit": unit, "doc": doc})


@dataclass(frozen=True)
class RobotParams:
    # --- geometry (paper Fig. 3) ------------------------------------------------
    wheel_radius: float = _p(0.021, "m", "wheel radius r")
    half_axle: float = _p(0.048, "m", "half the distance between the wheels, b")
    com_offset: float = _p(0.015, "m", "distance d from the wheel-axle centre C forward to G, the centre of mass "
                                       "of the body without its wheels (the point q's x, y describe; negative: behind C)")
    body_radius: float = _p(0.060, "m", "radius of the round body (collisions, sensor ring)")
    # --- masses and inertias ------------------------------------------------------
    body_mass: float = _p(0.46, "kg", "mass of the body without the wheels, m_c")
    wheel_mass: float = _p(0.025, "kg", "mass of one wheel with its motor rotor, m_w")
    body_inertia: float = _p(8.3e-4, "kg m^2", "body's moment of inertia about the vertical axis through G, I_c")
    wheel_inertia: float = _p(1.2e-5, "kg m^2",
                              "one wheel's inertia about its axle, rotor reflected through the gear, I_w")
    wheel_inertia_diam: float = _p(1.2e-6, "kg m^2", "one wheel's inertia about a diameter, I_m")
    # --- motors and drivers (paper 3.2) --------------------------------------------
    torque_constant: float = _p(0.0038, "N m/A", "motor torque constant k_t (= back-EMF constant k_e, V s/rad)")
    armature_resistance: float = _p(10.0, "ohm", "motor armature resistance R")
    gear_ratio: float = _p(50.0, "-", "motor turns per wheel turn N")
    gear_efficiency: float = _p(0.85, "-", "fraction of motor torque delivered through the gear")
    current_limit: float = _p(0.5, "A", "driver current limit")
    viscous_friction: float = _p(2.0e-4, "N m s/rad", "viscous friction at each wheel axle")
    coulomb_friction: float = _p(1.5e-3, "N m", "dry friction torque at each wheel axle")
    # Breakaway friction (docs/motors.md, "Breakaway friction"): a standing axle holds (1 + stiction) times its
    # dry friction, falling to it over stribeck_speed; absent (0) on the datasheet, fitted within tolerance.
    stiction_l: float = _p(0.0, "-", "left axle's breakaway friction beyond its dry friction, as a fraction of it")
    stiction_r: float = _p(0.0, "-", "right axle's breakaway friction beyond its dry friction, as a fraction of it")
    stribeck_speed: float = _p(1.0, "rad/s", "wheel speed over which the breakaway friction falls to the dry friction")
    battery_voltage: float = _p(7.4, "V", "battery voltage feeding the drivers")
    # --- the drive (docs/motors.md "Drives"): what the commands are and what turns them into motor current ----
    drive: float = _p(0.0, "-", "actuator the commands drive: current (0), voltage (1), duty (2) or wheel_speed "
                              "(3, set-points to the robot's own speed loop); a parameter file gives the name")
    pwm_decay: float = _p(0.0, "-", "H-bridge off-phase (voltage, duty, wheel_speed drives): coast (0, fast decay "
                                  "through the diodes) or brake (1, slow decay, both low sides on)")
    driver_deadband: float = _p(0.0, "-", "fraction of full duty below which the bridge gives nothing")
    dead_time: float = _p(0.0, "s", "the bridge's dead time: each PWM cycle's on-phase starts this late")
    pwm_frequency: float = _p(20000.0, "Hz", "the bridge's PWM frequency")
    motor_inductance: float = _p(2.0e-4, "H", "motor armature inductance L")
    speed_kp: float = _p(0.1, "V s/rad", "wheel_speed drive: the robot's speed loop's proportional gain "
                                         "(volts across the motor per rad/s of wheel-speed error)")
    speed_ki: float = _p(1.0, "V/rad", "wheel_speed drive: its integral gain (volts per rad of integrated error)")
    speed_loop_period: float = _p(0.01, "s", "wheel_speed drive: its period (encoder speed measured over it)")
    electronics_current: float = _p(0.08, "A", "what the boards, sensors and emitters draw from the battery beside "
                                               "the motors (matters only with battery_resistance)")
    # --- contact (host_sim/physics/contact.py, docs/dynamics.md "Contact") ------------------
    wheel_friction: float = _p(0.8, "-", "Coulomb friction coefficient mu between a wheel and the floor; each "
                                         "wheel carries half the weight, (m_c + 2 m_w) g / 2")
    wall_friction: float = _p(0.3, "-", "Coulomb friction coefficient between the body's rim and a wall")
    # --- encoders ------------------------------------------------------------------
    ticks_per_rev: float = _p(1200, "ticks", "encoder ticks per wheel turn (12 CPR x2 decoding x 50:1); "
                                             "need not be whole (a 29.86:1 gear with 12 counts: 358.32)")
    # --- IR sensors (paper 3.3; host_sim/sensors/ir_sensor.py, docs/ir-sensor.md) ----------
    # reflected = ir_gain * min(L/100, ir_saturation) * A(angle) * F(x), in ADC
    # counts.  Calibrated on a white matte wall straight ahead at L = 60 %:
    # ~700 counts at 5 cm, ~78 at 15 cm, ~28 at 25 cm; maximum at 1.5 cm
    # (7760 counts: the 12-bit ADC saturates from ~1.0 to ~2.3 cm), 0 at contact.
    sensor_range: float = _p(0.50, "m", "farthest reflection considered, from the sensor; the response "
                                        "fades to 0 over the last 20 % of it")
    ir_gain: float = _p(2.9, "counts m^2", "C of the far-field law C/x^2 at normal incidence and 100 % "
                                           "pulse width (linear extrapolation; the emitter saturates first)")
    ir_near_peak: float = _p(0.015, "m", "distance of the response maximum, where the near law D x^2 "
                                         "(D = C/x_p^4) meets C/x^2")
    ir_blend: float = _p(2.5, "-", "k: between x_p/k and k x_p the near and the far law are averaged "
                                   "(geometric mean, the far law's weight a smootherstep of ln x)")
    ir_saturation: float = _p(0.85, "-", "emitter pulse-width fraction above which more pulse width adds "
                                         "no light (Fig. 10)")
    ir_ambient: float = _p(150.0, "counts", "global ambient light seen by every phototransistor, when the "
                                            "world sets none")
    ir_noise: float = _p(3.0, "counts", "standard deviation of the Gaussian noise on every ADC reading")
    ir_on_delay: float = _p(4.0e-4, "s", "time from a sensor's emitter-off reading to its emitter-on "
                                         "reading (emitter settling + the 8-way multiplexer)")
    adc_bits: float = _p(12, "bits", "ADC resolution; readings clip at 2^bits - 1")
    ir_beam_rays: float = _p(1, "rays", "rays per sensor: 1 = along its axis only; n > 1 = a beam of n rays "
                                        "spread evenly over +-ir_beam_half_angle, weighted by cos^2 of the "
                                        "angle off the axis (emitter and receiver Lambertian)")
    ir_beam_half_angle: float = _p(0.35, "rad", "half-angle of the beam (used when ir_beam_rays > 1)")
    # Angle response A (Fig. 7): two 5th-degree polynomials in |angle| (rad),
    # coefficients x^0..x^5, blended by a smoothstep of |angle| over
    # ir_angle_blend.  Least-squares fits (x^1 held at 0) of the target in
    # docs/ir-sensor.md (ir_sensor.fit_angle_polynomials): diffuse
    # 0.78 cos^1.5 + 0.02, plus a specular Gaussian 0.2 exp(-a^2 / (2 0.12^2)).
    ir_big_dome: tuple[float, ...] = field(
        default=(0.800363, 0.0, -0.607462, 0.0698622, 0.056394, 0.0106067),
        metadata={"unit": "-", "doc": "big dome: diffuse reflection, |angle| in rad, x^0..x^5 "
                                      "(0.80 at 0, 0.017 at pi/2, positive on [0, pi/2])"})
    ir_small_dome: tuple[float, ...] = field(
        default=(1.00305, 0.0, -10.7864, 45.1569, -73.8708, 42.4242),
        metadata={"unit": "-", "doc": "small dome: diffuse + the specular beam near normal incidence, "
                                      "|angle| in rad, x^0..x^5; used up to ir_angle_blend[1]"})
    ir_angle_blend: tuple[float, ...] = field(
        default=(0.25, 0.45),
        metadata={"unit": "rad", "doc": "below the first |angle| the small dome alone, above the second the "
                                        "big dome alone, smoothstep in between"})
    ir_bearings: tuple[float, ...] = field(
        default=tuple(i * math.pi / 4 for i in range(8)),
        metadata={"unit": "rad", "doc": "each IR pair's place on the rim, counter-clockwise from the heading: as "
                                        "many pairs as bearings (the firmware's ring: eight, S1 front, every 45 deg)"})

    # --- effects (host_sim/physics/effects.py, docs/effects.md): physics the nominal twin leaves out.
    # Each holds the value meaning "absent" by default; diagnosis fits them, a parameter file sets them.
    # The library declares their checks (tests/test_effects_library.py: its fields and units agree with these).
    coulomb_friction_delta_l: float = _p(0.0, "N m", "left axle's dry friction beyond coulomb_friction")
    coulomb_friction_delta_r: float = _p(0.0, "N m", "right axle's dry friction beyond coulomb_friction")
    viscous_friction_delta_l: float = _p(0.0, "N m s/rad", "left axle's viscous friction beyond viscous_friction")
    viscous_friction_delta_r: float = _p(0.0, "N m s/rad", "right axle's viscous friction beyond viscous_friction")
    wheel_radius_delta_l: float = _p(0.0, "m", "left wheel's radius minus wheel_radius")
    wheel_radius_delta_r: float = _p(0.0, "m", "right wheel's radius minus wheel_radius")
    torque_constant_delta_l: float = _p(0.0, "N m/A", "left motor's torque constant minus torque_constant")
    torque_constant_delta_r: float = _p(0.0, "N m/A", "right motor's torque constant minus torque_constant")
    ticks_per_rev_delta_l: float = _p(0.0, "ticks", "left encoder's counts per wheel turn minus ticks_per_rev")
    ticks_per_rev_delta_r: float = _p(0.0, "ticks", "right encoder's counts per wheel turn minus ticks_per_rev")
    armature_resistance_delta_l: float = _p(0.0, "ohm", "left motor's armature resistance minus armature_resistance "
                                                        "(voltage, duty and wheel_speed drives)")
    armature_resistance_delta_r: float = _p(0.0, "ohm", "right motor's armature resistance minus "
                                                        "armature_resistance (voltage, duty and wheel_speed drives)")
    backlash_l: float = _p(0.0, "rad", "play in the left gear, at the wheel")
    backlash_r: float = _p(0.0, "rad", "play in the right gear, at the wheel")
    actuator_delay: float = _p(0.0, "s", "a new current reference reaches the drivers this late")
    battery_resistance: float = _p(0.0, "ohm", "battery internal resistance: the voltage sags with the current")
    caster_drag: float = _p(0.0, "N", "the caster's drag force, against the direction of motion")
    turning_resistance: float = _p(0.0, "N m", "the tyres' scrub torque, against turning")
    ir_gain_scale: tuple[float, ...] = field(
        default=(1.0,) * 8, metadata={"unit": "-", "doc": "each IR pair's optical efficiency relative to ir_gain"})
    ir_misalignment: tuple[float, ...] = field(
        default=(0.0,) * 8, metadata={"unit": "rad", "doc": "each IR pair's axis turned counter-clockwise"})
    ir_offset: tuple[float, ...] = field(
        default=(0.0,) * 8, metadata={"unit": "counts", "doc": "added to each emitter-on reading"})
    ambient_leakage: tuple[float, ...] = field(
        default=(0.0,) * 8, metadata={"unit": "-", "doc": "fraction of the ambient light each emitter-on reading "
                                                          "sees on top of the emitter-off one"})
    ir_latency: float = _p(0.0, "s", "the IR readings describe the pose this long ago")

    # ------------------------------------------------------------------------------
    def __post_init__(self) -> None:
        for name, choices in NAMED_FIELDS.items():  # RobotParams(drive="duty") holds the index
            value = getattr(self, name)
            if isinstance(value, str):
                object.__setattr__(self, name, float(choices.index(value)))

    @property
    def drive_kind(self) -> str:
        """The drive's name (DRIVES)."""
        return DRIVES[int(self.drive)]

    @property
    def adc_max(self) -> int:
        return (1 << int(self.adc_bits)) - 1

    def replace(self, **changes: float) -> RobotParams:
        return dataclasses.replace(self, **changes)  # type: ignore[arg-type]

    # --- as a plain vector, for identification -----------------------------------
    @classmethod
    def scalar_names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls) if f.type in ("float", float)]

    def to_vector(self, names: list[str] | None = None) -> list[float]:
        return [float(getattr(self, n)) for n in (names or self.scalar_names())]

    @classmethod
    def from_vector(cls, values: list[float], names: list[str] | None = None,
                    base: RobotParams | None = None) -> RobotParams:
        names = names or cls.scalar_names()
        if len(values) != len(names):
            raise ValueError(f"{len(values)} values for {len(names)} names")
        return dataclasses.replace(base or cls(), **dict(zip(names, map(float, values))))

    def describe(self) -> list[tuple[str, object, str, str]]:
        """(name, value, unit, meaning) for every parameter."""
        return [(f.name, getattr(self, f.name), f.metadata["unit"], f.metadata["doc"])
                for f in dataclasses.fields(self)]

    def to_json(self) -> dict[str, object]:
        out: dict[str, object] = {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v)
                                  for f in dataclasses.fields(self)}
        for name, choices in NAMED_FIELDS.items():
            out[name] = choices[int(getattr(self, name))]
        return out


def cached_per_params(compute: Callable[[Any], T]) -> Callable[[Any], T]:
    """compute(p), cached for the last parameter object seen.

    Parameters are frozen (RobotParams) or never changed once built (ParamBatch), so the
    object's identity is enough; the hot paths call these every step with the same robot."""
    last: list[Any] = [None, None]

    def cached(p: Any) -> T:
        if last[0] is not p:
            last[1] = compute(p)
            last[0] = p
        return last[1]  # type: ignore[no-any-return]

    cached.__doc__ = compute.__doc__
    cached.__name__ = compute.__name__
    return cached


class ParamsError(ValueError):
    """A parameter file is wrong; the message names the file, the entry and the problem."""


# What a parameter file may say beyond "finite and positive": whole numbers
# where the hardware counts, and ranges outside which the models overflow or
# stop meaning anything (readings travel as 16-bit fields on the wire).  The
# fields an effect of the library sets are checked as it declares (effects.Admits).
INTEGER_PARAMS = {"adc_bits": (8, 16)}
PARAM_RANGES = {
    # counts per wheel turn need not be whole, as behind a 29.86:1 gearbox
    # (tests/test_import.py::test_counts_per_turn_need_not_be_whole)
    "ticks_per_rev": (1.0, 1e6),
    "dead_time": (0.0, 1e-3),
    "pwm_frequency": (1.0, 1e7), "motor_inductance": (0.0, 10.0), "speed_kp": (0.0, 1e4), "speed_ki": (0.0, 1e6),
    "speed_loop_period": (1e-4, 1.0),
    "ir_saturation": (0.0, 1.0), "ir_on_delay": (0.0, 0.04), "ir_noise": (0.0, 1e4),
    "viscous_friction": (0.0, 1e3), "coulomb_friction": (0.0, 1e3),
    "stiction_l": (0.0, 10.0), "stiction_r": (0.0, 10.0), "stribeck_speed": (1e-3, 1e3),
    "ir_blend": (1.0, 1e3), "ir_gain": (0.0, 1e6), "ir_ambient": (0.0, 1e6), "ir_near_peak": (0.0, 1.0),
    **effects.ranges(),  # the library's fields with a range of their own (current_limit), checked as these
}
MAX_MAGNITUDE = 1e9  # any other scalar, in its unit


def params_from_dict(data: object, where: str = "parameters") -> RobotParams:
    if not isinstance(data, dict):
        raise ParamsError(f"{where}: expected a JSON object of name: value")
    known = {f.name: f for f in dataclasses.fields(RobotParams)}
    changes: dict[str, object] = _ring_of(data, where)
    for name, value in data.items():
        if name not in known:
            import difflib

            close = difflib.get_close_matches(str(name), list(known), n=1, cutoff=0.8)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise ParamsError(f"{where}: unknown parameter '{name}'{hint}")
        default = changes.get(name, known[name].default)
        if name == "ir_bearings":
            continue  # _ring_of read it
        if name in NAMED_FIELDS:
            if value not in NAMED_FIELDS[name]:
                raise ParamsError(f"{where}: '{name}' must be one of {', '.join(NAMED_FIELDS[name])}, got {value!r}")
            changes[name] = float(NAMED_FIELDS[name].index(value))
        elif isinstance(default, tuple):
            if not isinstance(value, list) or len(value) != len(default) or not all(
                    isinstance(v, (int, float)) for v in value):
                raise ParamsError(f"{where}: '{name}' must be a list of {len(default)} numbers"
                                  + (", one per IR pair" if name in PER_PAIR else ""))
            changes[name] = tuple(float(v) for v in value)
        else:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParamsError(f"{where}: '{name}' must be a finite number ({known[name].metadata['unit']}), "
                                  f"got {value!r}")
            changes[name] = float(value)
    _check_ranges(changes, where)
    params = dataclasses.replace(RobotParams(), **changes)  # type: ignore[arg-type]
    for name in ("wheel_radius", "body_radius", "wheel_mass", "body_inertia",
                 "wheel_inertia", "torque_constant", "armature_resistance", "gear_ratio", "ticks_per_rev",
                 "battery_voltage", "sensor_range", "adc_bits"):
        if getattr(params, name) <= 0:
            raise ParamsError(f"{where}: '{name}' must be positive, got {getattr(params, name)}")
    if params.wall_friction < 0:
        raise ParamsError(f"{where}: 'wall_friction' must be >= 0, got {params.wall_friction}")
    if not 0 < params.gear_efficiency <= 1:
        raise ParamsError(f"{where}: 'gear_efficiency' must be in (0, 1], got {params.gear_efficiency}")
    why = effects.refusal(params)
    if why is not None:
        raise ParamsError(f"{where}: {why}")
    return params


# Lists with one entry per IR pair: as many as ir_bearings has, each pair neutral by default.
PER_PAIR = {"ir_gain_scale": 1.0, "ir_misalignment": 0.0, "ir_offset": 0.0, "ambient_leakage": 0.0}
MAX_IR_PAIRS = 64


def _ring_of(data: dict[Any, Any], where: str) -> dict[str, object]:
    """The ring a parameter file gives (ir_bearings), with its pairs' lists sized to it (neutral values)."""
    if "ir_bearings" not in data:
        return {}
    value = data["ir_bearings"]
    if not isinstance(value, list) or not 1 <= len(value) <= MAX_IR_PAIRS or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        raise ParamsError(f"{where}: 'ir_bearings' must be a list of 1..{MAX_IR_PAIRS} finite numbers (rad)")
    n = len(value)
    return {"ir_bearings": tuple(float(v) for v in value), **{k: (v,) * n for k, v in PER_PAIR.items()}}


def _check_ranges(changes: dict[str, object], where: str) -> None:
    for name, value in changes.items():
        if isinstance(value, tuple):
            if not all(math.isfinite(v) and abs(v) <= MAX_MAGNITUDE for v in value):
                raise ParamsError(f"{where}: '{name}' has an item that is not a finite number within "
                                  f"+-{MAX_MAGNITUDE:g}")
            continue
        v = float(value)  # type: ignore[arg-type]
        if name in INTEGER_PARAMS:
            lo, hi = INTEGER_PARAMS[name]
            if v != int(v) or not lo <= v <= hi:
                raise ParamsError(f"{where}: '{name}' must be a whole number in {lo}..{hi}, got {value}")
        elif name in PARAM_RANGES:
            lo_f, hi_f = PARAM_RANGES[name]
            if not lo_f <= v <= hi_f:
                raise ParamsError(f"{where}: '{name}' must be in {lo_f:g}..{hi_f:g}, got {value}")
        elif abs(v) > MAX_MAGNITUDE:
            raise ParamsError(f"{where}: '{name}' is beyond +-{MAX_MAGNITUDE:g}, got {value}")


def read_json(path: str | os.PathLike[str], what: str, error: type[ValueError] = ParamsError) -> object:
    """A JSON file's content; `error` says in one line, naming the file, why it cannot be read (a file that
    is missing, not UTF-8 text, or not JSON).  what: the kind of file, e.g. "parameter file"."""
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a {what}: byte {exc.start} is not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise error(f"{path}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None


def load_params(path: str | Path) -> RobotParams:
    return params_from_dict(read_json(path, "parameter file"), str(path))


DEFAULT = RobotParams()
