"""Each case's own robot: the datasheet's values drawn within a few per cent, and the physics the twin lacks at
drawn, realistic levels.  `draw_robot(seed)` -> PlantSpec.  The table and its reasons: docs/proving-ground.md,
"Every robot is drawn".
"""
from __future__ import annotations

import numpy as np

from host_sim.physics.params import DEFAULT
from tools.reference_plant.robot_model import PlantSpec, datasheet_spec

TRUNCATE = 3.0  # standard deviations: a normal draw beyond this is drawn again
# Relative standard deviation of each datasheet value (normal, truncated at 3 sd); "pair" fields are drawn per
# wheel, since a real robot's two motors, axles and tyres differ.
SPREAD = {
    "wheel_radius": 0.005, "torque_constant": 0.02, "armature_resistance": 0.03,
    "coulomb_friction": 0.04, "viscous_friction": 0.05,  # pairs
    "half_axle": 0.005, "com_offset": 0.05, "com_height": 0.05, "body_radius": 0.003, "body_mass": 0.02,
    "body_inertia": 0.04, "wheel_mass": 0.02, "wheel_inertia_diam": 0.04, "gear_efficiency": 0.015,
    "current_limit": 0.02, "battery_voltage": 0.015, "quiescent_current": 0.05, "floor_friction": 0.05,
}
INERTIA_SPREAD = 0.04  # the rotor's inertia seen through the gear
IR_GAIN_SPREAD = 0.05  # each IR pair's optical efficiency
IR_SHAPE_SPREAD = 0.05  # the IR curve's set-back, near field, fade and gloss
EDGES_PER_MOTOR_TURN = 24  # 12 CPR with x2 decoding: the edges' pattern repeats every motor turn
EDGE_SD = 0.08  # ticks: each edge's placement error (magnet poles, hall sensor hysteresis)


def _normal(rng: np.random.Generator) -> float:
    while True:
        z = float(rng.standard_normal())
        if abs(z) <= TRUNCATE:
            return z


def _scaled(rng: np.random.Generator, value: object, sd: float) -> object:
    if isinstance(value, tuple):
        return tuple(float(v) * (1.0 + sd * _normal(rng)) for v in value)
    return float(value) * (1.0 + sd * _normal(rng))  # type: ignore[arg-type]


def _datasheet_values(spec: PlantSpec, rng: np.random.Generator) -> PlantSpec:
    changes = {name: _scaled(rng, getattr(spec, name), sd) for name, sd in SPREAD.items()}
    changes["gear_efficiency"] = min(float(changes["gear_efficiency"]), 0.95)  # type: ignore[arg-type]
    # A rigid wheel's spin inertia is twice its diametral one at most: the wheel's own part follows the
    # drawn diametral inertia, the rotor's share is drawn apart.
    rotor = spec.rotor_inertia * (1.0 + INERTIA_SPREAD * _normal(rng))
    changes["rotor_inertia"] = rotor
    changes["wheel_inertia"] = rotor + 2.0 * float(changes["wheel_inertia_diam"])  # type: ignore[arg-type]
    changes["ir_gain_scale"] = tuple(1.0 + IR_GAIN_SPREAD * _normal(rng) for _ in range(8))
    ir = dict(spec.ir)
    for k in ("setback", "near_field", "fade_range", "gloss", "on_delay"):
        ir[k] = float(ir[k]) * (1.0 + IR_SHAPE_SPREAD * _normal(rng))
    changes["ir"] = ir
    return spec.replace(**changes)


def _missing_physics(spec: PlantSpec, rng: np.random.Generator) -> PlantSpec:
    """The physics the twin lacks, each on at a drawn level (docs/proving-ground.md gives the reasons)."""
    u = rng.uniform
    henry = DEFAULT.motor_inductance
    teeth = float(rng.choice([36.0, 40.0, 45.0, 50.0]))  # one gearbox design: the same output stage both sides
    edges = tuple(tuple(float(np.clip(EDGE_SD * rng.standard_normal(), -0.25, 0.25))
                        for _ in range(EDGES_PER_MOTOR_TURN)) for _ in range(2))
    ir = {**spec.ir, "noise": u(2.0, 5.0)}
    return spec.replace(
        # the winding a datasheet states (the twin's motor_inductance), each motor's within 15 % of it
        inductance=(henry * u(0.85, 1.15), henry * u(0.85, 1.15)), current_loop_hz=u(200.0, 500.0),
        stiction_ratio=(u(1.1, 1.35), u(1.1, 1.35)), stribeck_speed=u(0.5, 2.0),
        ripple=(u(0.01, 0.04), u(0.01, 0.04)), ripple_teeth=(teeth, teeth),
        ripple_phase=(u(-np.pi, np.pi), u(-np.pi, np.pi)), slip_stiffness=1.75 * u(8.0, 20.0),
        lateral_stiffness=u(1500.0, 4000.0), caster_rolling=u(0.001, 0.004), encoder_edges=edges,
        vbat_noise=u(0.003, 0.010), vbat_lsb=3.3 * 3 / 4096, ir=ir, period_jitter=u(0.001, 0.003),
        late_share=u(0.005, 0.02), drop_share=u(0.002, 0.01), tracker_noise_xy=u(0.0007, 0.0015),
        tracker_noise_phi=float(np.radians(u(0.2, 0.4))))


def draw_robot(seed: int) -> PlantSpec:
    """Case `seed`'s robot: the datasheet drawn, then the missing physics drawn (a stream of its own, so the
    effect, the world and the drive of a case do not depend on it)."""
    rng = np.random.default_rng([seed, 2024, 7])
    return _missing_physics(_datasheet_values(datasheet_spec(), rng), rng)
