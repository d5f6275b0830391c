"""The coupled motor + rolling-dynamics step, second order: scalar and batch side by side.

The motors (host_sim/motors.py) give the wheel torques from the current
references and the wheel speeds; the dynamics (host_sim/dynamics.py) advance
the robot under a torque held over the step.  Evaluating the torque at the
start of the step makes the coupled step first order, however good the
dynamics step is.  Here the torque is taken at the speed predicted for the
middle of the step (explicit midpoint on the torque):

    tau_n   = tau(i_ref, v_n)
    v_mid   = v_n + dt/2 * v'(v_n, tau_n)          (reduced closed form)
    tau_mid = tau(i_ref, v_mid)
    (q, v)_{n+1} = dynamics.step(q_n, v_n, tau_mid, dt)

which is second order for the coupled system wherever the torque is smooth
in the speed (docs/dynamics.md, "Integrator", the measured table).  It costs
one reduced acceleration and two more motor evaluations per step, inlined
here so the scalar path stays a single call.

`drive_step` (pure-Python floats, one robot) and `drive_step_batch` (numpy,
N robots, per-robot parameters) compute the same thing; tests/test_drive.py
checks them against each other and against an RK4 of the coupled system.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from host_sim import dynamics, motors
from host_sim.params import RobotParams, cached_per_params


@cached_per_params
def _consts(p: RobotParams) -> tuple[float, ...]:
    """(I_lim, k_e N / R, eta k_t N, V_bat / R, c_v, T_c, 1 / w_eps, g/m_t, 1/J_t, r, b, 1/r, b/r), cached."""
    lim, n_kt, eta_n_kt, v_r, inv_r, c_v, t_c = motors._consts(p)
    r, b, _d, g, _mt, _jt, imt, ijt = dynamics._coeffs(p)[:8]
    c = (lim, n_kt * inv_r, eta_n_kt, v_r, c_v, t_c, 1.0 / motors.COULOMB_EPS, g, imt, ijt, r, b, 1.0 / r, b / r)
    return c


def drive_step(q: Any, v: Any, i_ref: Any, dt: float, p: RobotParams
               ) -> tuple[tuple[float, ...], tuple[float, float], tuple[float, float], tuple[float, float]]:
    """One coupled step: (q_next, v_next, (tau_l, tau_r) used, (i_l, i_r) at mid-step)."""
    lim, k_r, eta_n_kt, v_r, c_v, t_c, i_eps, g, imt, ijt, r, b, ir, bir = _consts(p)
    il, ir_ = i_ref[0], i_ref[1]
    il = lim if il > lim else (-lim if il < -lim else il)
    ir_ = lim if ir_ > lim else (-lim if ir_ < -lim else ir_)
    wl, wr = v[0], v[1]
    # torques at v_n (motors.wheel_torque, inlined)
    e = k_r * wl
    i0 = v_r - e if il > v_r - e else (-v_r - e if il < -v_r - e else il)
    tl = eta_n_kt * i0 - c_v * wl - t_c * math.tanh(wl * i_eps)
    e = k_r * wr
    i0 = v_r - e if ir_ > v_r - e else (-v_r - e if ir_ < -v_r - e else ir_)
    tr = eta_n_kt * i0 - c_v * wr - t_c * math.tanh(wr * i_eps)
    # speeds predicted at mid-step (dynamics.reduced_accel_fast, inlined)
    u = 0.5 * r * (wl + wr)
    w = 0.5 * r * (wr - wl) / b
    ud = ((tl + tr) * ir + g * w * w) * imt
    wd = (bir * (tr - tl) - g * u * w) * ijt
    h = 0.5 * dt
    wl_m = wl + h * (ud - b * wd) * ir
    wr_m = wr + h * (ud + b * wd) * ir
    # torques at the mid-step speeds
    e = k_r * wl_m
    cl = v_r - e if il > v_r - e else (-v_r - e if il < -v_r - e else il)
    tl = eta_n_kt * cl - c_v * wl_m - t_c * math.tanh(wl_m * i_eps)
    e = k_r * wr_m
    cr = v_r - e if ir_ > v_r - e else (-v_r - e if ir_ < -v_r - e else ir_)
    tr = eta_n_kt * cr - c_v * wr_m - t_c * math.tanh(wr_m * i_eps)
    q1, v1 = dynamics.step(q, v, (tl, tr), dt, p)
    return q1, v1, (tl, tr), (cl, cr)


def drive_step_batch(q: np.ndarray, v: np.ndarray, i_ref: Any, dt: Any, p: Any, p_wheels: Any = None,
                     out: tuple[np.ndarray, np.ndarray] | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`drive_step` for N robots: q (N, 5), v (N, 2), i_ref (2,) or (N, 2) -> (q_next, v_next, tau, current).

    p: RobotParams or ParamBatch; p_wheels: the same parameters as motors.wheel_torque_batch
    wants them (e.g. widened to (N, 2) per wheel; default p).  out as dynamics.step_batch.
    """
    pw = p if p_wheels is None else p_wheels
    tau, _i = motors.wheel_torque_batch(i_ref, v, pw)
    acc = dynamics.reduced_accel_batch(q, v, tau, p)
    v_mid = v + (0.5 * dt if np.ndim(dt) == 0 else 0.5 * np.asarray(dt)[:, None]) * acc
    tau, cur = motors.wheel_torque_batch(i_ref, v_mid, pw)
    q1, v1 = dynamics.step_batch(q, v, tau, dt, p, out=out)
    return q1, v1, tau, cur
