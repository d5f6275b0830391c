"""Wall contact and wheel slip as physics (host_sim/contact.py; docs/dynamics.md "Contact").

A robot driven into walls: the result does not depend on the step, it turns to face a wall it
meets at an angle (friction at the rim), it stays out of both walls of a corner, contact never
adds energy, the collision counter counts contact starts, and the scalar and batch versions agree.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from host_sim import contact, dynamics
from host_sim.batch import BatchSim
from host_sim.interface import Actuate
from host_sim.params import DEFAULT
from host_sim.sim_robot import SimRobot
from host_sim.world import World

FLOOR = World(name="floor", size=(2.0, 2.0), walls=[{"segment": [-1.0, 0.0, 3.0, 0.0]}])
CORNER = World(name="corner", size=(2.0, 2.0),
               walls=[{"segment": [0.0, 0.0, 2.0, 0.0]}, {"segment": [0.0, 0.0, 0.0, 2.0]}])
BOX = World(name="box", size=(1.0, 1.0), walls=[
    {"segment": [0.0, 0.0, 1.0, 0.0]}, {"segment": [1.0, 0.0, 1.0, 1.0]}, {"segment": [1.0, 1.0, 0.0, 1.0]},
    {"segment": [0.0, 1.0, 0.0, 0.0]}, {"polygon": [[0.45, 0.45], [0.6, 0.45], [0.6, 0.6], [0.45, 0.6]]}])
R = DEFAULT.body_radius


def drive(world, pose, i_ma, seconds, dt, p=DEFAULT, each=None):
    robot = SimRobot(world, p, pose, noise=False)
    robot.actuate(Actuate(i_ma[0], i_ma[1], 0))
    for _ in range(round(seconds / dt)):
        robot.advance(dt)
        if each:
            each(robot)
    return robot


def gaps(world, robot):
    x, y, _ = robot.pose
    return world.wall_distances(np.array([[x, y]]))[0][0] - R


def test_driven_into_a_wall_the_pose_hardly_depends_on_the_step():
    """0.3 A on both wheels into the floor wall at 30 degrees, 2 s, dt = 0.2 / 1 / 5 ms: the final
    poses agree within 5 mm and 3 degrees (the old push-out crept 1.6 / 8.1 / 40.7 mm)."""
    poses = np.array([drive(FLOOR, (0.5, 0.2, math.radians(-30)), (300, 300), 2.0, dt).pose
                      for dt in (0.0002, 0.001, 0.005)])
    spread = poses.max(0) - poses.min(0)
    assert spread[0] < 0.01 and spread[1] < 1e-9 and math.degrees(spread[2]) < 8
    fine = np.abs(poses[1] - poses[0])  # 1 ms against 0.2 ms: first order, 5x closer
    assert fine[0] < 0.003 and math.degrees(fine[2]) < 2.0


def test_a_robot_driven_into_a_wall_at_30_degrees_turns_to_face_it():
    """Rim friction at the contact point turns a round robot pushing at an angle towards the wall's
    normal; the wheels slip and the encoders keep counting.  Without rim friction the mechanism is gone:
    the offset centre of mass and the wheels' sideways friction turn it the other way, along the wall."""
    heading = []
    robot = drive(FLOOR, (0.5, 0.2, math.radians(-30)), (300, 300), 3.0, 0.001,
                  each=lambda r: heading.append(r.pose[2]))
    off_normal = np.abs(np.degrees(np.array(heading)) + 90)
    assert off_normal[0] == pytest.approx(60, abs=0.5) and off_normal[-1] < 10
    assert robot.pose[1] == pytest.approx(R, abs=1e-6)  # resting on the wall, not in it
    assert robot.collisions == 1 and robot.slip is not None and min(robot.encoder_ticks()) > 5000
    frictionless = drive(FLOOR, (0.5, 0.2, math.radians(-30)), (300, 300), 3.0, 0.001,
                         p=DEFAULT.replace(wall_friction=0.0))
    assert -20 < math.degrees(frictionless.pose[2]) < 0


def test_a_robot_in_a_corner_stays_out_of_both_walls():
    worst = []
    robot = drive(CORNER, (0.3, 0.3, math.radians(-135)), (400, 350), 4.0, 0.005,
                  each=lambda r: worst.append(gaps(CORNER, r).min()))
    assert min(worst) > -1e-9
    assert np.all(gaps(CORNER, robot) < 1e-3)  # it did reach both walls
    assert robot.collisions >= 1


@pytest.mark.parametrize("friction", [True, False])
def test_energy_never_grows_in_contact(friction):
    """No current, thrown at a wall at 0.6 m/s and spinning: the kinetic energy only falls (motor
    friction on or off), through the impact and the sliding after it."""
    p = DEFAULT if friction else DEFAULT.replace(viscous_friction=0.0, coulomb_friction=0.0,
                                                 battery_voltage=100.0)
    robot = SimRobot(CORNER, p, (0.15, 0.2, math.radians(-120)), noise=False)
    robot.v = dynamics.wheel_speeds(0.6, 3.0, p)
    energy, pushed = [], []

    def kinetic(r):
        if r.slip is None:
            return dynamics.kinetic_energy_reduced(r.v, p)
        u, l, om = r.slip
        m, k, j = contact.consts(p)[:3]
        return 0.5 * (m * (u * u + l * l) + 2 * k * l * om + j * om * om
                      + p.wheel_inertia * (r.v[0] ** 2 + r.v[1] ** 2))

    for _ in range(400):
        e0 = kinetic(robot)
        robot.advance(0.002)
        energy.append(kinetic(robot) - e0)
        pushed.append(robot.in_contact)
    assert any(pushed) and robot.collisions >= 1
    assert max(energy) <= 1e-12 * kinetic(SimRobot(CORNER, p, noise=False)) + 1e-15


def test_the_collision_counter_counts_contact_starts():
    """Drive into the wall, back off 10 cm, drive in again: two contacts, however long each lasts."""
    robot = SimRobot(FLOOR, DEFAULT, (0.5, 0.15, -math.pi / 2), noise=False)
    for i_ma, seconds in ((200, 1.0), (-200, 0.6), (200, 1.0)):
        robot.actuate(Actuate(i_ma, i_ma, 0))
        for _ in range(round(seconds / 0.005)):
            robot.advance(0.005)
    assert robot.collisions == 2 and robot.in_contact


def test_batch_and_scalar_contact_agree_on_random_scenarios_with_corners():
    """N robots thrown at random into a box with an obstacle (corners included), random currents and
    per-robot friction: BatchSim == SimRobot for each, to rounding."""
    rng = np.random.default_rng(8)
    n = 12
    poses = np.column_stack([rng.uniform(0.1, 0.35, n), rng.uniform(0.1, 0.35, n), rng.uniform(-np.pi, np.pi, n)])
    poses[:4, :2] = [[0.08, 0.08], [0.92, 0.08], [0.08, 0.92], [0.92, 0.92]]  # in the corners
    params = [DEFAULT.replace(wheel_friction=float(rng.uniform(0.3, 1.0)), wall_friction=float(rng.uniform(0, 0.6)))
              for _ in range(n)]
    cmd = np.repeat(np.round(rng.uniform(-0.2, 0.5, (6, n, 2)), 3), 15, axis=0)
    res = BatchSim(BOX, params, poses).run_inputs(cmd, sensors=False)
    slipped = 0
    for i in range(n):
        robot = SimRobot(BOX, params[i], tuple(poses[i]), noise=False)
        for row in range(len(cmd)):
            assert np.abs(np.array(robot.pose) - res.pose[row, i]).max() < 1e-9, (i, row)
            robot.actuate(Actuate(round(cmd[row, i, 0] * 1000), round(cmd[row, i, 1] * 1000), 60))
            for _ in range(8):
                robot.advance(0.005)
                slipped += robot.slip is not None
        assert robot.collisions == res.collisions[i]
    assert res.collisions.sum() >= n and slipped > 100  # contacts and slip were exercised


def test_traction_scalar_and_batch_agree_and_a_full_current_start_slips():
    rng = np.random.default_rng(3)
    v0, v1 = rng.uniform(-30, 30, (200, 2)), rng.uniform(-30, 30, (200, 2))
    tau = rng.uniform(-0.1, 0.1, (200, 2))
    batch = contact.traction_ok_batch(v0, v1, tau, 0.005, DEFAULT)
    assert list(batch) == [contact.traction_ok(v0[i], v1[i], tau[i], 0.005, DEFAULT) for i in range(200)]
    assert 0 < batch.sum() < 200
    slips = {150: 0, 500: 0}
    for i_ma in slips:
        def count(r, i_ma=i_ma):
            slips[i_ma] += r.slip is not None
        fast = drive(FLOOR, (0.5, 1.0, 0.0), (i_ma, i_ma), 0.3, 0.005, each=count)
    assert slips[150] == 0 and slips[500] > 5  # 7.7 N of thrust from rest against mu m g = 4 N
    assert fast.pose[1] == pytest.approx(1.0, abs=1e-12)  # straight: it spins its wheels, no sideways drift
