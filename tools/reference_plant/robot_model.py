"""The robot as MuJoCo sees it: PlantSpec (true physical values, SI, per wheel and per sensor) -> MJCF -> MjModel.

`datasheet_spec()` fills PlantSpec from host_sim.physics.params.DEFAULT (as numbers) plus what the twin does
not describe (heights, the caster, the contacts); `nominal_spec()` adds the physics the twin lacks at its
typical level.  The bodies and contacts: docs/proving-ground.md, "The robot in MuJoCo".
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import mujoco  # type: ignore[import-untyped]
import numpy as np

from host_sim.physics.params import DEFAULT
from host_sim.physics.world import World
from tools.reference_plant import ir_law, ir_paper

WALL_RADIUS = 0.01  # m, contact capsule around each wall line
WALL_HEIGHT = 0.025  # m above the floor: the contact capsules' axis and the IR rays
IR_GROUP = 3  # geom group of the IR reflecting surfaces (no contacts)
IR_SKIN = 1e-4  # m, half-thickness of the IR surfaces
CASTER_RADIUS = 0.006  # m
CASTER_X = 0.045  # m ahead of C
SKID_X = -0.045  # m, rear skid, behind C
SKID_GAP = 0.001  # m between the rear skid and a level floor
CONTACT_TIMECONST = 0.002  # s, stiffness of every contact (>= 2 timesteps)
SLIP_MIN_SPEED = 0.5  # rad/s: below it a compliant tyre's slip damper keeps its low-speed (finite) value


Pair = tuple[float, float]
Eight = tuple[float, ...]


@dataclass(frozen=True)
class PlantSpec:
    """True physical values of one robot (SI units; pairs are (left, right))."""

    # geometry
    wheel_radius: Pair  # m
    half_axle: float  # m, b: C to each wheel's mid-plane
    com_offset: float  # m, d: G ahead of C
    com_height: float  # m, G above the floor
    body_radius: float  # m
    # masses and inertias
    body_mass: float  # kg, without wheels
    body_inertia: float  # kg m^2, yaw, about G
    wheel_mass: float  # kg, each
    wheel_inertia: float  # kg m^2, each wheel about its axle, rotor reflected included
    rotor_inertia: float  # kg m^2, the rotor's share of wheel_inertia (reflected through the gear)
    wheel_inertia_diam: float  # kg m^2, each wheel about a diameter
    # drive train (per wheel)
    torque_constant: Pair  # N m/A (= back-EMF constant, V s/rad)
    armature_resistance: Pair  # ohm
    gear_ratio: float  # -
    gear_efficiency: float  # -
    coulomb_friction: Pair  # N m, dry (Coulomb) friction at the axle in motion
    viscous_friction: Pair  # N m s/rad
    backlash: Pair  # rad of play at the wheel, 0 = rigid gear
    current_limit: float  # A, the driver's limit
    actuator_delay: float  # s from a new current reference to the driver applying it
    # battery
    battery_voltage: float  # V, open circuit
    battery_resistance: float  # ohm, internal
    quiescent_current: float  # A drawn by the electronics
    vbat_noise: float  # V, sd of the battery voltage measurement
    # contacts and floor
    floor_friction: float  # -, wheel/floor (traction)
    torsional_friction: float  # m, wheel/floor spin friction (scrub), 0 = none
    caster_friction: float  # -, caster/floor, 0 = frictionless ball
    wall_friction: float  # -, body/wall
    floor_tilt: float  # rad, floor's slope (gravity off vertical)
    floor_tilt_direction: float  # rad, world direction of the downhill slope
    # encoders
    ticks_per_rev: Pair  # counts per wheel turn
    # IR ring
    ir: dict[str, Any] = field(default_factory=dict)  # the plant's IR constants (ir_law.NOMINAL's keys + noise...)
    ir_gain_scale: Eight = (1.0,) * 8  # -, per sensor
    ir_misalignment: Eight = (0.0,) * 8  # rad, per sensor, counter-clockwise
    ir_offset: Eight = (0.0,) * 8  # counts added to the emitter-on reading
    ambient_leakage: Eight = (0.0,) * 8  # fraction of ambient added to the emitter-on reading
    ir_latency: float = 0.0  # s, age of the pose the IR readings see
    # tracker
    tracker_noise_xy: float = 0.001  # m, sd
    tracker_noise_phi: float = math.radians(0.3)  # rad, sd
    # --- physics the twin lacks (docs/proving-ground.md, "Physics the twin lacks"); 0 = off
    inductance: Pair = (2.0e-4, 2.0e-4)  # H, the motor's winding: the current loop's plant and the bridge's load
    current_loop_hz: float = 300.0  # the driver's PI current loop's bandwidth; 0 = an ideal driver (the current
    # is its reference within the step)
    stiction_ratio: Pair = (1.0, 1.0)  # breakaway / Coulomb torque (Stribeck curve)
    stribeck_speed: float = 1.0  # rad/s at the wheel over which friction falls from breakaway to Coulomb
    ripple: Pair = (0.0, 0.0)  # gear-mesh torque ripple, fraction of the transmitted torque
    ripple_teeth: Pair = (40.0, 40.0)  # ripple cycles per wheel turn (the output stage's teeth)
    ripple_phase: Pair = (0.0, 0.0)  # rad
    slip_stiffness: float = 0.0  # N per unit of longitudinal slip, per tyre; 0 = no slip
    lateral_stiffness: float = 0.0  # N/m, the tyre carcass sideways; 0 = rigid
    caster_rolling: float = 0.0  # -, the ball caster's rolling drag / its load
    vbat_lsb: float = 0.0  # V per count of the battery ADC; 0 = exact
    encoder_edges: tuple[tuple[float, ...], tuple[float, ...]] = ((), ())  # each edge's offset (ticks), per motor turn
    period_jitter: float = 0.0  # s, sd of the firmware's period (whole ms)
    late_share: float = 0.0  # share of periods that run late by 5-15 ms
    drop_share: float = 0.0  # share of rows the link loses
    # --- mismatches outside the library (effects.py); 0 / -1 = off
    weak_wheel: int = -1  # 0 left, 1 right: its motor weakens at weak_time
    weak_fraction: float = 0.0  # of its torque constant lost
    weak_time: float = 0.0  # s
    eccentricity: Pair = (0.0, 0.0)  # m, the tyre's centre off its axle
    encoder_drift: Pair = (0.0, 0.0)  # counts per second added to the encoder
    adc_clip: float = 0.0  # counts at which the IR readings clip; 0 = the ADC's full scale
    cable_drag: float = 0.0  # N per m of distance from the anchor
    cable_anchor: Pair = (0.0, 0.0)  # m, where the tether is fixed
    # --- the drive (docs/proving-ground.md, "Drives"): what the commands are; the others drive an H-bridge
    drive: str = "current"  # "current" | "voltage" | "duty" | "wheel_speed"
    pwm_decay: str = "coast"  # the bridge's off-phase: "coast" (fast decay, diodes) or "brake" (slow decay)
    driver_deadband: float = 0.0  # fraction of full duty below which the bridge gives nothing
    pwm_frequency: float = 20000.0  # Hz
    speed_kp: float = 0.1  # V s/rad, the robot's own wheel-speed loop
    speed_ki: float = 1.0  # V/rad
    speed_loop_period: float = 0.01  # s
    board_ticks_per_rev: float = 1200.0  # counts per wheel turn the robot's board believes (its speed loop's)

    def replace(self, **changes: object) -> PlantSpec:
        return dataclasses.replace(self, **changes)  # type: ignore[arg-type]


def datasheet_spec(paper_ir: bool = False) -> PlantSpec:
    """The robot the twin describes (host_sim.physics.params.DEFAULT, as numbers), in the plant's terms, with
    none of the physics the twin lacks: the ideal driver, Coulomb friction, rigid tyres, even encoder edges.
    Its IR ring reads the plant's own curve, or with paper_ir the paper's law and the datasheet's constants
    (ir_paper.py): then nothing but a concealed effect departs from the datasheet."""
    p = DEFAULT
    two = lambda v: (float(v), float(v))  # noqa: E731 - per-wheel pair
    # A rigid wheel's spin inertia is at most twice its diametral one (the
    # triangle inequality of inertias); the rest of the twin's wheel_inertia is
    # the rotor seen through the gear.
    wheel_own = 2.0 * p.wheel_inertia_diam
    return PlantSpec(
        wheel_radius=two(p.wheel_radius), half_axle=p.half_axle, com_offset=p.com_offset, com_height=0.02,
        body_radius=p.body_radius, body_mass=p.body_mass, body_inertia=p.body_inertia, wheel_mass=p.wheel_mass,
        wheel_inertia=p.wheel_inertia, rotor_inertia=p.wheel_inertia - wheel_own,
        wheel_inertia_diam=p.wheel_inertia_diam, torque_constant=two(p.torque_constant),
        armature_resistance=two(p.armature_resistance), gear_ratio=p.gear_ratio, gear_efficiency=p.gear_efficiency,
        coulomb_friction=two(p.coulomb_friction), viscous_friction=two(p.viscous_friction), backlash=(0.0, 0.0),
        current_limit=p.current_limit, actuator_delay=0.0, battery_voltage=p.battery_voltage,
        battery_resistance=0.0, quiescent_current=0.08, vbat_noise=0.005, floor_friction=1.0,
        torsional_friction=0.0, caster_friction=0.0, wall_friction=0.3, floor_tilt=0.0, floor_tilt_direction=0.0,
        ticks_per_rev=two(p.ticks_per_rev), pwm_frequency=p.pwm_frequency,
        inductance=two(p.motor_inductance), current_loop_hz=0.0, speed_kp=p.speed_kp, speed_ki=p.speed_ki,
        speed_loop_period=p.speed_loop_period, board_ticks_per_rev=p.ticks_per_rev,
        ir=ir_paper.datasheet_ir() if paper_ir else {
            **ir_law.NOMINAL, "ambient": p.ir_ambient, "noise": p.ir_noise, "on_delay": p.ir_on_delay,
            "adc_max": float((1 << int(p.adc_bits)) - 1)},
    )


def nominal_spec() -> PlantSpec:
    """The datasheet robot with the physics the twin lacks at its typical level (robot_draw.py draws each case's
    own): a real driver's current loop, Stribeck friction, gear ripple, compliant tyres, a rolling caster,
    uneven encoder edges, a quantised battery reading and a jittering period with lost rows."""
    return datasheet_spec().replace(
        inductance=(1.0e-3, 1.0e-3), current_loop_hz=300.0, stiction_ratio=(1.2, 1.2), stribeck_speed=1.0,
        ripple=(0.02, 0.02), ripple_teeth=(40.0, 40.0), slip_stiffness=25.0, lateral_stiffness=2500.0,
        caster_rolling=0.0025, vbat_lsb=0.0024, period_jitter=0.002, late_share=0.01, drop_share=0.005)


def _f(*v: float) -> str:
    return " ".join(f"{x:.9g}" for x in v)


def _tyre_xml(spec: PlantSpec, side: str, k: int, own: float) -> str:
    """The tyre on its hub: rigid, or (slip_stiffness > 0) a tread body turning and flexing sideways on the hub,
    the turn damped by Plant each step so that the slip is force / slip stiffness (docs/proving-ground.md)."""
    r = spec.wheel_radius[k]
    geom = f'<geom name="tyre_{side}" class="tyre" type="sphere" size="{r:.9g}" pos="{spec.eccentricity[k]:.9g} 0 0"/>'
    if spec.slip_stiffness <= 0:
        return geom
    tread_mass = 0.6 * spec.wheel_mass
    # The carcass's sideways flex: a spring with 30 % of critical damping against the tread's mass.
    damping = 0.6 * math.sqrt(max(spec.lateral_stiffness, 1.0) * tread_mass)
    lateral = (f'<joint name="flex_{side}" type="slide" axis="0 1 0" stiffness="{spec.lateral_stiffness:.9g}" '
               f'damping="{damping:.9g}"/>' if spec.lateral_stiffness > 0 else "")
    return f"""<body name="tread_{side}" pos="0 0 0">
          {lateral}
          <joint name="tread_{side}" type="hinge" axis="0 1 0" damping="{r * spec.slip_stiffness / SLIP_MIN_SPEED:.9g}"/>
          <inertial pos="0 0 0" mass="{tread_mass:.9g}"
                    diaginertia="{_f(0.6 * spec.wheel_inertia_diam, 0.6 * own, 0.6 * spec.wheel_inertia_diam)}"/>
          {geom}
        </body>"""


def _wheel_xml(spec: PlantSpec, side: str, k: int) -> str:
    """One wheel (and its separate rotor when the gear has play), as children of the chassis."""
    y = spec.half_axle if side == "l" else -spec.half_axle
    # the wheel's own spin inertia, at most twice its diametral one (a rigid body's triangle inequality)
    own = min(spec.wheel_inertia - spec.rotor_inertia, 1.9999 * spec.wheel_inertia_diam)
    # Axle friction: MuJoCo's dry friction (a stiff constraint: no creep below
    # breakaway) and viscous damping, on the joint the motor drives.  Its level is the
    # breakaway torque; Plant lowers it to the Stribeck curve in motion.
    breakaway = spec.coulomb_friction[k] * spec.stiction_ratio[k]
    friction = (f'frictionloss="{breakaway:.9g}" solreffriction="{CONTACT_TIMECONST} 1" '
                f'damping="{spec.viscous_friction[k]:.9g}" armature="{spec.rotor_inertia:.9g}"')
    rigid = spec.backlash[k] <= 0
    hub = 0.4 if spec.slip_stiffness > 0 else 1.0  # the hub's share of the wheel's mass and inertia
    wheel = f"""
      <body name="wheel_{side}" pos="0 {y:.9g} 0">
        <joint name="wheel_{side}" type="hinge" axis="0 1 0" {friction if rigid else ''}/>
        <inertial pos="0 0 0" mass="{hub * spec.wheel_mass:.9g}"
                  diaginertia="{_f(hub * spec.wheel_inertia_diam, hub * own, hub * spec.wheel_inertia_diam)}"/>
        {_tyre_xml(spec, side, k, own)}
      </body>"""
    if rigid:
        return wheel
    rotor = f"""
      <body name="rotor_{side}" pos="0 {y:.9g} 0">
        <joint name="rotor_{side}" type="hinge" axis="0 1 0" {friction}/>
        <inertial pos="0 0 0" mass="1e-4" diaginertia="1e-10 1e-10 1e-10"/>
      </body>"""
    return wheel + rotor


def drive_joint(spec: PlantSpec, k: int) -> str:
    """The joint the motor turns and the encoder reads: the wheel, or its rotor when the gear has play."""
    side = "lr"[k]
    return f"wheel_{side}" if spec.backlash[k] <= 0 else f"rotor_{side}"


def _walls_xml(world: World | None) -> str:
    if world is None:
        return ""
    parts = []
    z = WALL_HEIGHT
    for k, (x1, y1, x2, y2) in enumerate(world.segments):
        length = math.hypot(x2 - x1, y2 - y1)
        yaw = math.atan2(y2 - y1, x2 - x1)
        parts.append(f'<geom name="wall{k}" class="wall" type="capsule" size="{WALL_RADIUS}" '
                     f'fromto="{_f(x1, y1, z, x2, y2, z)}"/>')
        parts.append(f'<geom name="ir_wall{k}" class="ir_surface" type="box" size="{_f(length / 2, IR_SKIN, 0.03)}" '
                     f'pos="{_f((x1 + x2) / 2, (y1 + y2) / 2, 0.03)}" euler="0 0 {yaw:.9g}"/>')
    return "\n    ".join(parts)


def build_mjcf(spec: PlantSpec, world: World | None = None, timestep: float = 0.001) -> str:
    """The MJCF text of the robot on a floor among the world's walls (robot at the origin, heading +x)."""
    g = 9.81
    tilt, direction = spec.floor_tilt, spec.floor_tilt_direction
    gravity = (g * math.sin(tilt) * math.cos(direction), g * math.sin(tilt) * math.sin(direction),
               -g * math.cos(tilt))
    r0 = 0.5 * (spec.wheel_radius[0] + spec.wheel_radius[1])  # axle height
    zc = WALL_HEIGHT - r0  # robot's wall capsule centre, relative to C
    caster_condim = 1 if spec.caster_friction <= 0 else 3
    tyre_condim = 3 if spec.torsional_friction <= 0 else 4
    i_pitch = 0.55 * spec.body_inertia  # a disc with some height: a little over half the yaw inertia
    return f"""
<mujoco model="twinbot_plant">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{timestep}" gravity="{_f(*gravity)}" integrator="implicitfast" cone="elliptic"
          impratio="10" noslip_iterations="8" solver="Newton" iterations="50" tolerance="1e-10"/>
  <default>
    <geom solref="{CONTACT_TIMECONST} 1" solimp="0.95 0.99 0.001"/>
    <default class="tyre">
      <geom contype="0" conaffinity="1" condim="{tyre_condim}"
            friction="{_f(spec.floor_friction, max(spec.torsional_friction, 1e-5), 1e-5)}"/>
    </default>
    <default class="caster">
      <geom contype="0" conaffinity="1" condim="{caster_condim}"
            friction="{_f(max(spec.caster_friction, 1e-5), 1e-5, 1e-5)}"/>
    </default>
    <default class="hull">
      <geom contype="0" conaffinity="2" condim="3" friction="{_f(spec.wall_friction, 1e-5, 1e-5)}"/>
    </default>
    <default class="wall">
      <geom contype="2" conaffinity="0" condim="3" group="2" friction="{_f(spec.wall_friction, 1e-5, 1e-5)}"/>
    </default>
    <default class="ir_surface">
      <geom contype="0" conaffinity="0" group="{IR_GROUP}"/>
    </default>
  </default>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 1" contype="1" conaffinity="0" condim="3" friction="1e-5 1e-5 1e-5"/>
    {_walls_xml(world)}
    <body name="chassis" pos="0 0 {r0:.9g}">
      <freejoint name="chassis"/>
      <inertial pos="{_f(spec.com_offset, 0, spec.com_height - r0)}" mass="{spec.body_mass:.9g}"
                diaginertia="{_f(i_pitch, i_pitch, spec.body_inertia)}"/>
      <geom name="hull" class="hull" type="capsule" size="{spec.body_radius - WALL_RADIUS:.9g} 0.002"
            pos="0 0 {zc:.9g}"/>
      <geom name="caster" class="caster" type="sphere" size="{CASTER_RADIUS}"
            pos="{_f(CASTER_X, 0, CASTER_RADIUS - r0)}"/>
      <geom name="skid" class="caster" type="sphere" size="{CASTER_RADIUS}"
            pos="{_f(SKID_X, 0, CASTER_RADIUS + SKID_GAP - r0)}"/>
      {_wheel_xml(spec, "l", 0)}
      {_wheel_xml(spec, "r", 1)}
    </body>
  </worldbody>
  <actuator>
    <motor name="motor_l" joint="{drive_joint(spec, 0)}"/>
    <motor name="motor_r" joint="{drive_joint(spec, 1)}"/>
  </actuator>
  {_tendons_xml(spec)}
</mujoco>
"""


def _tendons_xml(spec: PlantSpec) -> str:
    """The gear play: rotor angle minus wheel angle confined to [-play/2, play/2]."""
    lines = []
    for k, side in enumerate("lr"):
        gap = spec.backlash[k]
        if gap > 0:
            lines.append(f'<fixed name="play_{side}" limited="true" range="{_f(-gap / 2, gap / 2)}" '
                         f'solreflimit="{CONTACT_TIMECONST} 1">'
                         f'<joint joint="rotor_{side}" coef="1"/><joint joint="wheel_{side}" coef="-1"/></fixed>')
    return f"<tendon>{''.join(lines)}</tendon>" if lines else ""


def build_model(spec: PlantSpec, world: World | None = None, timestep: float = 0.001) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(build_mjcf(spec, world, timestep))


def ir_group_mask() -> np.ndarray:
    """geomgroup for mujoco.mj_ray: the IR surfaces only."""
    mask = np.zeros(6, dtype=np.uint8)
    mask[IR_GROUP] = 1
    return mask
