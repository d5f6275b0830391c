"""Wall contact and wheel slip as physics (host_sim/physics/contact.py; docs/dynamics.md "Contact").

A robot driven into walls: the result does not depend on the step, it turns to face a wall it
meets at an angle (friction at the rim), it stays out of both walls of a corner, contact never
adds energy, the collision counter counts contact starts, and the scalar and batch versions agree.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from host_sim.physics import contact, dynamics
from host_sim.robot.batch import BatchSim
from host_sim.controller.hardware_io import Actuate
from host_sim.physics.params import DEFAULT
from host_sim.robot.sim_robot import SimRobot
from host_sim.physics.world import World
from tests import test_dynamics as reference  # the reference formulas (written out there)

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


@pytest.mark.parametrize("angle, i_ma", [(-30, 300), (-60, 150)])
def test_driven_into_a_wall_the_pose_hardly_depends_on_the_step(angle, i_ma):
    """Into the floor wall at 30 degrees (0.3 A, the wheels slip) and at 60 degrees (0.15 A), 2 s,
    dt = 0.2 / 1 / 5 ms: the final poses agree within 2 mm and 1 degree, 0.3 mm and 0.1 degree between
    0.2 and 1 ms (measured 1.2 mm / 0.0 deg and 1.0 mm / 0.5 deg; the old push-out crept 1.6 / 8.1 /
    40.7 mm along the wall)."""
    poses = np.array([drive(FLOOR, (0.5, 0.2, math.radians(angle)), (i_ma, i_ma), 2.0, dt).pose
                      for dt in (0.0002, 0.001, 0.005)])
    for group, (mm, deg) in ((poses, (2.0, 1.0)), (poses[:2], (0.3, 0.1))):
        spread = group.max(0) - group.min(0)
        assert 1000 * math.hypot(spread[0], spread[1]) < mm and math.degrees(spread[2]) < deg
    assert abs(poses[0, 0] - 0.5) > 0.05  # it did slide along the wall


def test_a_robot_driven_into_a_wall_at_30_degrees_turns_to_face_it():
    """Rim friction at the contact point turns a round robot pushing at an angle until it faces the
    wall; the wheels slip and the encoders keep counting.  Without rim friction the mechanism is
    gone: it turns a few degrees at the impact (its centre of mass is ahead of the axle) and then
    slides along the wall at a constant heading."""
    heading = []
    robot = drive(FLOOR, (0.5, 0.2, math.radians(-30)), (300, 300), 3.0, 0.001,
                  each=lambda r: heading.append(r.pose[2]))
    off_normal = np.abs(np.degrees(np.array(heading)) + 90)
    assert off_normal[0] == pytest.approx(60, abs=0.5) and off_normal[-1] < 0.1
    assert off_normal[len(off_normal) // 3] < 5  # within a second
    assert robot.pose[1] == pytest.approx(R, abs=1e-6)  # resting on the wall, not in it
    assert robot.collisions == 1 and robot.slip is not None and min(robot.encoder_ticks()) > 5000
    heading.clear()
    frictionless = drive(FLOOR, (0.5, 0.2, math.radians(-30)), (300, 300), 3.0, 0.001,
                         p=DEFAULT.replace(wall_friction=0.0), each=lambda r: heading.append(r.pose[2]))
    late = np.degrees(heading[len(heading) // 3:])
    assert -40 < late.min() and late.max() < -30 and np.ptp(late) < 0.2
    assert frictionless.pose[0] > 1.5  # slid along the wall


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
    robot.v = reference.wheel_speeds(0.6, 3.0, p)
    energy, pushed = [], []

    def kinetic(r):
        if r.slip is None:
            return reference.kinetic_energy_reduced(r.v, p)
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


@pytest.mark.parametrize("vector_from", [1, 64])
def test_batch_and_scalar_contact_agree_on_random_scenarios_with_corners(vector_from):
    """N robots thrown at random into a box with an obstacle (corners included), random currents and
    per-robot friction: BatchSim == SimRobot for each, to rounding; BatchSim's contact steps
    vectorised (contact.slip_step_batch) or, for few robots, one by one (contact.slip_step)."""
    rng = np.random.default_rng(8)
    n = 12
    poses = np.column_stack([rng.uniform(0.1, 0.35, n), rng.uniform(0.1, 0.35, n), rng.uniform(-np.pi, np.pi, n)])
    poses[:4, :2] = [[0.08, 0.08], [0.92, 0.08], [0.08, 0.92], [0.92, 0.92]]  # in the corners
    params = [DEFAULT.replace(wheel_friction=float(rng.uniform(0.3, 1.0)), wall_friction=float(rng.uniform(0, 0.6)))
              for _ in range(n)]
    cmd = np.repeat(np.round(rng.uniform(-0.2, 0.5, (6, n, 2)), 3), 15, axis=0)
    sim = BatchSim(BOX, params, poses)
    sim.vector_contacts_from = vector_from
    res = sim.run_inputs(cmd, sensors=False)
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


def random_slip_states(n, seed=11):
    """n robots' states for one contact step: slipping or rolling, zero to two walls in reach (corners),
    per-robot parameters, a previous step's forces (some axle torques beyond their bound)."""
    from host_sim.physics.dynamics import ParamBatch
    from host_sim.physics import motors

    rng = np.random.default_rng(seed)
    params = [DEFAULT.replace(wheel_friction=float(rng.uniform(0.2, 1.0)), wall_friction=float(rng.uniform(0, 0.6)),
                              com_offset=float(rng.uniform(0, 0.03)), body_mass=float(rng.uniform(0.3, 0.8)))
              for _ in range(n)]
    pb = ParamBatch.from_params(params)
    q = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-4, 4, n), rng.uniform(-9, 9, (n, 2))])
    v = rng.uniform(-30, 30, (n, 2))
    body = np.column_stack([rng.uniform(-0.5, 0.5, n), rng.uniform(-0.2, 0.2, n), rng.uniform(-5, 5, n)])
    slipping = rng.random(n) < 0.5
    i_ref = rng.uniform(-0.5, 0.5, (n, 2))
    n_walls = rng.integers(0, 3, n)
    gaps = np.full((n, 2), np.inf)
    normals = np.zeros((n, 2, 2))
    normals[..., 0] = 1.0
    for i in range(n):
        for w in range(n_walls[i]):
            a = rng.uniform(-np.pi, np.pi)
            gaps[i, w] = rng.uniform(-1e-4, 3e-3)
            normals[i, w] = (math.cos(a), math.sin(a))
    warm_wheels = rng.uniform(-1, 1, (2, 2, n)) * np.array([p.wheel_friction for p in params]) * 0.7
    axle_torques = rng.uniform(-1.5, 1.5, (2, 1, n)) * DEFAULT.coulomb_friction  # some beyond the bound: clipped
    warm_wheels = np.concatenate([warm_wheels, axle_torques], axis=1)
    warm_walls = np.stack([rng.uniform(0, 3, (2, n)), rng.uniform(-0.1, 0.1, (2, n))])
    warm_walls[:, ~np.isfinite(gaps.T)] = 0.0
    tau, _c, slope = motors.wheel_torque_slope_batch(i_ref, v, pb)
    body_b = np.where(slipping[:, None], body, np.column_stack(contact.body_velocity(v.T, pb)))
    return dict(params=params, pb=pb, q=q, v=v, body=body, body_b=body_b, slipping=slipping, i_ref=i_ref,
                n_walls=n_walls, gaps=gaps, normals=normals, warm_wheels=warm_wheels, warm_walls=warm_walls,
                tau=tau, slope=slope)


def test_slip_step_scalar_and_batch_agree_function_by_function():
    """contact.slip_step == contact.slip_step_batch on random states: slipping or rolling, zero to two
    walls in reach (corners), with and without a warm start, per-robot parameters."""
    from host_sim.physics import motors

    n = 40
    st = random_slip_states(n)
    params, pb, q, v, body, body_b, slipping, i_ref = (st[k] for k in (
        "params", "pb", "q", "v", "body", "body_b", "slipping", "i_ref"))
    n_walls, gaps, normals, warm_wheels, warm_walls, tau, slope = (st[k] for k in (
        "n_walls", "gaps", "normals", "warm_wheels", "warm_walls", "tau", "slope"))
    for warm in (False, True):
        out = contact.slip_step_batch(q, v, body_b, tau, slope, 0.005, pb, gaps, normals, None,
                                      warm_wheels if warm else None, warm_walls if warm else None)
        for i in range(n):
            walls = [(gaps[i, w], normals[i, w, 0], normals[i, w, 1], w) for w in range(n_walls[i])]
            w_s = (warm_wheels[:, :, i].tolist(), warm_walls[:, :n_walls[i], i].T.tolist()) if warm else None
            tl, _il, sl = motors.wheel_torque_slope(i_ref[i, 0], v[i, 0], params[i])
            tr, _ir, sr = motors.wheel_torque_slope(i_ref[i, 1], v[i, 1], params[i])
            assert np.allclose((tl, tr, sl, sr), (*tau[i], *slope[i]), rtol=1e-12, atol=1e-15)
            qs, vs, bs, pushed, forces = contact.slip_step(q[i], v[i], tuple(body[i]) if slipping[i] else None,
                                                          (tl, tr), (sl, sr), 0.005, params[i], walls, w_s)
            assert np.allclose(out[0][i], qs, rtol=1e-10, atol=1e-10)
            assert np.allclose(out[1][i], vs, rtol=1e-9, atol=1e-8)
            assert (bs is None) == bool(out[3][i]) and pushed == bool(out[4][i])
            if bs is not None:
                assert np.allclose(out[2][i], bs, rtol=1e-9, atol=1e-9)
            assert np.allclose(out[5][:, :, i], forces[0], rtol=1e-8, atol=1e-8)  # with the axles' torques
            assert all(abs(f[2]) <= params[i].coulomb_friction * (1 + 1e-12) for f in forces[0])
    assert out[3].sum() > 0 and (~out[3]).sum() > 0 and out[4].sum() > 0  # gripping, slipping and pushed


def _solved_with(monkeypatch, setting, values):
    """For each value of contact's `setting`: the outputs of one slip_step_batch on 300 random states, cold
    and warm-started (keyed (value, warm)), and the sizes of the batch sweeps it took (keyed value; one per
    wheel's axle row)."""
    st = random_slip_states(300, seed=5)
    swept = []
    axle_row = contact._axle_row
    monkeypatch.setattr(contact, "_axle_row", lambda nu, i, axle, active: (swept.append(len(active)),
                                                                           axle_row(nu, i, axle, active)))
    outs = {}
    for value in values:
        monkeypatch.setattr(contact, setting, value)
        swept.clear()
        for warm in (False, True):
            outs[value, warm] = contact.slip_step_batch(
                st["q"], st["v"], st["body_b"], st["tau"], st["slope"], 0.005, st["pb"], st["gaps"], st["normals"],
                None, st["warm_wheels"] if warm else None, st["warm_walls"] if warm else None)
        outs[value] = list(swept)
    return outs


def _same_figures(outs, value, reference):
    return all(np.array_equal(a, b) for warm in (False, True) for a, b in zip(outs[value, warm], outs[reference, warm]))


def test_the_batch_solve_goes_on_with_the_unsettled_robots_alone_and_the_same_numbers(monkeypatch):
    """Once most robots' impulses have settled, _solve_batch's sweeps go on with the others alone: fewer
    robots a sweep, and every figure of every robot exactly as when all of them are swept to the end.
    (The last few robots' going on alone is the next test's; here they stay in the batch.)"""
    monkeypatch.setattr(contact, "ALONE_FROM", 0)
    below = contact.COMPACT_BELOW
    outs = _solved_with(monkeypatch, "COMPACT_BELOW", (below, 0.0))
    assert min(outs[below]) < 300 / 4 and set(outs[0.0]) == {300}
    assert sum(outs[below]) < sum(outs[0.0]) / 2
    assert _same_figures(outs, below, 0.0)


def test_the_last_unsettled_robots_of_a_batch_solve_go_on_alone_with_the_same_numbers(monkeypatch):
    """Once few robots are still unsettled, each is swept to the end alone in Python floats: every figure of
    every robot exactly as when the batch sweeps them all (and as when every robot goes on alone from the
    first sweep), and the batch's own sweeps end sooner."""
    alone = contact.ALONE_FROM
    outs = _solved_with(monkeypatch, "ALONE_FROM", (0, alone, 300))
    assert len(outs[alone]) < len(outs[0]) / 2 and len(outs[300]) == 2 * 2  # one batch sweep (two wheels) a solve
    assert outs[0, False][3].sum() < 300 and outs[0, False][4].any()  # some slip, some are pushed by a wall
    assert _same_figures(outs, alone, 0) and _same_figures(outs, 300, 0)


def test_a_wheels_friction_on_its_disc_is_the_same_alone_and_in_a_batch():
    """contact._on_disc on Python floats gives, bit for bit, what it gives on arrays: square roots, which
    are exactly rounded everywhere, not numpy's own powers (x ** -0.5 differs from libm's in the last bit)."""
    rng = np.random.default_rng(3)
    n = 5000
    mu1, mu2 = rng.uniform(1, 50, n), rng.uniform(0.01, 1, n)
    theta = rng.uniform(-np.pi, np.pi, n)
    be, bn, lim = rng.normal(0, 1, n), rng.normal(0, 1, n), rng.uniform(0.01, 0.3, n)
    eig = (np.cos(theta), np.sin(theta), mu1, mu2)
    pe, pn = contact._on_disc(be, bn, lim, eig)
    for i in range(n):
        one = contact._on_disc(float(be[i]), float(bn[i]), float(lim[i]), tuple(float(x[i]) for x in eig))
        assert one == (pe[i], pn[i])


def test_torque_slope_is_the_derivative_and_walls_in_reach_agree():
    from host_sim.physics import motors

    for i_ref in (0.0, 0.2, 0.5, -0.5):
        for w in (-35.0, -2.0, -0.05, 0.0, 0.03, 5.0, 30.0):
            tau, _i, slope = motors.wheel_torque_slope(i_ref, w, DEFAULT)
            assert tau == motors.wheel_torque(i_ref, w, DEFAULT)[0]
            h = 1e-6
            fd = (motors.wheel_torque(i_ref, w + h, DEFAULT)[0] - motors.wheel_torque(i_ref, w - h, DEFAULT)[0]) / (2 * h)
            assert slope == pytest.approx(fd, rel=1e-5, abs=1e-9) and slope < 0
    centres = np.array([[0.05, 0.05], [0.5, 0.062], [0.5, 0.5], [0.94, 0.5], [0.52, 0.52]])
    g, nrm, order, gmin = contact.walls_in_reach_batch(BOX, centres, R, np.full(5, 0.01))
    for k, (cx, cy) in enumerate(centres):
        walls, gm = contact.walls_in_reach(BOX, cx, cy, R, 0.01)
        assert gm == pytest.approx(gmin[k], abs=1e-15)
        assert [w[3] for w in walls] == list(order[k, : len(walls)]) and np.isinf(g[k, len(walls):]).all()
        assert np.allclose([w[0] for w in walls], g[k, : len(walls)], atol=1e-15)
    assert len(contact.walls_in_reach(BOX, 0.05, 0.05, R, 0.01)[0]) == 2  # the corner: both walls
    assert contact.walls_in_reach(BOX, 0.52, 0.52, R, 0.01)[1] < 0  # inside the obstacle: negative gap


def test_a_slipping_wheels_friction_is_opposite_its_slip():
    """contact._on_disc: the minimum of 1/2 P^T W P + P^T b on the disc |P| = lim has the slip velocity
    W P + b exactly opposite to P (Coulomb, maximal dissipation), for blocks like a wheel's (heading
    stiff through the wheel's inertia, sideways soft) and lims from 1 % to 99 % of the free minimum."""
    rng = np.random.default_rng(0)
    for _ in range(2000):
        wee, wnn = rng.uniform(20, 60), rng.uniform(1, 4)
        wen = rng.uniform(-0.5, 0.5) * math.sqrt(wee * wnn)
        w = np.array([[wee, wen], [wen, wnn]])
        b = rng.normal(size=2) * 10 ** rng.uniform(-4, 0)
        free = -np.linalg.solve(w, b)
        lim = np.linalg.norm(free) * rng.uniform(0.01, 0.99)
        force = np.array(contact._on_disc(b[0], b[1], lim, contact._eigen(wee, wen, wnn)))
        slip = w @ force + b
        assert np.linalg.norm(force) == pytest.approx(lim, rel=1e-12)
        assert slip @ force < 0 and abs(slip[0] * force[1] - slip[1] * force[0]) < 1e-9 * np.linalg.norm(slip) * lim


def test_on_ice_the_wheels_spin_and_the_robot_stays():
    """wheel_friction = 0: no ground force at all; scalar and batch (both paths) agree."""
    ice = DEFAULT.replace(wheel_friction=0.0)
    robot = drive(World(name="e", size=(1.0, 1.0), walls=[]), (0.0, 0.0, 0.0), (500, 300), 0.96, 0.005, p=ice)
    assert robot.pose == (0.0, 0.0, 0.0) and robot.slip is not None and min(robot.encoder_ticks()) > 1000
    for vector_from in (1, 64):
        sim = BatchSim(None, [ice, DEFAULT], np.zeros((2, 3)))
        sim.vector_contacts_from = vector_from
        res = sim.run_inputs(np.tile([[0.5, 0.3]], (25, 1)), sensors=False)
        assert np.array_equal(res.pose[-1, 0], [0.0, 0.0, 0.0]) and res.pose[-1, 1, 0] > 0.3
        assert np.abs(res.enc[-1, 0] - robot.encoder_ticks()).max() <= 1  # row 24: after 0.96 s


def test_zero_wheel_friction_slides_freely_with_shared_parameters_and_with_drive_effects():
    """wheel_friction = 0 where the friction disc's radius is a Python float: every robot of a batch on the
    same parameters, solved vectorised, and a robot with a drive effect (a BatchSim of one).  The disc is
    the point 0 (no grip): the wheels spin, the body stays, and the paths agree."""
    ice = DEFAULT.replace(wheel_friction=0.0)
    eig = contact._eigen(40.0, 0.3, 2.0)
    assert contact._on_disc(0.3, -0.2, 0.0, eig) == (0.0, 0.0)
    free = World(name="e", size=(1.0, 1.0), walls=[])
    robot = drive(free, (0.0, 0.0, 0.0), (500, 300), 0.96, 0.005, p=ice)
    sim = BatchSim(None, ice, np.zeros((2, 3)))
    sim.vector_contacts_from = 1
    res = sim.run_inputs(np.tile([[0.5, 0.3]], (25, 1)), sensors=False)
    assert np.array_equal(res.pose[-1], np.zeros((2, 3)))
    assert np.abs(res.enc[-1] - robot.encoder_ticks()).max() <= 1  # row 24: after 0.96 s
    wider = ice.replace(wheel_radius_delta_l=1e-4)
    effects = drive(free, (0.0, 0.0, 0.0), (500, 300), 0.96, 0.005, p=wider)
    assert effects.pose == (0.0, 0.0, 0.0) and effects.slip is not None
    assert abs(effects.encoder_ticks()[1] - robot.encoder_ticks()[1]) <= 1
