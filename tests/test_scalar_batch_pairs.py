"""Each piece of physics has a scalar path (one robot, pure Python) and a batch path (N robots,
numpy) side by side in its module; here each pair is checked to agree, on seeded random
states, inputs and per-robot parameter sets far from the defaults (docs/dynamics.md).
Contact and the IR beam have their own pair tests, with their code.
"""
from __future__ import annotations

# Tolerances, and why:
# - dynamics.step vs step_batch, reduced_accel_fast vs reduced_accel_batch: the same closed
#   form with the floating-point operations grouped differently, so they agree to rounding:
#   1e-12 relative to the size of the terms summed (accel_scale), not bit for bit;
# - motors.wheel_torque vs wheel_torque_batch: the same regimes (current limit, supply voltage
#   less back-EMF, friction) by branches vs np.where: 1e-12 relative;
# - motors.encoder_ticks vs encoder_ticks_batch: a floor, so EXACTLY equal (same float
#   expression, and the ticks are what the firmware counts);
# - SimRobot vs BatchSim, open-loop driving away from walls: the pairs above compounded over
#   seconds: poses to 1e-9 m, ticks equal except within 1e-6 tick of a boundary.

import math

import numpy as np
import pytest

from host_sim.physics import dynamics as dy
from host_sim.physics import motors as mo
from host_sim.robot.batch import BatchSim
from host_sim.controller.hardware_io import Actuate
from host_sim.physics.params import DEFAULT as P
from host_sim.robot.sim_robot import SimRobot
from host_sim.physics.world import World
from tests.test_batch import assert_ticks_match
from tests.test_dynamics import accel_scale, random_params

N = 64
EMPTY = World(name="empty", size=(100.0, 100.0), walls=[])


@pytest.fixture(scope="module")
def robots() -> tuple[list, dy.ParamBatch, np.random.Generator]:
    rng = np.random.default_rng(4)
    params = [random_params(rng) for _ in range(N)]
    pb = dy.ParamBatch.from_params(params)
    assert all(pb.robot(i) == p for i, p in enumerate(params))
    return params, pb, rng


def random_state(rng: np.random.Generator, n: int = N) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q (n, 5), v (n, 2) rad/s, tau (n, 2) N m: far poses, headings of many turns, fast wheels."""
    q = np.column_stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(-40, 40, n),
                         rng.uniform(-500, 500, n), rng.uniform(-500, 500, n)])
    return q, rng.uniform(-50, 50, (n, 2)), rng.uniform(-0.1, 0.1, (n, 2))


# --------------------------------------------------------------------------- #
# host_sim/physics/dynamics.py
# --------------------------------------------------------------------------- #
def test_reduced_accel_fast_and_batch_agree(robots) -> None:
    params, pb, rng = robots
    q, v, tau = random_state(rng)
    acc = dy.reduced_accel_batch(q, v, tau, pb)
    for i, p in enumerate(params):
        scale = accel_scale(v[i], tau[i], p, q[i])
        assert np.abs(acc[i] - dy.reduced_accel_fast(q[i], v[i], tau[i], p)).max() <= 1e-12 * scale
    # one RobotParams shared by all robots
    shared = dy.reduced_accel_batch(q, v, tau, P)
    for i in (0, 31, 63):
        assert np.abs(shared[i] - dy.reduced_accel_fast(q[i], v[i], tau[i], P)).max() <= \
            1e-12 * accel_scale(v[i], tau[i], P, q[i])


def test_step_and_step_batch_agree(robots) -> None:
    params, pb, rng = robots
    q, v, tau = random_state(rng)
    dt = 0.004
    qn, vn = dy.step_batch(q, v, tau, dt, pb)
    for i, p in enumerate(params):
        scale = accel_scale(v[i], tau[i], p, q[i])
        qs, vs = dy.step(q[i], v[i], tau[i], dt, p)
        assert np.allclose(vn[i], vs, rtol=1e-12, atol=1e-12 * (np.abs(v[i]).max() + dt * scale))
        assert np.allclose(qn[i], qs, rtol=1e-12, atol=1e-12)
    # a shared RobotParams, a float dt, and writing in place give the same
    qn2, vn2 = dy.step_batch(q, v, tau, dt, dy.ParamBatch.broadcast(P, N))
    qc, vc = q.copy(), v.copy()
    dy.step_batch(qc, vc, tau, dt, P, out=(qc, vc))
    assert np.array_equal(qc, qn2) and np.array_equal(vc, vn2)
    # per-robot dt
    dts = rng.uniform(1e-3, 1e-2, N)
    qd_, vd_ = dy.step_batch(q, v, tau, dts, pb)
    for i in (0, 17, 63):
        qs, vs = dy.step(q[i], v[i], tau[i], float(dts[i]), params[i])
        assert np.allclose(qd_[i], qs, rtol=1e-12, atol=1e-12) and np.allclose(vd_[i], vs, rtol=1e-12)


# --------------------------------------------------------------------------- #
# host_sim/physics/motors.py
# --------------------------------------------------------------------------- #
def test_wheel_torque_and_batch_agree_in_every_regime(robots) -> None:
    params, pb, rng = robots
    _q, v, _tau = random_state(rng)
    v[:8] = 0.0  # at rest: the smoothed Coulomb friction's centre
    i_ref = rng.uniform(-1.5, 1.5, (N, 2))  # past the current limit (0.1..1 A) too
    t_b, i_b = mo.wheel_torque_batch(i_ref, v, pb)
    limited = 0
    for i, p in enumerate(params):
        for j in range(2):
            t_s, i_s = mo.wheel_torque(i_ref[i, j], v[i, j], p)
            assert t_b[i, j] == pytest.approx(t_s, rel=1e-12, abs=1e-15)
            assert i_b[i, j] == pytest.approx(i_s, rel=1e-12, abs=1e-15)
            limited += abs(i_s) < abs(i_ref[i, j]) - 1e-9
    assert 0 < limited < 2 * N  # both regimes were exercised: the current followed and was limited
    # (N,) arrays and a shared RobotParams
    t1, i1 = mo.wheel_torque_batch(i_ref[:, 0], v[:, 0], P)
    for i in (0, 9, 63):
        t_s, i_s = mo.wheel_torque(i_ref[i, 0], v[i, 0], P)
        assert t1[i] == pytest.approx(t_s, rel=1e-12, abs=1e-15) and i1[i] == pytest.approx(i_s, rel=1e-12)


def test_encoder_ticks_and_batch_agree_exactly(robots) -> None:
    params, pb, rng = robots
    q, _v, _tau = random_state(rng)
    ticks = mo.encoder_ticks_batch(q[:, 3:], pb)
    assert ticks.dtype == np.int64 and ticks.shape == (N, 2)
    for i, p in enumerate(params):
        for j in range(2):
            assert ticks[i, j] == mo.encoder_ticks(float(q[i, 3 + j]), p)
    # Angles on tick boundaries and one float either side, where another rounding would show:
    # 2000 per robot, (N, 2000) at once.
    k = rng.integers(-10**6, 10**6, (N, 2000))
    on = k * (2 * math.pi) / pb.ticks_per_rev[:, None]
    for theta in (on, np.nextafter(on, -np.inf), np.nextafter(on, np.inf)):
        batch = mo.encoder_ticks_batch(theta, pb)
        scalar = [[mo.encoder_ticks(float(x), p) for x in row] for row, p in zip(theta, params)]
        assert np.array_equal(batch, np.array(scalar))
    one = mo.encoder_ticks_batch(on[0], P)
    assert [int(t) for t in one] == [mo.encoder_ticks(float(x), P) for x in on[0]]


# --------------------------------------------------------------------------- #
# host_sim/robot/sim_robot.py SimRobot vs host_sim/robot/batch.py BatchSim
# --------------------------------------------------------------------------- #
def test_simrobot_and_batchsim_agree_driving_open_loop_away_from_walls(robots) -> None:
    """4 s (100 control periods, 8 substeps each) of changing current references, per-robot
    parameters, in an empty 100 m room: no contact, so only dynamics and motors are compared."""
    params, _pb, rng = robots
    chosen = params[:6]
    starts = np.column_stack([rng.uniform(45, 55, 6), rng.uniform(45, 55, 6), rng.uniform(-3, 3, 6)])
    cmd = np.round(np.repeat(rng.uniform(-0.4, 0.6, (10, 6, 2)), 10, axis=0), 3)  # A, held 0.4 s
    sim = BatchSim(EMPTY, chosen, starts)
    res = sim.run_inputs(cmd, sensors=False)
    for i, p in enumerate(chosen):
        robot = SimRobot(EMPTY, p, tuple(starts[i]), noise=False)
        pose, enc, theta = [], [], []
        for row in cmd[:, i]:
            pose.append(robot.pose)
            enc.append(robot.encoder_ticks())
            theta.append(robot.q[3:5])
            robot.actuate(Actuate(round(row[0] * 1000), round(row[1] * 1000), 60))
            for _ in range(8):
                robot.advance(0.04 / 8)
        np.testing.assert_allclose(res.pose[:, i], pose, rtol=0, atol=1e-9)
        assert_ticks_match(res.enc[:, i], np.array(enc), theta, p)
        assert robot.collisions == 0 and res.collisions[i] == 0
        assert math.dist(pose[0][:2], pose[-1][:2]) > 0.05  # it did drive
