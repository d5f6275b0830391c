"""The library's drive effects are physics in the twin (host_sim/physics/drivetrain_effects.py, docs/effects.md).

Each effect is checked on a case worked out by hand (a steady speed, a turning
radius, a shifted response, an encoder count), on the batch path; SimRobot and
BatchSim are checked to agree with each effect on, walls and slip included; a
parameter file with the effects loads and `twinbot sim --params` runs with it.
Absent effects leave the twin as it was: the golden vectors, repeatability and
scalar/batch tests guard that.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from host_sim.physics import drivetrain_effects, motors
from host_sim.robot.batch import BatchSim
from host_sim.controller.hardware_io import Actuate
from host_sim.physics.params import DEFAULT, load_params
from host_sim.robot.sim_robot import SimRobot
from host_sim.physics.world import World, builtin_world
from tests.helpers import run_twinbot

P = DEFAULT
ETA_N_KT = P.gear_efficiency * P.gear_ratio * P.torque_constant  # N m/A at the wheel
FLAT = P.replace(com_offset=0.0)  # no gyroscopic coupling: the steady states below are exact
I_LOW = 0.02  # A: well inside what the battery allows at the speeds it gives


def steady_speeds(p, i_l: float, i_r: float, seconds: float = 6.0) -> tuple[np.ndarray, BatchSim]:
    """(wheel speeds (2,) rad/s at the end, the simulator) after `seconds` at constant current references."""
    sim = BatchSim(None, p, np.zeros((1, 3)))
    sim.run_inputs(np.tile([i_l, i_r], (int(seconds / 0.04), 1)), sensors=False)
    return sim.v[0].copy(), sim


def balance_speed(i: float, extra_torque: float = 0.0, c_v: float = P.viscous_friction,
                  t_c: float = P.coulomb_friction, eta_n_kt: float = ETA_N_KT) -> float:
    """A wheel's steady speed where the motor balances the friction (tanh = 1) and a load extra_torque."""
    return (eta_n_kt * i - t_c - extra_torque) / c_v


# --------------------------------------------------------------------------- #
# Each effect, by hand
# --------------------------------------------------------------------------- #
def test_absent_effects_take_the_nominal_path():
    assert not drivetrain_effects.active(P)
    assert BatchSim(None, P)._fx is None and BatchSim(None, P)._delay is None
    assert SimRobot(World(name="e", size=(1.0, 1.0), walls=[]), P).batch._floats  # one robot, Python floats


@pytest.mark.parametrize("wheel", ["l", "r"])
def test_viscous_friction_lowers_that_wheels_steady_speed(wheel):
    extra = 2e-4
    v, _ = steady_speeds(FLAT.replace(**{f"viscous_friction_delta_{wheel}": extra}), I_LOW, -I_LOW)
    k = "lr".index(wheel)  # opposite currents: a spin in place, each wheel in its own balance
    expect = balance_speed(I_LOW, c_v=P.viscous_friction + extra)
    other = balance_speed(I_LOW)
    assert abs(v[k]) == pytest.approx(expect, rel=2e-3)
    assert abs(v[1 - k]) == pytest.approx(other, rel=2e-3)
    assert expect < 0.6 * other


@pytest.mark.parametrize("wheel", ["l", "r"])
def test_dry_friction_lowers_that_wheels_steady_speed_by_delta_over_c_v(wheel):
    extra = 5e-4
    v, _ = steady_speeds(FLAT.replace(**{f"coulomb_friction_delta_{wheel}": extra}), I_LOW, -I_LOW)
    k = "lr".index(wheel)
    assert abs(v[k]) == pytest.approx(balance_speed(I_LOW, t_c=P.coulomb_friction + extra), rel=2e-3)
    assert abs(v[1 - k]) == pytest.approx(balance_speed(I_LOW), rel=2e-3)


def test_torque_constant_sets_torque_and_back_emf():
    dk = 5e-4
    p = FLAT.replace(torque_constant_delta_l=dk)
    k_l = P.torque_constant + dk
    # current-regulated: the torque scales with k
    v, _ = steady_speeds(p, I_LOW, -I_LOW)
    assert abs(v[0]) == pytest.approx(balance_speed(I_LOW, eta_n_kt=ETA_N_KT * k_l / P.torque_constant), rel=2e-3)
    # battery-limited (0.5 A asked): i = (V - k N w) / R, no-load speed (eta k N V / R - T_c) / (eta (k N)^2 / R + c_v)
    v, _ = steady_speeds(p, 0.5, -0.5)
    for k, kt in ((0, k_l), (1, P.torque_constant)):
        kn = kt * P.gear_ratio
        w = (P.gear_efficiency * kn * P.battery_voltage / P.armature_resistance - P.coulomb_friction) / (
            P.gear_efficiency * kn * kn / P.armature_resistance + P.viscous_friction)
        assert abs(v[k]) == pytest.approx(w, rel=2e-3)


def test_unequal_radii_curve_with_the_predicted_radius():
    dr = 1e-3
    p = FLAT.replace(wheel_radius_delta_r=dr)
    v, sim = steady_speeds(p, I_LOW, I_LOW, seconds=14.0)
    # both wheels in their own balance (no coupling with d = 0): equal spin, unequal rims
    assert v[0] == pytest.approx(v[1], rel=1e-6)
    r_l, r_r = P.wheel_radius, P.wheel_radius + dr
    radius = P.half_axle * (r_l + r_r) / (r_r - r_l)  # 2.06 m
    u = 0.5 * (r_l * v[0] + r_r * v[1])
    omega = 0.5 * (r_r * v[1] - r_l * v[0]) / P.half_axle
    assert u / omega == pytest.approx(radius, rel=1e-6)
    # and the pose follows: over 2 s more the heading turns by distance / radius
    start = sim.pose[0].copy()
    res = sim.run_inputs(np.tile([I_LOW, I_LOW], (50, 1)), sensors=False)
    end = sim.pose[0]
    chord = math.dist(start[:2], end[:2])
    assert end[2] - start[2] == pytest.approx(2 * math.asin(chord / (2 * radius)), rel=1e-4)
    assert res.pose.shape == (50, 1, 3)


@pytest.mark.parametrize("dr", [0.0, 2e-3])
def test_wheels_slipping_against_a_wall_turn_at_the_speed_their_rim_friction_allows(dr):
    """Driven head-on into a wall at 0.5 A, both wheels slip (the contact step) while the robot stands:
    the battery-limited motor torque equals the floor's friction at the rim, r_i mu N."""
    wall = World(name="wall", size=(2.0, 2.0), walls=[{"segment": [1.0, -1.0, 1.0, 1.0]}])
    p = P.replace(wheel_radius_delta_l=dr, wheel_radius_delta_r=dr)
    sim = BatchSim(wall, p, [[1.0 - P.body_radius - 0.01, 0.0, 0.0]])
    sim.run_inputs(np.tile([0.5, 0.5], (75, 1)), sensors=False)
    assert sim.slipping[0]
    kn = P.torque_constant * P.gear_ratio
    mu_n = P.wheel_friction * (P.body_mass + 2 * P.wheel_mass) * 9.81 / 2
    # eta k N (V - k N w) / R - c_v w - T_c = r mu N
    w = (P.gear_efficiency * kn * P.battery_voltage / P.armature_resistance - P.coulomb_friction
         - (P.wheel_radius + dr) * mu_n) / (P.gear_efficiency * kn * kn / P.armature_resistance + P.viscous_friction)
    assert sim.v[0] == pytest.approx([w, w], rel=1e-3)


def test_encoder_scale_counts_that_wheels_turns():
    p = P.replace(ticks_per_rev_delta_r=60.0)
    robot = SimRobot(World(name="e", size=(1.0, 1.0), walls=[]), p, (0.5, 0.5, 0.0), noise=False)
    robot.q = robot.q[:3] + (2 * math.pi * 3.25, 2 * math.pi * 3.25)
    assert robot.encoder_ticks() == (3900, 4095)  # 3.25 turns of 1200 and of 1260 counts
    sim = BatchSim(None, p, q=[robot.q])
    assert sim.encoder_ticks().tolist() == [[3900, 4095]]
    assert motors.encoder_angle(4095, p, 1) == pytest.approx(2 * math.pi * 4095.5 / 1260)


@pytest.mark.parametrize("delay", [0.060, 0.0125])
def test_actuator_delay_shifts_the_response_by_the_delay(delay):
    cmd = np.zeros((60, 2))
    cmd[5:] = [0.2, 0.1]
    late = BatchSim(None, P.replace(actuator_delay=delay), np.zeros((1, 3))).run_inputs(cmd, sensors=False, substeps=8)
    on_time = BatchSim(None, P, np.zeros((1, 3))).run_inputs(cmd, sensors=False, substeps=80)
    t = on_time.t
    for k in range(2):
        shifted = np.interp(late.t - delay, t, on_time.theta[:, 0, k], left=0.0)
        assert np.abs(late.theta[:, 0, k] - shifted).max() < 2e-3 * np.abs(shifted).max()
    assert (late.theta[: 5 + int(delay / 0.04), 0] == 0).all()  # nothing moves before the command arrives


def test_a_delayed_run_starting_mid_stream_uses_the_commands_already_sent():
    cmd = np.tile([0.2, 0.2], (10, 1))
    sim = BatchSim(None, P.replace(actuator_delay=0.08), np.zeros((1, 3)))
    sim.seed_commands([-0.12, -0.08, -0.04], [[0.0, 0.0], [0.2, 0.2], [0.2, 0.2]])
    res = sim.run_inputs(cmd, sensors=False)
    assert res.theta[1, 0, 0] > 0  # the command sent 80 ms before the start arrives at once


ROTOR_INERTIA = P.wheel_inertia - 2 * P.wheel_inertia_diam  # the motor side, at the wheel: all but the wheel's own
NO_AXLE_FRICTION = P.replace(coulomb_friction=0.0, viscous_friction=0.0)


def test_backlash_the_rotor_crosses_the_play_in_the_time_its_inertia_and_torque_give():
    """From rest at a small current the rotor (the motor side) alone accelerates across half the play under the
    motor torque less the dry friction; the wheel stays exactly at rest until the gap closes."""
    play, i = 0.1, 0.05
    p = P.replace(viscous_friction=0.0, backlash_l=play, backlash_r=play)
    sim = BatchSim(None, p, np.zeros((1, 3)))
    tau_net = ETA_N_KT * i - P.coulomb_friction
    alpha = tau_net / ROTOR_INERTIA
    t_close = math.sqrt(2 * (0.5 * play) * ROTOR_INERTIA / tau_net)  # 12.1 ms (the massless model: 2.6 ms)
    dt, wheel, motor = 1e-4, [], []
    for _ in range(200):  # 20 ms
        sim.substep([i, i], dt)
        wheel.append(sim.q[0, 3])
        motor.append(sim.encoder_angles()[0, 0])
    t = dt * np.arange(1, 201)
    before = t < t_close - 1e-9
    assert (np.array(wheel)[before] == 0.0).all()  # not driven while the gap is open
    assert np.array(motor)[before] == pytest.approx(0.5 * alpha * t[before] ** 2, rel=1e-9)  # the encoder counts it
    assert (np.array(wheel)[~before] > 0).all()  # moving from the step in which the gap closed
    assert np.array(motor)[-1] - wheel[-1] == pytest.approx(0.5 * play, abs=1e-12)  # closed on the driving side


def test_backlash_on_a_reversal_the_wheel_coasts_while_the_rotor_crosses_the_play():
    """No motor torque and no axle friction reach the wheel while the gap is open (FLAT, no caster: nothing
    else acts on a robot going straight), then the rotor brakes it."""
    play = 0.2
    sim = BatchSim(None, FLAT.replace(backlash_l=play, backlash_r=play), np.zeros((1, 3)))
    sim.run_inputs(np.tile([0.2, 0.2], (10, 1)), sensors=False)
    w_before = sim.v[0, 0]
    assert sim.gear_gap[0, 0] == 0.5 * play and w_before > 5
    dt, coasting = 1e-4, 0
    while sim.gear_gap[0, 0] > -0.5 * play:
        sim.substep([-0.2, -0.2], dt)
        if sim.gear_gap[0, 0] > -0.5 * play:
            assert sim.v[0] == pytest.approx([w_before, w_before], rel=1e-12)
            coasting += 1
    # the rotor went from the wheel's speed to past it the other way, I_r over (eta N k i + friction)
    assert coasting > 0.5 * ROTOR_INERTIA * w_before / (ETA_N_KT * 0.2) / dt
    for _ in range(100):
        sim.substep([-0.2, -0.2], dt)
    assert sim.gear_gap[0, 0] == -0.5 * play and sim.v[0, 0] < w_before - 0.3


def test_backlash_the_impact_at_engagement_conserves_momentum():
    """Left gear with play, right rigid, no friction, no body forces, G on the axle (no gyroscopic terms):
    with the current off, the generalised momentum in (u, omega) of the wheels' side plus the free rotor's
    stays what it was, across the impact that closes the gap; the impact leaves rotor and wheel together."""
    p = NO_AXLE_FRICTION.replace(com_offset=0.0, backlash_l=0.1)
    sim = BatchSim(None, p, np.zeros((1, 3)))
    sim.run_inputs(np.tile([0.2, 0.2], (5, 1)), sensors=False)
    for _ in range(10):
        sim.substep([-0.3, 0.0], 2e-4)  # the left rotor falls back from its wheel: the gear opens
    assert abs(sim.gear_gap[0, 0]) < 0.05 and sim.rotor_speed[0, 0] < sim.v[0, 0]
    r, b, i_r = P.wheel_radius, P.half_axle, ROTOR_INERTIA
    m = P.body_mass + 2 * P.wheel_mass
    j = P.body_inertia + 2 * P.wheel_mass * b * b + 2 * P.wheel_inertia_diam
    own_l, own_r = (P.wheel_inertia - i_r) / r ** 2, P.wheel_inertia / r ** 2  # the left wheel without its rotor

    def momentum() -> np.ndarray:
        u, om = 0.5 * r * (sim.v[0, 0] + sim.v[0, 1]), 0.5 * r * (sim.v[0, 1] - sim.v[0, 0]) / b
        h = np.array([[m + own_l + own_r, b * (own_r - own_l)], [b * (own_r - own_l), j + b * b * (own_l + own_r)]])
        return h @ [u, om] + i_r * sim.rotor_speed[0, 0] / r * np.array([1.0, -b])

    before, closed = momentum(), False
    for _ in range(400):
        sim.substep([0.0, 0.0], 2e-4)
        closed |= sim.gear_gap[0, 0] == -0.05
        np.testing.assert_allclose(momentum(), before, rtol=1e-12, atol=1e-15)
    assert closed and sim.rotor_speed[0, 0] == sim.v[0, 0]
    assert sim.v[0, 0] < sim.v[0, 1]  # the slower rotor braked the left wheel


def test_encoders_count_the_motor_side():
    p = P.replace(backlash_l=0.3)
    cmd = np.tile([0.2, 0.2], (10, 1))
    sim = BatchSim(None, p, np.zeros((1, 3)))
    res = sim.run_inputs(cmd, sensors=False)
    motor = sim.encoder_angles()[0]
    assert motor[0] - sim.q[0, 3] == pytest.approx(0.15) and motor[1] == sim.q[0, 4]  # left's motor 0.15 rad ahead
    assert sim.encoder_ticks()[0].tolist() == [math.floor(m / (2 * math.pi) * P.ticks_per_rev) for m in motor]
    assert res.theta[-1, 0, 0] > res.theta[-2, 0, 0] > 0


def battery_steady_speed(r_int: float) -> tuple[float, float]:
    """Straight, both wheels battery-limited: eta N k i = c_v w + T_c, i = (V - k N w) / R,
    V = V_bat - R_int (2 i + i_e); returns (w, V)."""
    kn = P.torque_constant * P.gear_ratio
    ekn = P.gear_efficiency * kn
    rr = P.armature_resistance + 2 * r_int
    v_open = P.battery_voltage - r_int * P.electronics_current  # what the motors find with no current of theirs
    w = (v_open - P.coulomb_friction * rr / ekn) / (kn + P.viscous_friction * rr / ekn)
    i = (P.viscous_friction * w + P.coulomb_friction) / ekn
    return w, v_open - 2 * r_int * i


def test_battery_resistance_sags_the_supply_and_the_top_speed():
    r_int = 4.0
    p = FLAT.replace(battery_resistance=r_int)
    sim = BatchSim(None, p, np.zeros((1, 3)))
    res = sim.run_inputs(np.tile([0.5, 0.5], (150, 1)), sensors=False)
    w, volts = battery_steady_speed(r_int)
    assert sim.v[0] == pytest.approx([w, w], rel=2e-3)
    assert res.vbat[-1, 0] == pytest.approx(volts, rel=1e-3)
    # at rest, before the first command: only the electronics draw
    assert res.vbat[0, 0] == pytest.approx(P.battery_voltage - r_int * P.electronics_current)
    assert res.vbat[1, 0] < res.vbat[-1, 0] - 1.0  # accelerating draws more than cruising
    assert battery_steady_speed(0.0)[0] - w > 2.0  # rad/s lost to the sag
    robot = SimRobot(World(name="e", size=(10.0, 10.0), walls=[]), p, (5.0, 5.0, 0.0), noise=False)
    robot.actuate(Actuate(500, 500, 0))
    for _ in range(150 * 8):
        robot.advance(0.005)
    assert robot.sense().vbat_mv == round(volts * 1000)


def test_battery_gives_the_switching_drivers_power_not_their_current():
    """Below full duty a PWM bridge draws u i / V from the battery (power balance), not i."""
    r_int, i = 2.0, I_LOW
    p = FLAT.replace(battery_resistance=r_int)
    v, sim = steady_speeds(p, i, i)
    w = float(v[0])
    u = P.armature_resistance * i + P.torque_constant * P.gear_ratio * w  # each motor's terminal voltage
    # V = V_bat - R_int (i_e + 2 u i / V), the positive root of V^2 - (V_bat - R_int i_e) V + 2 R_int u i = 0
    b = P.battery_voltage - r_int * P.electronics_current
    volts = (b + math.sqrt(b * b - 8 * r_int * u * i)) / 2
    assert u < 0.5 * volts  # part duty: the two models differ here
    assert sim.vbat[0] == pytest.approx(volts, rel=1e-9)
    assert sim.vbat[0] > P.battery_voltage - r_int * (P.electronics_current + 2 * i) + 0.05


def test_nominal_vbat_is_the_battery_voltage():
    res = BatchSim(None, P, np.zeros((2, 3))).run_inputs(np.tile([0.5, 0.5], (5, 1)), sensors=False)
    assert (res.vbat == P.battery_voltage).all() and res.vbat.shape == (5, 2)


def test_caster_drag_loads_both_wheels_by_f_r_over_2():
    drag = 0.05
    v, _ = steady_speeds(FLAT.replace(caster_drag=drag), I_LOW, I_LOW)
    w = balance_speed(I_LOW, extra_torque=drag * P.wheel_radius / 2)
    assert v == pytest.approx([w, w], rel=2e-3)
    assert w < 0.75 * balance_speed(I_LOW)


def test_caster_drag_resists_a_spin_through_its_lever():
    drag = 0.05
    v, _ = steady_speeds(FLAT.replace(caster_drag=drag), -I_LOW, I_LOW)
    # the caster at a = CASTER_BEHIND behind C slides sideways at a omega: moment a F about C
    a = drivetrain_effects.CASTER_BEHIND
    w = balance_speed(I_LOW, extra_torque=drag * a * P.wheel_radius / (2 * P.half_axle))
    assert np.abs(v) == pytest.approx([w, w], rel=2e-3)


def test_turning_resistance_resists_a_spin_not_a_straight_run():
    scrub = 0.003
    p = FLAT.replace(turning_resistance=scrub)
    v, _ = steady_speeds(p, -I_LOW, I_LOW)
    w = balance_speed(I_LOW, extra_torque=scrub * P.wheel_radius / (2 * P.half_axle))
    assert np.abs(v) == pytest.approx([w, w], rel=2e-3)
    straight, _ = steady_speeds(p, I_LOW, I_LOW)
    assert straight == pytest.approx([balance_speed(I_LOW)] * 2, rel=2e-3)


@pytest.mark.parametrize("grip", ["rolling", "sliding"])
def test_turning_resistance_holds_a_turn_below_it_to_the_creep_of_its_smoothing(grip):
    """A yaw moment of about half the scrub torque: the body creeps at the rate where the smoothed torque
    balances it, eps_w atanh(M / T_s) (4 mrad/s wide), rolling or with both wheels sliding on ice.  Taken
    explicitly, a torque this sharp overshoots 0 at every substep: the mean rate came out 5x too fast
    (rolling), and on ice 5x again unless the slide's step counts the wheels' moment (contact.slip_step_batch)."""
    scrub = 0.01  # the upper bound: the sharpest the fit tries
    if grip == "rolling":
        p = FLAT.replace(turning_resistance=scrub)
        moment = 0.5 * scrub  # each wheel pushes f = moment / 2b, beyond its axle's dry friction
        i = (moment / (2 * P.half_axle) * P.wheel_radius + P.coulomb_friction) / ETA_N_KT
    else:
        p = FLAT.replace(turning_resistance=scrub, wheel_friction=0.02)
        cap = p.wheel_friction * (p.body_mass + 2 * p.wheel_mass) * 9.81 / 2
        moment, i = 2 * P.half_axle * cap, 0.3  # the wheels spin, each sliding at its full grip
    sim = BatchSim(None, p, np.zeros((1, 3)))
    heading = []
    for _ in range(60):
        sim.run_inputs(np.array([[-i, i]]), sensors=False)
        heading.append(sim.q[0, 2])
    assert bool(sim.slipping[0]) == (grip == "sliding")
    eps = P.wheel_radius * drivetrain_effects.SCRUB_SMOOTHING_SPEED / P.half_axle
    rate = np.diff(heading[-11:]) / 0.04
    assert rate == pytest.approx(eps * math.atanh(moment / scrub), rel=0.01)


# --------------------------------------------------------------------------- #
# SimRobot == BatchSim with each effect, walls and slip included
# --------------------------------------------------------------------------- #
EFFECTS = {
    "dry_friction": {"coulomb_friction_delta_l": 2e-3},
    "viscous_friction": {"viscous_friction_delta_r": 3e-4},
    "wheel_radius": {"wheel_radius_delta_l": -1.5e-3},
    "torque_constant": {"torque_constant_delta_r": 8e-4},
    "encoder_scale": {"ticks_per_rev_delta_l": -90.0},
    "actuator_delay": {"actuator_delay": 0.07},
    "battery_resistance": {"battery_resistance": 3.0},
    "caster_drag": {"caster_drag": 0.1},
    "turning_resistance": {"turning_resistance": 0.004},
    "backlash": {"backlash_r": 0.25},
}


# A corner 15 cm ahead and 15 cm to the left; 3.2 s of changing references drive the robot into it.
CORNER = World(name="corner", size=(2.0, 2.0), walls=[{"segment": [0.8, -1.0, 0.8, 1.0]},
                                                      {"segment": [-1.0, 0.2, 1.0, 0.2]}])
CORNER_START = (0.5, 0.0, 0.3)
CORNER_CMD = np.repeat([[0.3, 0.3], [0.45, 0.1], [-0.2, 0.25], [0.35, 0.35], [0.0, 0.0], [0.2, 0.5],
                        [-0.3, -0.3], [0.5, 0.4]], 10, axis=0)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_simrobot_and_batchsim_agree_with_the_effect(name):
    """3.2 s of changing references by a corner: the robot drives into both walls and slips."""
    world, cmd = CORNER, CORNER_CMD
    p = P.replace(**EFFECTS[name])
    res = BatchSim(world, [p, P], np.tile(CORNER_START, (2, 1))).run_inputs(np.repeat(cmd[:, None], 2, 1),
                                                                             sensors=False)
    assert res.collisions.min() > 0
    robot = SimRobot(world, p, CORNER_START, noise=False)
    pose, enc, vbat = [], [], []
    for row in cmd:
        pose.append(robot.pose)
        enc.append(robot.encoder_ticks())
        vbat.append(robot.vbat)
        robot.actuate(Actuate(round(row[0] * 1000), round(row[1] * 1000), 60))
        for _ in range(8):
            robot.advance(0.005)
    np.testing.assert_allclose(res.pose[:, 0], pose, rtol=0, atol=1e-9)
    assert np.abs(res.enc[:, 0] - np.array(enc)).max() <= 1
    np.testing.assert_allclose(res.vbat[:, 0], vbat, rtol=0, atol=1e-9)
    assert robot.collisions == res.collisions[0]
    # and the effect changed something against the nominal robot beside it
    assert np.abs(res.pose[:, 0] - res.pose[:, 1]).max() > 1e-4 or (res.enc[:, 0] != res.enc[:, 1]).any()


# --------------------------------------------------------------------------- #
# From a parameter file
# --------------------------------------------------------------------------- #
def test_a_parameter_file_with_effects_loads_and_twinbot_sim_runs_with_it(tmp_path):
    values = {k: v for d in EFFECTS.values() for k, v in d.items()}
    path = tmp_path / "robot.json"
    path.write_text(json.dumps(values))
    p = load_params(path)
    assert all(getattr(p, k) == v for k, v in values.items())
    r = run_twinbot("sim", "--params", str(path), "--duration", "3", timeout=120)
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("entry,words", [
    ({"wheel_radius_delta_l": -0.03}, "wheel_radius_delta_l"),
    ({"actuator_delay": -0.01}, "actuator_delay"),
    ({"battery_resistance": -1.0}, "battery_resistance"),
    ({"ticks_per_rev_delta_r": -1200.0}, "ticks_per_rev_delta_r"),
])
def test_a_parameter_file_with_an_impossible_effect_is_refused(tmp_path, entry, words):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(entry))
    r = run_twinbot("sim", "--params", str(path), "--duration", "1", timeout=60)
    assert r.returncode == 2 and words in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_a_robot_with_effects_meets_a_wall_drawn_in_front_of_it():
    """SimRobot.set_world (the gui's world edits) reaches the BatchSim that carries the effects."""
    robot = SimRobot(World(name="e", size=(2.0, 2.0), walls=[]), P.replace(caster_drag=0.05), (0.5, 1.0, 0.0),
                     noise=False)
    robot.actuate(Actuate(150, 150, 0))
    for _ in range(40):
        robot.advance(0.005)
    robot.set_world(World(name="wall", size=(2.0, 2.0), walls=[{"segment": [0.7, 0.0, 0.7, 2.0]}]))
    for _ in range(600):
        robot.advance(0.005)
    assert robot.collisions == 1 and robot.pose[0] <= 0.7 - P.body_radius + 1e-9


TINY = {"coulomb_friction_delta_l": 1e-15, "viscous_friction_delta_r": 1e-15, "wheel_radius_delta_l": 1e-15,
        "torque_constant_delta_r": 1e-15, "backlash_l": 1e-15, "actuator_delay": 1e-15, "battery_resistance": 1e-15,
        "caster_drag": 1e-15, "turning_resistance": 1e-15}


@pytest.mark.parametrize("field", list(TINY))
def test_an_effect_enters_continuously_from_absent(field):
    """The effects' path with an effect of 1e-15 is the nominal twin to rounding (walls and slip included):
    the diagnosis's finite differences start from "absent" without a jump."""
    res = BatchSim(CORNER, [P.replace(**{field: TINY[field]}), P], np.tile(CORNER_START, (2, 1))).run_inputs(
        np.repeat(CORNER_CMD[:, None], 2, 1), sensors=False)
    assert res.collisions[1] > 0  # the nominal robot meets a wall: contact is compared too
    np.testing.assert_allclose(res.pose[:, 0], res.pose[:, 1], rtol=0, atol=1e-9)


def test_seeded_commands_continue_a_delayed_run_exactly():
    p = P.replace(actuator_delay=0.1)
    cmd = np.round(np.repeat(np.random.default_rng(0).uniform(-0.2, 0.3, (12, 2)), 5, axis=0), 3)
    whole = BatchSim(None, p, np.zeros((1, 3)))
    whole.run_inputs(cmd[:40], sensors=False)
    later = BatchSim(None, p, q=whole.q.copy(), v=whole.v.copy(), t=whole.t)
    later.seed_commands(whole.t - 0.04 * np.arange(6, 0, -1), cmd[34:40])
    assert np.array_equal(whole.run_inputs(cmd[40:], sensors=False).theta, later.run_inputs(cmd[40:], sensors=False).theta)


def test_a_replay_from_a_middle_row_has_the_delayed_commands_on_their_way(tmp_path, monkeypatch):
    from host_sim.recordings import replay
    from host_sim.recordings.recording import RecordingWriter, load_recording
    from host_sim.controller.sil import SilController
    from host_sim.loops.simulation import Simulation

    p = P.replace(actuator_delay=0.1)
    world = builtin_world("paper_room")
    path = tmp_path / "late.csv"
    with RecordingWriter(path, source="simulator", sample_period=0.04, robot=p.to_json(), world=world.to_dict(),
                         extra={"mode": "fixed"}) as w:
        Simulation(world, p, SilController(1), seed=1, recorder=w).run_fixed(4.0)
    rec = load_recording(path)
    seeded = np.abs(replay.replay_batch(rec, p, start=40, stop=60, sensors=False).enc[:, 0] - rec.enc[40:60]).max()
    monkeypatch.setattr(replay, "SEED_ROWS", 0)
    blind = np.abs(replay.replay_batch(rec, p, start=40, stop=60, sensors=False).enc[:, 0] - rec.enc[40:60]).max()
    # what remains is the start's wheel speeds, estimated from the counts around row 40
    assert seeded < 0.05 * blind


def test_a_sub_batch_asks_again_which_effects_its_own_robots_have():
    """Drive's flags (a caster's drag, a scrub, a bridge, a battery's resistance) and its wheels' mean radius are
    taken once per batch and steer every step; a sub-batch (Drive.sub, the robots that slip) takes its own, not
    its parent's: a robot without a caster keeps a caster-free step beside one with."""
    from host_sim.physics.dynamics import ParamBatch
    d = drivetrain_effects.Drive.of(ParamBatch.from_params([P.replace(caster_drag=0.05, battery_resistance=0.5),
                                                            P.replace(turning_resistance=0.001,
                                                                      wheel_radius_delta_r=0.001)]))
    assert d.dragged and d.resistive and d.scrubbed and not d.bridged
    assert d.r_mean == pytest.approx([P.wheel_radius, P.wheel_radius + 0.0005], rel=1e-12)
    alone = d.sub(np.array([1]))
    assert not alone.dragged and not alone.resistive and alone.scrubbed
    assert alone.r_mean == pytest.approx([P.wheel_radius + 0.0005], rel=1e-12)  # its own wheels' mean, not the batch's
    f_e, f_n, _m = drivetrain_effects.body_forces(np.array([0.1, 0.1]), np.zeros(2), np.zeros(2), d)
    assert f_e[0] < 0.0 and f_e[1] == 0.0 and f_n[1] == 0.0  # the caster drags its own robot only
    # without a caster or a scrub in the batch, the step skips their laws: the same figures, zeros' signs and all
    u, lat, om = np.array([0.1, -0.1, 0.0]), np.array([0.02, -0.03, 0.0]), np.array([0.3, -0.2, -0.0])
    bare = drivetrain_effects.Drive.of(ParamBatch.from_params([P] * 3))
    skipped = drivetrain_effects.body_forces(u, lat, om, bare)
    bare.__dict__.update(dragged=True, scrubbed=True)  # the laws in full, with zero drag and scrub
    for a, b in zip(skipped, drivetrain_effects.body_forces(u, lat, om, bare)):
        assert np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))
