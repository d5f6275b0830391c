"""The robot's dynamics and motors (host_sim/physics/dynamics.py, host_sim/physics/motors.py; docs/dynamics.md).

(a) symmetric torques -> straight line; (b) d = 0 is the textbook model; (c) no input,
no friction -> kinetic energy conserved, and the fixed-step integrator converges;
(d) an independent KKT solve of M q'' + V = E tau - A^T lambda agrees with the reduced
model, and the constraints hold along a trajectory; (e) batch == scalar: in
tests/test_scalar_batch_pairs.py with the other pairs; (f) the matrix path == the closed
form; (g) motors and encoders.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from host_sim.physics import drivetrain
from host_sim.physics import dynamics as dy
from host_sim.physics import motors as mo
from host_sim.physics.params import DEFAULT, RobotParams

P = DEFAULT
SETTINGS = settings(deadline=None, max_examples=150)

# --------------------------------------------------------------------------- #
# strategies
# --------------------------------------------------------------------------- #
finite = dict(allow_nan=False, allow_infinity=False)
states = st.tuples(st.floats(-10, 10, **finite), st.floats(-10, 10, **finite), st.floats(-60, 60, **finite),
                   st.floats(-1e3, 1e3, **finite), st.floats(-1e3, 1e3, **finite))
speeds = st.tuples(st.floats(-60, 60, **finite), st.floats(-60, 60, **finite))
torques = st.tuples(st.floats(-0.2, 0.2, **finite), st.floats(-0.2, 0.2, **finite))


@st.composite
def robots(draw: st.DrawFn) -> RobotParams:
    """Physically sensible parameter sets, far from the defaults too (d = 0 included)."""
    return P.replace(
        wheel_radius=draw(st.floats(0.01, 0.05)), half_axle=draw(st.floats(0.03, 0.1)),
        com_offset=draw(st.one_of(st.just(0.0), st.floats(0.0, 0.05))),
        body_mass=draw(st.floats(0.1, 2.0)), wheel_mass=draw(st.floats(0.005, 0.1)),
        body_inertia=draw(st.floats(1e-4, 5e-3)), wheel_inertia=draw(st.floats(1e-6, 1e-4)),
        wheel_inertia_diam=draw(st.floats(0.0, 1e-5)))


def random_params(rng: np.random.Generator) -> RobotParams:
    f = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
    return P.replace(wheel_radius=f(0.01, 0.05), half_axle=f(0.03, 0.1), com_offset=f(0.0, 0.05),
                     body_mass=f(0.1, 2.0), wheel_mass=f(0.005, 0.1), body_inertia=f(1e-4, 5e-3),
                     wheel_inertia=f(1e-6, 1e-4), wheel_inertia_diam=f(0.0, 1e-5),
                     torque_constant=f(0.002, 0.01), armature_resistance=f(2.0, 20.0),
                     gear_ratio=f(10.0, 100.0), gear_efficiency=f(0.5, 1.0), current_limit=f(0.1, 1.0),
                     viscous_friction=f(0.0, 1e-3), coulomb_friction=f(0.0, 5e-3),
                     battery_voltage=f(3.0, 12.0), ticks_per_rev=float(rng.integers(100, 5000)))


# --------------------------------------------------------------------------- #
# reference formulas, written out here so that they check the library, not copy it
# --------------------------------------------------------------------------- #
def body_velocity(v, p) -> tuple[float, float]:
    """(u, omega): forward speed (m/s) and yaw rate (rad/s) from the wheel speeds."""
    r, b = p.wheel_radius, p.half_axle
    return 0.5 * r * (v[0] + v[1]), 0.5 * r * (v[1] - v[0]) / b


def wheel_speeds(u: float, omega: float, p) -> tuple[float, float]:
    """(w_l, w_r) (rad/s) for a forward speed u and a yaw rate omega: body_velocity's inverse."""
    r, b = p.wheel_radius, p.half_axle
    return (u - b * omega) / r, (u + b * omega) / r


def qdot(q, v, p) -> tuple[float, float, float, float, float]:
    """q' = S(q) v, the kinematics written out (G a distance d ahead of the axle)."""
    d = p.com_offset
    u, w = body_velocity(v, p)
    c, s = math.cos(q[2]), math.sin(q[2])
    return (u * c - d * w * s, u * s + d * w * c, w, v[0], v[1])


def kinetic_energy(q, q_dot, p) -> float:
    """T = 1/2 q'^T M(q) q' (J), from the mass matrix."""
    qd = np.asarray(q_dot, dtype=float)
    return float(0.5 * qd @ dy.mass_matrix(q, p) @ qd)


def kinetic_energy_reduced(v, p) -> float:
    """T = 1/2 m_t u^2 + 1/2 J_t omega^2 (J), from the effective mass and inertia."""
    m_t, j_t = dy.effective_inertias(p)
    u, w = body_velocity(v, p)
    return 0.5 * (m_t * u * u + j_t * w * w)


def full_constrained_accel(q, q_dot, tau, p) -> tuple[np.ndarray, np.ndarray]:
    """(q'', lambda) of  M q'' + V = E tau - A^T lambda,  A q'' + A' q' = 0  (KKT system; S not used).

    lambda = (-F_lat, F_l, F_r): F_lat is the sideways ground force on the robot at the axle
    (N, positive to the left), F_l, F_r the forward traction forces at the wheels (N).
    q_dot must satisfy A q' = 0 (only then is this the robot's motion).
    """
    qd = np.asarray(q_dot, dtype=float)
    a = dy.constraint_matrix(q, p)
    kkt = np.zeros((8, 8))
    kkt[:5, :5] = dy.mass_matrix(q, p)
    kkt[:5, 5:] = a.T
    kkt[5:, :5] = a
    rhs = np.empty(8)
    rhs[:5] = dy.input_matrix(q, p) @ np.asarray(tau, dtype=float) - dy.coriolis(q, qd, p)
    rhs[5:] = -dy.constraint_matrix_dot(q, qd, p) @ qd
    sol = np.linalg.solve(kkt, rhs)
    return sol[:5], sol[5:]


def accel_scale(v, tau, p, q=(0.0, 0.0, 0.0, 0.0, 0.0)) -> float:
    """Size of the terms summed into v' (so that tolerances are relative to them): H^-1 times
    |S^T E tau|, |S^T M S' v| and |S^T V| separately."""
    v = np.asarray(v, dtype=float)
    qd = list(qdot(q, v, p))
    qd[2] = p.wheel_radius / (2 * p.half_axle) * (abs(v[0]) + abs(v[1]))  # phi' before cancelling too
    m, vv, e, _a, s, s_dot = dy.matrices(q, qd, p)
    a = np.abs
    h_inv = a(np.linalg.inv(s.T @ m @ s))
    terms = [a(s.T) @ a(e) @ a(tau), a(s.T) @ a(m) @ a(s_dot) @ a(v), a(s.T) @ a(vv)]  # bounds before cancelling
    return float(sum((h_inv @ t).max() for t in terms) + 1e-300)


# --------------------------------------------------------------------------- #
# reference integrators (RK4), used only here
# --------------------------------------------------------------------------- #
def rk4(f, x, dt):
    """One classical RK4 step of X' = f(X)."""
    k1 = f(x)
    k2 = f(x + 0.5 * dt * k1)
    k3 = f(x + 0.5 * dt * k2)
    k4 = f(x + dt * k3)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def rk4_reduced(q, v, tau, dt, p):
    """Classical RK4 on X = (q, v), X' = (S(q) v, v'(v, tau)), tau held over the step."""

    def f(x):
        return np.array([*qdot(x[:5], x[5:], p), *dy.reduced_accel_fast(x[:5], x[5:], tau, p)])

    x = rk4(f, np.array([*q, *v], dtype=float), dt)
    return x[:5], x[5:]


def rk4_full(q, qd, tau, dt, p):
    """RK4 on the full constrained system X = (q, q'), X' = (q', q''_KKT): no S anywhere."""

    def f(x):
        return np.concatenate([x[5:], full_constrained_accel(x[:5], x[5:], tau, p)[0]])

    x = rk4(f, np.concatenate([q, qd]), dt)
    return x[:5], x[5:]


def run(q, v, tau, dt, n, p, stepper=dy.step):
    for _ in range(n):
        q, v = stepper(q, v, tau, dt, p)
    return q, v


# --------------------------------------------------------------------------- #
# the model itself: constraints, M, V, the meaning of q
# --------------------------------------------------------------------------- #
@SETTINGS
@given(states, robots())
def test_null_space_annihilates_constraints(q, p):
    a, s = dy.constraint_matrix(q, p), dy.null_space(q, p)
    assert np.abs(a @ s).max() < 1e-15
    assert np.linalg.matrix_rank(a) == 3 and np.linalg.matrix_rank(s) == 2
    assert np.allclose(s.T @ dy.input_matrix(q, p), np.eye(2))  # v = wheel speeds => S^T E = I


@SETTINGS
@given(states, speeds, robots())
def test_constraints_are_the_papers_scalar_equations_and_physical(q, v, p):
    """A q' = 0 is the paper's three equations; under it the axle centre C has no sideways velocity
    and each wheel's contact point is at rest (rolling without slipping)."""
    xd, yd, phd, tld, trd = qdot(q, v, p)
    r, b, d, phi = p.wheel_radius, p.half_axle, p.com_offset, q[2]
    c, s = math.cos(phi), math.sin(phi)
    scale = (abs(xd) + abs(yd) + (b + d + r) * abs(phd) + r * (abs(tld) + abs(trd))) * 1e-14 + 1e-300
    assert abs(yd * c - xd * s - d * phd) < scale
    assert abs(xd * c + yd * s - b * phd - r * tld) < scale
    assert abs(xd * c + yd * s + b * phd - r * trd) < scale
    # C = G - d e: velocity G' - d phi' n
    cx, cy = xd + d * phd * s, yd - d * phd * c
    assert abs(-cx * s + cy * c) < scale
    for side, spin in ((+1, tld), (-1, trd)):
        # wheel centre W = C + side b n; contact point velocity = W' + (spin about the axle) x (-r z)
        wx, wy = cx - side * b * phd * c, cy - side * b * phd * s
        assert abs(wx * c + wy * s - r * spin) < scale and abs(-wx * s + wy * c) < scale


@SETTINGS
@given(states, st.tuples(*[st.floats(-30, 30)] * 5), robots())
def test_mass_matrix_from_the_bodies_kinetic_energy(q, qd, p):
    """1/2 q'^T M q' equals T computed body by body from the geometry (any q', constrained or not)."""
    x, y, phi = q[:3]
    xd, yd, phd, tld, trd = qd
    e, n = np.array([math.cos(phi), math.sin(phi)]), np.array([-math.sin(phi), math.cos(phi)])
    b, d = p.half_axle, p.com_offset
    g_dot = np.array([xd, yd])
    t = 0.5 * p.body_mass * g_dot @ g_dot + 0.5 * p.body_inertia * phd ** 2
    for side, spin in ((+1, tld), (-1, trd)):
        w_dot = g_dot - d * phd * n - side * b * phd * e  # W = G - d e + side b n
        t += 0.5 * p.wheel_mass * w_dot @ w_dot + 0.5 * p.wheel_inertia * spin ** 2
        t += 0.5 * p.wheel_inertia_diam * phd ** 2
    assert kinetic_energy(q, qd, p) == pytest.approx(t, rel=1e-12, abs=1e-300)


@SETTINGS
@given(states, st.tuples(*[st.floats(-30, 30)] * 5), robots())
def test_coriolis_is_mdot_qdot_minus_dT_dq(q, qd, p):
    """V = M' q' - dT/dq, M' and dT/dphi by central differences of M (only phi enters M)."""
    qd = np.array(qd)
    h = 1e-6

    def m_at(dphi):
        return dy.mass_matrix((q[0], q[1], q[2] + dphi, q[3], q[4]), p)

    dm_dphi = (m_at(h) - m_at(-h)) / (2 * h)
    v_fd = (dm_dphi * qd[2]) @ qd
    v_fd[2] -= 0.5 * qd @ dm_dphi @ qd
    v = dy.coriolis(q, qd, p)
    assert np.allclose(v, v_fd, rtol=1e-6, atol=1e-8 * (np.abs(v_fd).max() + 2 * p.wheel_mass * 0.05 * 1e-3))


def test_axle_conversion_round_trip():
    q = dy.q_from_axle_pose(0.3, -0.2, 2.0, P, 1.0, -1.0)
    assert np.allclose(dy.axle_centre(q, P), (0.3, -0.2))
    assert math.hypot(q[0] - 0.3, q[1] + 0.2) == pytest.approx(P.com_offset)


# --------------------------------------------------------------------------- #
# (a) symmetric torques -> straight line
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("stepper", [dy.step, dy.step_matrix])
def test_symmetric_torques_from_rest_go_straight(stepper):
    dt, n = 1e-3, 2000 if stepper is dy.step else 200
    q, v = (0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 0.0)
    xs = []
    for _ in range(n):
        q, v = stepper(q, v, (0.004, 0.004), dt, P)
        assert abs(q[1]) < 1e-12 and abs(q[2]) < 1e-12
        xs.append(q[0])
    # along the line: x(t) = 1/2 a t^2 with a = 2 tau / (r m_t), exactly for a trapezoidal step
    a = 2 * 0.004 / (P.wheel_radius * dy.effective_inertias(P)[0])
    assert np.all(np.diff(xs) > 0) and xs[-1] == pytest.approx(0.5 * a * (n * dt) ** 2, rel=1e-9)


def test_symmetric_current_through_motors_goes_straight_at_any_heading():
    """Equal current references from rest at heading phi0, motors and friction on: the axle stays on its line."""
    phi0 = 0.7
    q, v = dy.q_from_axle_pose(0.1, 0.2, phi0, P), (0.0, 0.0)
    for _ in range(2000):  # 2 s at 1 ms
        t = (mo.wheel_torque(0.3, v[0], P)[0], mo.wheel_torque(0.3, v[1], P)[0])
        q, v = dy.step(q, v, t, 1e-3, P)
        assert q[2] == phi0 and v[0] == v[1]
    cx, cy = dy.axle_centre(q, P)
    along = (cx - 0.1) * math.cos(phi0) + (cy - 0.2) * math.sin(phi0)
    across = -(cx - 0.1) * math.sin(phi0) + (cy - 0.2) * math.cos(phi0)
    assert along > 0.5 and abs(across) < 1e-12


# --------------------------------------------------------------------------- #
# (b) d = 0: the textbook model
# --------------------------------------------------------------------------- #
@SETTINGS
@given(states, speeds, torques, robots())
def test_d_zero_is_the_textbook_model(q, v, tau, p):
    """With d = 0 (G on the axle) the textbook differential drivetrain.

    Newton-Euler on the robot with the wheel-ground traction forces F_l, F_r (forward):
        (m_c + 2 m_w) u' = F_l + F_r                  (no centripetal coupling: G on the axle)
        (I_c + 2 m_w b^2 + 2 I_m) omega' = b (F_r - F_l)
    and on each wheel's spin  I_w w_i' = tau_i - r F_i,  with u = r (w_l + w_r)/2,
    omega = r (w_r - w_l)/(2b).  Eliminating F_i:
        m_t u' = (tau_l + tau_r) / r,      m_t = m_c + 2 m_w + 2 I_w / r^2
        I_t omega' = b (tau_r - tau_l) / r, I_t = I_c + 2 m_w b^2 + 2 I_m + 2 b^2 I_w / r^2
    (each wheel's spin inertia adds I_w/r^2 to the mass and I_w b^2/r^2 to the yaw inertia),
    the kinematics are the unicycle's x' = u cos(phi), y' = u sin(phi), and the Lagrangian matrices
    are constant: M diagonal, V = 0.
    """
    p = p.replace(com_offset=0.0)
    r, b = p.wheel_radius, p.half_axle
    m_t = p.body_mass + 2 * p.wheel_mass + 2 * p.wheel_inertia / r ** 2
    i_t = p.body_inertia + 2 * p.wheel_mass * b ** 2 + 2 * p.wheel_inertia_diam + 2 * b ** 2 * p.wheel_inertia / r ** 2
    ud = (tau[0] + tau[1]) / r / m_t
    wd = b * (tau[1] - tau[0]) / r / i_t
    expect = np.array([(ud - b * wd) / r, (ud + b * wd) / r])
    got = dy.reduced_accel(q, v, tau, p)  # the Lagrangian matrix path
    assert np.allclose(got, expect, rtol=1e-12, atol=1e-12 * accel_scale(v, tau, p, q))
    m, vv, _e, _a, s, s_dot = dy.matrices(q, qdot(q, v, p), p)
    assert np.count_nonzero(m - np.diag(np.diag(m))) == 0 and not vv.any()
    u, w = (v[0] + v[1]) * r / 2, (v[1] - v[0]) * r / (2 * b)
    assert np.allclose(s @ v, [u * math.cos(q[2]), u * math.sin(q[2]), w, v[0], v[1]], rtol=1e-13, atol=1e-13)


def test_d_zero_step_is_exact_for_constant_torque_and_second_order_on_the_arc():
    """d = 0, constant torques: the speeds are linear in t and the step reproduces them exactly;
    with no torque the robot runs a circle and the position error falls as dt^2."""
    p = P.replace(com_offset=0.0)
    m_t, i_t = dy.effective_inertias(p)
    r, b = p.wheel_radius, p.half_axle
    tau = (0.002, 0.005)
    q, v = (0.0,) * 5, (1.0, 2.0)
    q, v = run(q, v, tau, 0.01, 100, p)
    u0, w0 = body_velocity((1.0, 2.0), p)
    u1, w1 = u0 + (tau[0] + tau[1]) / r / m_t * 1.0, w0 + b * (tau[1] - tau[0]) / r / i_t * 1.0
    assert np.allclose(v, wheel_speeds(u1, w1, p), rtol=1e-12)
    assert q[2] == pytest.approx(w0 + 0.5 * (w1 - w0), rel=1e-12)  # phi = integral of a linear omega
    # circle
    v0 = (10.0, 14.0)
    u, w = body_velocity(v0, p)
    radius = u / w
    errs = []
    for dt in (0.02, 0.01, 0.005):
        n = round(2.0 / dt)
        q, _ = run((0.0,) * 5, v0, (0.0, 0.0), dt, n, p)
        exact = (radius * math.sin(w * 2.0), radius * (1 - math.cos(w * 2.0)))
        errs.append(math.hypot(q[0] - exact[0], q[1] - exact[1]))
    assert errs[0] / errs[1] == pytest.approx(4, rel=0.05) and errs[1] / errs[2] == pytest.approx(4, rel=0.05)


# --------------------------------------------------------------------------- #
# (c) energy and convergence
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("d", [0.015, 0.05])
def test_kinetic_energy_conserved_without_input_and_friction(d):
    """10 s of a fast spinning and driving robot (COM offset d), i_ref = 0 and no friction in the motors:
    kinetic energy conserved; the Lagrangian T(q, q') = 1/2 q'^T M q' is checked along the way."""
    p = P.replace(com_offset=d, viscous_friction=0.0, coulomb_friction=0.0)
    p = p.replace(battery_voltage=24.0)  # headroom: no back-EMF braking at i_ref = 0 (motors.py)
    q, v = (0.0, 0.0, 0.3, 0.0, 0.0), (-20.0, 35.0)
    t0 = kinetic_energy(q, qdot(q, v, p), p)
    dt, worst = 1e-3, 0.0
    for k in range(10_000):
        tau = (mo.wheel_torque(0.0, v[0], p)[0], mo.wheel_torque(0.0, v[1], p)[0])
        assert tau == (0.0, 0.0)
        q, v = dy.step(q, v, tau, dt, p)
        if k % 500 == 0:
            worst = max(worst, abs(kinetic_energy(q, qdot(q, v, p), p) / t0 - 1))
    worst = max(worst, abs(kinetic_energy_reduced(v, p) / t0 - 1))
    assert worst < 1e-12
    # the motion is not trivial: the offset COM trades forward speed against yaw rate
    assert abs(body_velocity(v, p)[0] - body_velocity((-20.0, 35.0), p)[0]) > 0.01


def test_kinetic_energy_conserved_with_rk4_reference():
    """The same with the RK4 reference integrator (dt = 1 ms, 10 s): drift < 1e-6."""
    q, v = (0.0, 0.0, 0.3, 0.0, 0.0), (-20.0, 35.0)
    t0 = kinetic_energy_reduced(v, P)
    for _ in range(10_000):
        q, v = rk4_reduced(q, v, (0.0, 0.0), 1e-3, P)
    assert abs(kinetic_energy(q, qdot(q, v, P), P) / t0 - 1) < 1e-6


@SETTINGS
@given(states, speeds, torques, st.floats(1e-4, 0.05), robots())
def test_discrete_work_energy_balance(q, v, tau, dt, p):
    """Each step: T+ - T = tau . (theta+ - theta), to rounding (no energy made up by the integrator)."""
    q1, v1 = dy.step(q, v, tau, dt, p)
    t0, t1 = kinetic_energy_reduced(v, p), kinetic_energy_reduced(v1, p)
    work = tau[0] * (q1[3] - q[3]) + tau[1] * (q1[4] - q[4])
    scale = t0 + t1 + sum(abs(tau[j]) * (dt * (abs(v[j]) + abs(v1[j])) + abs(q[3 + j]) + abs(q1[3 + j]))
                          for j in range(2))
    assert abs((t1 - t0) - work) < 1e-11 * scale + 1e-300


def test_fixed_step_converges_second_order():
    """Against an RK4 solution at dt = 0.1 ms: the error of `step` falls 4x per halving of dt,
    while the paper's explicit Euler (X = X + X' dt) falls 2x."""
    p = P.replace(com_offset=0.04)
    q0, v0, tau, t_end = (0.1, -0.2, 0.5, 0.0, 0.0), (25.0, -5.0), (0.01, -0.004), 1.0
    q_ref, v_ref = q0, v0
    for _ in range(10_000):
        q_ref, v_ref = rk4_reduced(q_ref, v_ref, tau, 1e-4, p)
    ref = np.array([*q_ref, *v_ref])

    def euler(q, v, tau, dt, p):
        return (np.asarray(q) + dt * np.array(qdot(q, v, p)),
                np.asarray(v) + dt * np.array(dy.reduced_accel_fast(q, v, tau, p)))

    for stepper, order in ((dy.step, 2), (euler, 1)):
        errs = []
        for dt in (0.004, 0.002, 0.001):
            q, v = run(q0, v0, tau, dt, round(t_end / dt), p, stepper)
            errs.append(np.abs(np.array([*q, *v]) - ref).max())
        ratios = [errs[0] / errs[1], errs[1] / errs[2]]
        assert all(abs(ratio / 2 ** order - 1) < 0.15 for ratio in ratios), (stepper, errs)
    assert errs[2] > 0  # euler's last error; step's at 1 ms was checked to fall as dt^2 above


# --------------------------------------------------------------------------- #
# (d) the independent constrained (KKT) solve
# --------------------------------------------------------------------------- #
@SETTINGS
@given(states, speeds, torques, robots())
def test_kkt_solve_agrees_with_reduced_model(q, v, tau, p):
    s = dy.null_space(q, p)
    qd = s @ np.array(v)
    vd = dy.reduced_accel(q, v, tau, p)
    qdd_reduced = s @ vd + dy.null_space_dot(q, qd, p) @ np.array(v)
    qdd, lam = full_constrained_accel(q, qd, tau, p)
    # q'' = S v' + S' v: bound the terms before they cancel (phi' itself is a difference of wheel speeds)
    w_bound = p.wheel_radius / (2 * p.half_axle) * (abs(v[0]) + abs(v[1]))
    s_dot_bound = np.abs(dy.null_space_dot(q, (0.0, 0.0, w_bound, 0.0, 0.0), p))
    scale = (np.abs(s).sum(axis=1).max() * accel_scale(v, tau, p, q)
             + (s_dot_bound @ np.abs(v)).max() + 1e-300)
    assert np.abs(qdd - qdd_reduced).max() < 1e-9 * scale
    # lambda: the traction forces F_i = (tau_i - I_w w_i') / r at the wheels
    f = (np.array(tau) - p.wheel_inertia * vd) / p.wheel_radius
    force_scale = np.abs(lam).max() + (p.body_mass + 2 * p.wheel_mass) * scale + np.abs(tau).max() / p.wheel_radius
    assert np.abs(lam[1:] - f).max() <= 1e-9 * force_scale


def test_kkt_trajectory_keeps_the_constraints_and_follows_the_reduced_model():
    """Integrate the full 10-state constrained system (RK4 on q, q'; no S) for 2 s from a consistent
    state under varying torques: A(q) q' stays ~0 and the path is the reduced model's."""
    p = P.replace(com_offset=0.03)
    q, v = np.array([0.0, 0.0, 0.2, 0.0, 0.0]), np.array([5.0, 12.0])
    qf, qdf = q.copy(), dy.null_space(q, p) @ v
    qr, vr = q.copy(), v.copy()
    qs, vs = tuple(q), tuple(v)
    dt = 2e-3
    worst_constraint = 0.0
    for k in range(1000):
        tau = (0.01 * math.sin(3 * k * dt), 0.008 * math.cos(5 * k * dt))
        qf, qdf = rk4_full(qf, qdf, tau, dt, p)
        qr, vr = rk4_reduced(qr, vr, tau, dt, p)
        qs, vs = dy.step(qs, vs, tau, dt, p)
        worst_constraint = max(worst_constraint, np.abs(dy.constraint_matrix(qf, p) @ qdf).max())
        assert np.abs(dy.constraint_matrix(qs, p) @ qdot(qs, vs, p)).max() < 1e-14
    assert worst_constraint < 1e-10
    assert np.abs(qf - qr).max() < 1e-9 and np.abs(qdf[3:] - vr).max() < 1e-8
    # the fixed-step integrator is close too (second order, dt = 2 ms)
    assert np.abs(np.array(qs) - qr).max() < 1e-3 and np.abs(np.array(vs) - vr).max() < 1e-2


# --------------------------------------------------------------------------- #
# (f) matrix path == closed form (batch == scalar: tests/test_scalar_batch_pairs.py)
# --------------------------------------------------------------------------- #
@SETTINGS
@given(states, speeds, torques, robots())
def test_matrix_path_equals_closed_form(q, v, tau, p):
    a = dy.reduced_accel(q, v, tau, p)
    b = np.array(dy.reduced_accel_fast(q, v, tau, p))
    assert np.abs(a - b).max() <= 1e-12 * accel_scale(v, tau, p, q)
    assert kinetic_energy(q, qdot(q, v, p), p) == pytest.approx(kinetic_energy_reduced(v, p), rel=1e-12,
                                                                      abs=1e-300)


@SETTINGS
@given(states, speeds, torques, st.floats(1e-4, 0.05), robots())
def test_matrix_step_equals_fast_step(q, v, tau, dt, p):
    qa, va = dy.step_matrix(q, v, tau, dt, p)
    qb, vb = dy.step(q, v, tau, dt, p)
    vscale = np.abs(v).max() + dt * accel_scale(v, tau, p, q) + 1e-300
    assert np.abs(va - np.array(vb)).max() <= 1e-12 * vscale
    qscale = np.abs(q).max() + dt * vscale * (1 + p.wheel_radius)
    assert np.abs(qa - np.array(qb)).max() <= 1e-12 * qscale


def test_param_batch_from_vectors():
    names = ["com_offset", "body_mass"]
    pb = dy.ParamBatch.from_vectors([[0.0, 0.4], [0.02, 0.6]], names)
    assert len(pb) == 2 and pb.robot(1) == P.replace(com_offset=0.02, body_mass=0.6)
    assert pb.wheel_radius[0] == P.wheel_radius
    with pytest.raises(ValueError, match="unknown"):
        dy.ParamBatch.from_vectors([[1.0]], ["nope"])
    with pytest.raises(ValueError, match="shape"):
        dy.ParamBatch.from_vectors([1.0, 2.0], names)


# --------------------------------------------------------------------------- #
# (g) motors and encoders
# --------------------------------------------------------------------------- #
def test_current_limited_by_driver_and_by_back_emf():
    k = P.torque_constant * P.gear_ratio  # back-EMF per wheel rad/s
    assert mo.current(2.0, 0.0, P) == P.current_limit  # V/R = 0.74 A > 0.5 A: the driver limits at stall
    assert mo.current(-2.0, 0.0, P) == -P.current_limit
    assert mo.current(0.2, 0.0, P) == 0.2
    w = 30.0
    hi = (P.battery_voltage - k * w) / P.armature_resistance
    assert 0 < hi < P.current_limit and mo.current(2.0, w, P) == pytest.approx(hi)
    assert mo.current(-2.0, w, P) == -P.current_limit  # braking: the battery helps
    assert mo.current(-2.0, -w, P) == pytest.approx(-hi)
    # driven faster than the battery allows: the nearest feasible current (regenerative braking)
    w_over = (P.battery_voltage + P.armature_resistance * 1.0) / k
    assert mo.current(0.0, w_over, P) == pytest.approx((P.battery_voltage - k * w_over) / P.armature_resistance)
    assert mo.current(0.0, w_over, P) < -P.current_limit


def test_stall_torque():
    stall = P.gear_ratio * P.gear_efficiency * P.torque_constant * P.current_limit
    assert mo.wheel_torque(5.0, 0.0, P) == (pytest.approx(stall), P.current_limit)
    assert mo.wheel_torque(-5.0, 0.0, P)[0] == pytest.approx(-stall)
    assert stall == pytest.approx(0.0808, abs=1e-4)


@pytest.mark.parametrize("friction", [False, True])
def test_no_load_speed_emerges(friction):
    """The wheel alone (inertia I_w), full current reference from rest: it settles where the supply
    can no longer push current against the back-EMF, V / (k_e N) without friction."""
    p = P if friction else P.replace(viscous_friction=0.0, coulomb_friction=0.0)
    k = p.torque_constant * p.gear_ratio
    if friction:  # eta k (V - k w)/R = c_v w + T_c (tanh ~ 1 there)
        expect = (p.gear_efficiency * k * p.battery_voltage / p.armature_resistance - p.coulomb_friction) / (
            p.gear_efficiency * k * k / p.armature_resistance + p.viscous_friction)
    else:
        expect = p.battery_voltage / k
    for sign in (1, -1):
        w, dt = 0.0, 1e-3
        for _ in range(1000):  # the axle's dry friction -T_c sign(w) on a turning wheel (host_sim/physics/friction.py)
            w += dt * (mo.wheel_torque(sign * 10.0, w, p)[0] - p.coulomb_friction * np.sign(w)) / p.wheel_inertia
        assert w == pytest.approx(sign * expect, rel=1e-9)
    assert P.battery_voltage / (P.torque_constant * P.gear_ratio) == pytest.approx(38.9, abs=0.1)


@given(st.floats(1e-6, 38.0))  # below the no-load speed, where a zero reference is a zero current
def test_friction_opposes_motion(w):
    for s in (1, -1):
        t, i = mo.wheel_torque(0.0, s * w, P)
        assert i == 0.0 and s * t < 0
    assert mo.wheel_torque(0.0, 0.0, P) == (0.0, 0.0)
    # below the no-load speed (39 rad/s) a zero reference is a zero current: friction alone, the viscous
    # part in the motor's torque, the dry part -T_c sign(w) for turning wheels in the step (host_sim/physics/friction.py)
    assert mo.wheel_torque(0.0, 30.0, P)[0] == pytest.approx(-P.viscous_friction * 30)
    for s in (1, -1):
        tau = drivetrain.step((0.0,) * 5, (s * 30.0, s * 20.0), (0.0, 0.0), 1e-3, P)[2]
        assert tau == (-s * P.coulomb_friction, -s * P.coulomb_friction)


def _coast(v0, dt, n=400):
    """The whole robot (motors, dry friction, dynamics: drivetrain.drive_step), zero current, from wheel speeds v0."""
    q, v, hist = (0.0,) * 5, v0, [v0]
    for _ in range(n):
        q, v = drivetrain.drive_step(q, v, (0.0, 0.0), dt, P)[:2]
        hist.append(v)
    return q, np.array(hist)


@pytest.mark.parametrize("dt", [1e-3, 5e-3, 0.02, 0.04])
def test_no_chatter_at_rest_with_zero_reference(dt):
    """The dry friction is solved in the step, stick and slip (host_sim/physics/friction.py): at any step a
    coasting robot comes to rest without overshooting zero speed back and forth, and then stays
    exactly at rest.  (The former smoothed Coulomb friction, T_c tanh(w / 0.1 rad/s), chattered
    above dt = 7.4 ms.)"""
    q, hist = _coast((0.0, 0.0), dt)
    assert not hist.any() and q == (0.0,) * 5
    for v0 in ((0.05, -0.05), (0.08, 0.06), (3.0, -2.0), (30.0, 28.0)):
        n = round(3.0 / dt)
        _q, hist = _coast(v0, dt, n)
        energy = [kinetic_energy_reduced(v, P) for v in hist]
        assert np.all(np.diff(energy) <= 0)  # friction only takes energy out
        for j in range(2):
            # at most one zero crossing per wheel (the offset COM turns spin into forward speed: a
            # wheel may reverse once, physically), never the sign flipping of chatter
            signs = np.sign(hist[:, j][hist[:, j] != 0.0])
            assert np.count_nonzero(np.diff(signs)) <= 1
        stopped = np.flatnonzero((hist == 0.0).all(1))
        assert stopped.size and (hist[stopped[0]:] == 0.0).all()  # at rest exactly, and it stays there


def test_encoder_ticks_known_values():
    tpr = P.ticks_per_rev
    assert mo.encoder_ticks(0.0, P) == 0
    assert mo.encoder_ticks(-1e-12, P) == -1
    assert mo.encoder_ticks(2 * math.pi, P) == tpr
    assert mo.encoder_ticks(-2 * math.pi, P) == -tpr
    assert mo.encoder_ticks(2 * math.pi * 2.5, P) == 2.5 * tpr
    assert isinstance(mo.encoder_ticks(1.0, P), int)
    assert list(mo.encoder_ticks_batch([-1e-12, 0.0, 2 * math.pi], P)) == [-1, 0, tpr]


@settings(deadline=None, max_examples=300)
@given(st.integers(-10**7, 10**7), st.floats(0.001, 0.999), st.sampled_from([1200.0, 48.0, 4096.0]))
def test_encoder_ticks_floor_toward_minus_infinity(k, frac, tpr):
    p = P.replace(ticks_per_rev=tpr)
    theta = (k + frac) * 2 * math.pi / tpr
    assert mo.encoder_ticks(theta, p) == k
    assert mo.encoder_ticks_batch(np.array([theta]), p)[0] == k
    # encoder_angle(k) is the centre of tick k: half a tick above its lower edge
    assert mo.encoder_angle(k, p) == pytest.approx((k + 0.5) * 2 * math.pi / tpr, rel=1e-15, abs=1e-15)


@pytest.mark.parametrize("tpr", [1200.0, 48.0, 4096.0, 1000.0])
def test_encoder_angle_round_trips_for_every_count(tpr):
    """encoder_ticks(encoder_angle(k)) == k for every k in -10^6..10^6, scalar and batch (the lower
    edge of the tick, k 2 pi / tpr, came back as k - 1 for ~17 % of k at 1200 ticks/rev)."""
    p = P.replace(ticks_per_rev=tpr)
    k = np.arange(-10**6, 10**6 + 1)
    assert np.array_equal(mo.encoder_ticks_batch(mo.encoder_angle_batch(k, p), p), k)
    pb = dy.ParamBatch.broadcast(p, 2)
    k2 = np.stack([k, k[::-1]])  # (2, n): one row per robot of the ParamBatch
    assert np.array_equal(mo.encoder_ticks_batch(mo.encoder_angle_batch(k2, pb), pb), k2)
    if tpr == 1200.0:  # the scalar path for every k (2e6 calls, ~1 s)
        ticks, angle = mo.encoder_ticks, mo.encoder_angle
        assert all(ticks(angle(j, p), p) == j for j in range(-10**6, 10**6 + 1))
        # and the old lower edge did fail, so this test can see the fault
        assert sum(ticks(j * 2 * math.pi / tpr, p) != j for j in range(-10**4, 10**4)) > 1000
