"""Stick-slip dry friction at the axles (host_sim/physics/friction.py, used by drivetrain.py, drive_effects.py, contact.py).

The solve meets its conditions and is continuous in its data; scalar == batch; a wheel below
breakaway holds exactly (SimRobot and BatchSim, nominal and effects paths, rolling and in the
contact step), above it starts; a reversed wheel stops once and restarts; the result converges
with the step.  `python -m tests.test_friction` prints the step-convergence table of
docs/dynamics.md ("Integrator").
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from host_sim.physics import drivetrain, dynamics, friction
from host_sim.robot.batch import BatchSim
from host_sim.physics.params import DEFAULT as P
from host_sim.robot.sim_robot import SimRobot
from host_sim.physics.world import World

OPEN = World(name="open", size=(20.0, 20.0), walls=[], start=(10.0, 10.0, 0.0))
BREAKAWAY = P.coulomb_friction / (P.gear_efficiency * P.gear_ratio * P.torque_constant)  # A: 9.3 mA


def random_problems(n, seed=1):
    """n problems v = v0 + W f, W a P-matrix as the steps make them (symmetric PD plus a skew part)."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.5, 2.0, n)
    c = a * rng.uniform(-0.9, 0.9, n)
    s = a * rng.uniform(-0.5, 0.5, n)
    d = a * rng.uniform(0.8, 1.25, n)
    w11, w12, w21, w22 = a, c + s, c - s, np.maximum(d, (c * c) / a * 1.01)
    v0 = rng.normal(0, 1, (n, 2)) * rng.choice([0.1, 1.0, 3.0], (n, 1))
    t = rng.uniform(0.0, 1.5, (n, 2)) * (rng.random((n, 2)) > 0.05)
    return v0, (w11, w12, w21, w22), t


def check_conditions(v0, w, t, f, stick, tol=1e-12):
    v = (v0[0] + w[0] * f[0] + w[1] * f[1], v0[1] + w[2] * f[0] + w[3] * f[1])
    for i in range(2):
        assert abs(f[i]) <= t[i] * (1 + tol) + tol
        if stick[i]:
            assert abs(v[i]) <= tol * 10
        else:  # slipping: the whole friction, against the end speed
            assert abs(abs(f[i]) - t[i]) <= tol * 10 and v[i] * f[i] <= tol


def test_solve_meets_the_conditions_and_batch_equals_scalar():
    v0, w, t = random_problems(3000)
    fl, fr, sl, sr = friction.solve_batch(v0[:, 0], v0[:, 1], *w, t[:, 0], t[:, 1])
    kinds = set()
    for k in range(len(fl)):
        wk = tuple(float(x[k]) for x in w)
        out = friction.solve(float(v0[k, 0]), float(v0[k, 1]), *wk, float(t[k, 0]), float(t[k, 1]))
        assert out[2:] == (sl[k], sr[k]) and np.allclose(out[:2], (fl[k], fr[k]), rtol=1e-13, atol=1e-15)
        check_conditions(v0[k], wk, t[k], out[:2], out[2:])
        kinds.add(out[2:])
    assert kinds == {(False, False), (True, False), (False, True), (True, True)}  # every combination met


def test_batch_equals_scalar_bit_for_bit_on_either_path(monkeypatch):
    """A few robots off the easy path are solved one by one, many vectorised: both give `solve`'s answer
    to the last bit, with the step's start speeds (reversals) and without."""
    v0, w, t = random_problems(4000, seed=7)
    start = np.random.default_rng(8).normal(0, 1, (4000, 2)) * v0.std()
    v0[::3] = 5.0 * np.sign(v0[::3]) + v0[::3]  # a third turn fast: batches with few and many near rest
    taken = {"one by one": 0, "vectorised": 0}
    for path, name in (("one by one", "_solve_each"), ("vectorised", "_three_candidates")):
        real = getattr(friction, name)
        monkeypatch.setattr(friction, name, lambda *a, path=path, real=real: (taken.__setitem__(path, taken[path] + 1), real(*a))[1])
    for lo, size in zip(range(0, 4000, 40), [3, 8, 17, 40] * 25):
        k = slice(lo, lo + size)
        for st in (None, start[k]):
            got = friction.solve_batch(v0[k, 0], v0[k, 1], *(x[k] for x in w), t[k, 0], t[k, 1], start=st)
            for j in range(len(got[0])):
                s0 = (0.0, 0.0) if st is None else tuple(st[j].tolist())
                want = friction.solve(*v0[k][j].tolist(), *(float(x[k][j]) for x in w), *t[k][j].tolist(), start=s0)
                assert want == tuple(g[j] for g in got)
    assert min(taken.values()) > 10, taken  # both paths taken


def test_solve_is_continuous_in_its_data():
    """A fit by finite differences on T needs the friction continuous in T (and in the speeds): a small
    change of the data moves the solution by a comparable amount (Lipschitz), across stick-slip switches."""
    v0, w, t = random_problems(400, seed=7)
    for k in range(len(v0)):
        wk = tuple(float(x[k]) for x in w)
        base = np.array(friction.solve(*v0[k], *wk, *t[k])[:2])
        for h in (1e-6, 1e-9):
            for dv in ((h, 0), (0, h)):
                moved = np.array(friction.solve(v0[k, 0] + dv[0], v0[k, 1] + dv[1], *wk, *t[k])[:2])
                assert np.abs(moved - base).max() <= 1e3 * h
            moved = np.array(friction.solve(*v0[k], *wk, t[k, 0] + h, t[k, 1])[:2])
            assert np.abs(moved - base).max() <= 1e3 * h


def test_drive_step_batch_equals_scalar_near_rest():
    """Speeds and currents around breakaway, where the wheels stick and slip (test_drive checks the rest)."""
    rng = np.random.default_rng(3)
    n = 400
    q = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-3, 3, n), rng.uniform(-5, 5, (n, 2))])
    v = rng.normal(0, 0.3, (n, 2)) * (rng.random((n, 2)) > 0.3)
    i_ref = rng.uniform(-2, 2, (n, 2)) * BREAKAWAY
    stuck = 0
    for dt in (0.005, 0.0002):
        qb, vb, tb, cb = drivetrain.drive_step_batch(q, v, i_ref, dt, P)
        for i in range(n):
            qs, vs, ts, cs = drivetrain.drive_step(q[i], v[i], i_ref[i], dt, P)
            assert np.allclose(qb[i], qs, rtol=1e-12, atol=1e-13) and np.allclose(vb[i], vs, rtol=1e-10, atol=1e-12)
            assert np.allclose(tb[i], ts, rtol=1e-10, atol=1e-14) and np.allclose(cb[i], cs, rtol=1e-12, atol=1e-15)
            stuck += sum(x == 0.0 for x in vs)
    assert 0.2 * n < stuck < 3.8 * n  # both regimes met


def _hold(robot_factory, i_ma, seconds=2.0):
    robot = robot_factory()
    for _ in range(round(seconds / 0.005)):
        robot.advance(0.005)
    return robot


def sim_robot(params, i_ma, pose=None, world=OPEN):
    from host_sim.controller.hardware_io import Actuate

    robot = SimRobot(world, params, pose=pose, noise=False)
    robot.actuate(Actuate(i_left_ma=i_ma[0], i_right_ma=i_ma[1], emitter_pct=0))
    return robot


@pytest.mark.parametrize("params", [P, P.replace(coulomb_friction_delta_l=2e-4, coulomb_friction_delta_r=-1e-4)],
                         ids=["nominal", "effects path"])
def test_below_breakaway_the_wheels_hold_exactly(params):
    """8 mA on both wheels from rest (under T_c; the smoothed friction crept 45 ticks in 2 s): no motion at
    all, SimRobot and BatchSim; the same on one wheel alone, the other held by its own friction."""
    for i_ma in ((8, 8), (8, -8), (8, 0), (-8, 0)):
        robot = _hold(lambda: sim_robot(params, i_ma), i_ma)
        assert robot.v == (0.0, 0.0) and robot.encoder_ticks() == (0, 0)
        assert robot.q == sim_robot(params, i_ma).q
        sim = BatchSim(OPEN, params, poses=[OPEN.start] * 2, substeps=8)
        res = sim.run_inputs(np.full((50, 2), np.array(i_ma) / 1000.0), sensors=False)
        assert not res.enc.any() and (sim.v == 0.0).all() and (res.pose == res.pose[0]).all()


def test_a_wheel_pressed_against_a_wall_holds_in_the_contact_step():
    """In the contact step the axle's friction is a row of the impulse solve: a robot against a wall, its
    wheels at 8 mA, does not turn them."""
    box = World(name="wall", size=(1.0, 1.0), walls=[{"segment": [1.0, -1.0, 1.0, 2.0]}], start=(0.5, 0.5, 0.0))
    for params in (P, P.replace(caster_drag=0.05)):
        robot = sim_robot(params, (300, 300), pose=(1.0 - P.body_radius - 0.01, 0.5, 0.0), world=box)
        for _ in range(200):  # driven into the wall: the wheels slip
            robot.advance(0.005)
        assert robot.slip is not None
        from host_sim.controller.hardware_io import Actuate

        robot.actuate(Actuate(i_left_ma=8, i_right_ma=-8, emitter_pct=0))
        for _ in range(200):
            robot.advance(0.005)
        ticks = robot.encoder_ticks()
        for _ in range(400):
            robot.advance(0.005)
        assert robot.encoder_ticks() == ticks and max(abs(x) for x in robot.v) < 1e-7


def _from_rest(i_a, seconds=0.5, dt=0.001):
    q, v = (0.0,) * 5, (0.0, 0.0)
    for _ in range(round(seconds / dt)):
        q, v = drivetrain.drive_step(q, v, i_a, dt, P)[:2]
    return q, v


def test_breakaway_at_the_dry_friction():
    """Straight from rest: held at 0.98 of the breakaway current, moving at 1.02 of it, with the speed the
    net torque (motor - T_c) gives; one wheel alone breaks away at the same current."""
    for side in ((1, 1), (1, 0), (0, -1)):
        q, v = _from_rest((0.98 * BREAKAWAY * side[0], 0.98 * BREAKAWAY * side[1]))
        assert v == (0.0, 0.0) and q == (0.0,) * 5
        q, v = _from_rest((1.02 * BREAKAWAY * side[0], 1.02 * BREAKAWAY * side[1]))
        assert all((x > 0) if s > 0 else (x < 0) if s < 0 else True for x, s in zip(v, side)), (side, v)
    # both wheels: (m_t r^2 / 2) w' = 0.02 T_c - c_v w per wheel: w = 0.02 T_c / c_v (1 - exp(-t / tau))
    _q, v = _from_rest((1.02 * BREAKAWAY,) * 2, seconds=3.0)
    tau = 0.5 * dynamics.effective_inertias(P)[0] * P.wheel_radius ** 2 / P.viscous_friction
    expect = 0.02 * P.coulomb_friction / P.viscous_friction * (1 - math.exp(-3.0 / tau))
    assert v[0] == pytest.approx(v[1]) and v[0] == pytest.approx(expect, rel=1e-4)


def test_a_reversed_wheel_stops_once_and_restarts():
    """Spinning at 0.2 A, then -0.2 A: each wheel passes zero once (no chatter), reaches the same speed
    backwards; reversed to a current under breakaway it stops and stays stopped, exactly."""
    for dt in (0.001, 0.005, 0.02):
        q, v = _from_rest((0.2, 0.2), seconds=1.0, dt=dt)
        hist = [v]
        for _ in range(round(1.5 / dt)):
            q, v = drivetrain.drive_step(q, v, (-0.2, -0.2), dt, P)[:2]
            hist.append(v)
        h = np.array(hist)
        for j in range(2):
            assert np.count_nonzero(np.diff(np.sign(h[:, j][h[:, j] != 0.0]))) == 1
        assert v[0] == pytest.approx(-hist[0][0], rel=1e-6)
        q, v = _from_rest((0.2, 0.2), seconds=1.0, dt=dt)
        hist = []
        for _ in range(round(2.0 / dt)):
            q, v = drivetrain.drive_step(q, v, (-0.008, -0.008), dt, P)[:2]
            hist.append(v)
        h = np.array(hist)
        first = np.flatnonzero((h == 0.0).all(1))[0]
        assert first * dt < 1.0 and (h[first:] == 0.0).all()
        for j in range(2):
            assert np.count_nonzero(np.diff(np.sign(h[:first, j][h[:first, j] != 0.0]))) == 0


# (name, seconds, (left, right) A): drive, hold under breakaway, coast to rest, spin, reverse, creep-test
PROGRAM = [(0.4, (0.2, 0.15)), (0.4, (0.008, 0.008)), (0.3, (0.0, 0.0)), (0.4, (-0.12, 0.12)),
           (0.4, (0.12, -0.12)), (0.3, (0.012, 0.0)), (0.4, (-0.008, 0.006)), (0.3, (0.3, 0.3))]
CONVERGENCE_SUBSTEPS = (200, 40, 8)  # dt = 0.2, 1, 5 ms at the 40 ms control period


def run_program(substeps):
    """The PROGRAM through a BatchSim of one at 40 ms control periods: (pose of C, encoder ticks) at the end."""
    cmd = np.concatenate([np.tile(i, (round(s / 0.04), 1)) for s, i in PROGRAM])
    sim = BatchSim(OPEN, P, poses=[OPEN.start], substeps=substeps)
    res = sim.run_inputs(cmd, sensors=False)
    return sim.pose[0], sim.encoder_ticks()[0], res


def convergence_table():
    """Per dt: (distance of the final pose of C from the 0.2 ms run (m), its heading's difference (deg),
    final tick difference (left, right), the largest tick difference at any control instant)."""
    runs = {n: run_program(n) for n in CONVERGENCE_SUBSTEPS}
    ref_pose, ref_ticks, ref_res = runs[CONVERGENCE_SUBSTEPS[0]]
    table = {}
    for n, (pose, ticks, res) in runs.items():
        table[1000 * 0.04 / n] = (math.hypot(*(pose[:2] - ref_pose[:2])), math.degrees(abs(pose[2] - ref_pose[2])),
                                  tuple(int(x) for x in ticks - ref_ticks), int(np.abs(res.enc - ref_res.enc).max()))
    return table


def test_the_result_converges_with_the_step():
    """The same program of stick, slip, breakaway and reversal at dt = 0.2, 1, 5 ms: the 1 and 5 ms runs
    within 0.5 mm, 0.1 degrees and 1 tick of the 0.2 ms run (docs/dynamics.md has the measured table)."""
    table = convergence_table()
    for dt_ms, (dist, dphi, ticks, worst) in table.items():
        assert dist < 5e-4 and dphi < 0.1 and worst <= 1, (dt_ms, table)
    assert table[1.0][0] < table[5.0][0] / 5  # and it converges


if __name__ == "__main__":  # print the table for docs/dynamics.md
    for dt_ms, row in convergence_table().items():
        print(f"{dt_ms:g} ms", row)


def test_a_warm_start_with_the_axle_torques_gives_the_same_step():
    """The contact solve starts from the last step's impulses, the axles' friction torques among them: the
    step is the same (to the solve's tolerance) as from a cold start, and the held torque stays in its bound."""
    from host_sim.physics import contact, motors

    q, v, dt = (0.5, 0.5, 0.0, 0.0, 0.0), (0.0, 0.0), 0.005
    walls = [(-1e-5, -1.0, 0.0, 0)]  # a wall just ahead, touched
    tl, _il, sl = motors.wheel_torque_slope(0.006, 0.0, P)
    tr, _ir, sr = motors.wheel_torque_slope(0.006, 0.0, P)
    step = None, (tl, tr), (sl, sr), dt, P, walls
    cold = contact.slip_step(q, v, *step)
    warm = contact.slip_step(q, v, *step, (cold[4][0], cold[4][1]))
    assert all(len(f) == 3 and abs(f[2]) <= P.coulomb_friction for f in cold[4][0])
    assert any(abs(f[2]) > 0.1 * P.coulomb_friction for f in cold[4][0])  # the axles hold the wheels
    assert np.allclose(warm[0], cold[0], atol=1e-9) and np.allclose(warm[1], cold[1], atol=1e-7)


def test_breakaway_friction_holds_a_wheel_coulomb_friction_lets_turn():
    """A build with 30 % breakaway friction (stiction_l/_r, Drive.dry): from rest 1.2 times the dry friction's
    current holds both wheels exactly, 1.4 times starts them; once turning well past the Stribeck speed, 1.2
    times keeps them turning, at the speed the Coulomb friction alone allows."""
    sticky = P.replace(stiction_l=0.3, stiction_r=0.3, stribeck_speed=0.5)

    def run(currents):
        sim = BatchSim(OPEN, sticky, poses=[OPEN.start], substeps=8)
        res = sim.run_inputs(np.asarray(currents, dtype=float), sensors=False)
        return sim, res

    sim, res = run(np.full((100, 2), 1.2 * BREAKAWAY))
    assert not res.enc.any() and (sim.v == 0.0).all()
    sim, res = run(np.full((100, 2), 1.4 * BREAKAWAY))
    assert (sim.v > 0.0).all()
    sim, res = run(np.vstack([np.full((100, 2), 0.1), np.full((400, 2), 1.2 * BREAKAWAY)]))
    held = 0.2 * P.coulomb_friction / P.viscous_friction  # the net 0.2 T_c against c_v w
    assert sim.v[0] == pytest.approx([held, held], rel=0.05)
