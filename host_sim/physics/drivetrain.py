"""The coupled motor + rolling-dynamics step, second order, with stick-slip dry friction.

The motors' torque is taken at the speed predicted for the middle of the step (explicit midpoint on
the torque), the axles' dry friction solved inside the step (friction.py), then dynamics.step.
`drive_step` (Python floats, one robot) and `drive_step_batch` (numpy, N robots) compute the same thing
(tests/test_drive.py).  Derivation and measured orders: docs/dynamics.md ("Integrator"), docs/motors.md.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from host_sim.physics import dynamics, friction, motors
from numpy.typing import ArrayLike

from host_sim.physics.params import RobotParams, cached_per_params

if TYPE_CHECKING:  # annotations only
    from host_sim.physics.dynamics import Params, PerRobot, Vec


@cached_per_params
def _consts(p: RobotParams) -> tuple[float, ...]:
    """(I_lim, k_e N / R, eta k_t N, V_bat / R, c_v, T_c, g, m_t, J_t, 1/m_t, 1/J_t, m_t J_t, 1/r, b/r, r/2,
    r/(2b), d, the half-step's friction response H^-1 in wheel speeds per dt/2: diagonal, off-diagonal)."""
    lim, n_kt, eta_n_kt, v_r, inv_r, c_v, t_c = motors._consts(p)
    r, b, d, g, mt, jt, imt, ijt, hr, kw, ir, bir, mtjt = dynamics._coeffs(p)
    c = (lim, n_kt * inv_r, eta_n_kt, v_r, c_v, t_c, g, mt, jt, imt, ijt, mtjt, ir, bir, hr, kw, d,
         ir * ir * imt + bir * bir * ijt, ir * ir * imt - bir * bir * ijt)
    return c


def _torque(i: float, w: float, k_r: float, v_r: float, eta_n_kt: float, c_v: float) -> tuple[float, float]:
    """(motor torque less viscous friction, current) for the driver's clipped reference i (motors.wheel_torque)."""
    e = k_r * w
    i = v_r - e if i > v_r - e else (-v_r - e if i < -v_r - e else i)
    return eta_n_kt * i - c_v * w, i


def drive_step(q: Vec, v: Vec, i_ref: Vec, dt: float, p: RobotParams
               ) -> tuple[tuple[float, ...], tuple[float, float], tuple[float, float], tuple[float, float]]:
    """One coupled step: (q_next, v_next, (tau_l, tau_r) used (dry friction included), (i_l, i_r) at mid-step)."""
    lim, k_r, eta, v_r, c_v, t_c, g, _mt, _jt, imt, ijt, _mtjt, ir, bir, hr, kw, _d, hd, ho = _consts(p)
    il = lim if i_ref[0] > lim else (-lim if i_ref[0] < -lim else i_ref[0])
    ir_ = lim if i_ref[1] > lim else (-lim if i_ref[1] < -lim else i_ref[1])
    wl, wr = v[0], v[1]
    tl, _c = _torque(il, wl, k_r, v_r, eta, c_v)
    tr, _c = _torque(ir_, wr, k_r, v_r, eta, c_v)
    # speeds predicted at mid-step (dynamics.reduced_accel_fast, inlined), with the half step's dry friction
    u, w = hr * (wl + wr), kw * (wr - wl)
    ud = ((tl + tr) * ir + g * w * w) * imt
    wd = (bir * (tr - tl) - g * u * w) * ijt
    h = 0.5 * dt
    vl, vr = wl + h * (ir * ud - bir * wd), wr + h * (ir * ud + bir * wd)
    hd_, ho_ = h * hd, h * ho
    fl, fr, sl, sr = friction.solve(vl, vr, hd_, ho_, ho_, hd_, t_c, t_c, (wl, wr))
    wl_m, wr_m = friction.end_speeds(vl, vr, hd_, ho_, ho_, hd_, fl, fr, sl, sr)
    tl, cl = _torque(il, wl_m, k_r, v_r, eta, c_v)
    tr, cr = _torque(ir_, wr_m, k_r, v_r, eta, c_v)
    q1, v1, tau = step(q, v, (tl, tr), dt, p, (fl, fr))
    return q1, v1, tau, (cl, cr)


def step(q: Vec, v: Vec, tau: Vec, dt: float, p: RobotParams, f_pred: Vec = (0.0, 0.0)
         ) -> tuple[tuple[float, ...], tuple[float, float], tuple[float, float]]:
    """dynamics.step under the torques tau held over the step, plus the axles' dry friction solved in it:
    (q_next, v_next, the torques with the dry friction).  f_pred: the dry friction that predicted the
    mid-step yaw rate for the gyroscopic coefficient (drive_step's half step)."""
    _lim, _k_r, _eta, _v_r, _c_v, t_c, g, mt, jt, _imt, ijt, mtjt, ir, bir, hr, kw, d, _hd, _ho = _consts(p)
    wl, wr = v[0], v[1]
    tl, tr = tau[0], tau[1]
    u, w = hr * (wl + wr), kw * (wr - wl)
    h = 0.5 * dt
    # dynamics.step, inlined, without dry friction
    gam = bir * (tr - tl)
    al = h * g * (w + h * (gam + bir * (f_pred[1] - f_pred[0]) - g * u * w) * ijt)
    r1 = mt * u + al * w + dt * ir * (tl + tr)
    r2 = jt * w - al * u + dt * gam
    idet = 1.0 / (mtjt + al * al)
    u1, w1 = (jt * r1 + al * r2) * idet, (mt * r2 - al * r1) * idet
    vl, vr = ir * u1 - bir * w1, ir * u1 + bir * w1
    # its response to the dry friction, W (friction.py), and the friction
    k = dt * idet
    da, dc, ds = k * (jt * ir * ir + mt * bir * bir), k * (jt * ir * ir - mt * bir * bir), 2.0 * k * al * ir * bir
    fl, fr, sl, sr = friction.solve(vl, vr, da, dc + ds, dc - ds, da, t_c, t_c, (wl, wr))
    wl1, wr1 = friction.end_speeds(vl, vr, da, dc + ds, dc - ds, da, fl, fr, sl, sr)
    u1, w1 = hr * (wl1 + wr1), kw * (wr1 - wl1)
    sb, wb = h * (u + u1), 0.5 * (w + w1)  # distance along the heading, mean yaw rate
    dwb = dt * d * wb
    ph = q[2] + h * wb
    cs, sn = math.cos(ph), math.sin(ph)
    q1 = (q[0] + sb * cs - dwb * sn, q[1] + sb * sn + dwb * cs, q[2] + dt * wb,
          q[3] + h * (wl + wl1), q[4] + h * (wr + wr1))
    return q1, (wl1, wr1), (tl + fl, tr + fr)


def drive_step_batch(q: np.ndarray, v: np.ndarray, i_ref: ArrayLike, dt: PerRobot, p: Params, p_wheels: Params | None = None,
                     out: tuple[np.ndarray, np.ndarray] | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`drive_step` for N robots: q (N, 5), v (N, 2), i_ref (2,) or (N, 2) -> (q_next, v_next, tau, current).

    p: RobotParams or ParamBatch; p_wheels: the same parameters as motors.wheel_torque_batch
    wants them (e.g. widened to (N, 2) per wheel; default p).  out as dynamics.step_batch.
    """
    pw = p if p_wheels is None else p_wheels
    _r, _b, d, g, mt, jt, imt, ijt, hr, kw, ir, bir, mtjt = dynamics._coeffs(p)
    t_c = p.coulomb_friction
    hdt = 0.5 * dt if np.ndim(dt) == 0 else 0.5 * np.asarray(dt)
    tau, _i = motors.wheel_torque_batch(i_ref, v, pw)
    acc = dynamics.reduced_accel_batch(q, v, tau, p)
    # the half step's dry friction: its response is dt/2 H^-1 in wheel speeds
    hd, ho = hdt * (ir * ir * imt + bir * bir * ijt), hdt * (ir * ir * imt - bir * bir * ijt)
    vl, vr = v[:, 0] + hdt * acc[:, 0], v[:, 1] + hdt * acc[:, 1]
    fl, fr, sl, sr = friction.solve_batch(vl, vr, hd, ho, ho, hd, t_c, t_c, v)
    v_mid = np.stack(friction.end_speeds_batch(vl, vr, hd, ho, ho, hd, fl, fr, sl, sr), 1)
    tau, cur = motors.wheel_torque_batch(i_ref, v_mid, pw)
    # dynamics.step_batch without dry friction, its gyroscopic coefficient from the predictor
    wl, wr = v[:, 0], v[:, 1]
    tl, tr = tau[:, 0], tau[:, 1]
    u, w = hr * (wl + wr), kw * (wr - wl)
    gam = bir * (tr - tl)
    al = (hdt * g) * (w + (hdt * ijt) * (gam + bir * (fr - fl) - g * u * w))
    r1 = mt * u + al * w + dt * ir * (tl + tr)
    r2 = jt * w - al * u + dt * gam
    idet = 1.0 / (mtjt + al * al)
    u1, w1 = (jt * r1 + al * r2) * idet, (mt * r2 - al * r1) * idet
    vl, vr = ir * u1 - bir * w1, ir * u1 + bir * w1
    k = dt * idet  # the step's response to the dry friction, W (friction.py)
    da, dc, ds = k * (jt * ir * ir + mt * bir * bir), k * (jt * ir * ir - mt * bir * bir), 2.0 * k * al * ir * bir
    fl, fr, sl, sr = friction.solve_batch(vl, vr, da, dc + ds, dc - ds, da, t_c, t_c, v)
    wl1, wr1 = friction.end_speeds_batch(vl, vr, da, dc + ds, dc - ds, da, fl, fr, sl, sr)
    q1, v1 = _advance(q, v, wl1, wr1, u, w, dt, (hr, kw, d), out)
    return q1, v1, tau + np.stack([fl, fr], 1), cur


def _advance(q: np.ndarray, v: np.ndarray, wl1: np.ndarray, wr1: np.ndarray, u: np.ndarray, w: np.ndarray, dt: PerRobot,
             coeffs: tuple[PerRobot, PerRobot, PerRobot], out: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    """(q_next, v_next) from the end speeds, as dynamics.step_batch: the pose at the mean velocities."""
    hr, kw, d = coeffs
    hdt = 0.5 * dt
    u1, w1 = hr * (wl1 + wr1), kw * (wr1 - wl1)
    ub, wb = dt * 0.5 * (u + u1), 0.5 * (w + w1)
    ph = q[:, 2] + hdt * wb
    c, s = np.cos(ph), np.sin(ph)
    qn, vn = (np.empty(q.shape), np.empty(v.shape)) if out is None else out
    dwb = (dt * d) * wb
    qn[:, 0] = q[:, 0] + (ub * c - dwb * s)
    qn[:, 1] = q[:, 1] + (ub * s + dwb * c)
    qn[:, 3] = q[:, 3] + hdt * (v[:, 0] + wl1)
    qn[:, 4] = q[:, 4] + hdt * (v[:, 1] + wr1)
    qn[:, 2] = q[:, 2] + dt * wb
    vn[:, 0], vn[:, 1] = wl1, wr1
    return qn, vn
