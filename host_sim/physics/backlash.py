"""Backlash: the play in each gear between the motor side (rotor, encoder) and the wheel.  N robots, numpy.

Each gear's gap lives in [-play, play]; engaged, rotor and wheel turn as one; open, each turns on its own;
a gap that closes within a substep splits it at an inelastic impact.  Continuous in the play: with the
play -> 0 the step is the engaged one.  Model and equations: docs/effects.md, "backlash".
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from host_sim.physics import drivetrain_effects, friction
from host_sim.physics.drivetrain_effects import Drive

if TYPE_CHECKING:  # annotations only
    from host_sim.physics.dynamics import PerRobot

MAX_EVENTS = 3  # gaps that close within one substep and split it (two wheels, and a margin)
BISECTIONS = 48  # on the closing time, as a fraction of the stretch: 4e-15


def engaged_at(gap: np.ndarray, d: Drive) -> np.ndarray:
    """(N, 2) bool: the gap is closed on one side (a gear without play always is)."""
    return np.abs(gap) >= d.play


def _col(dt: np.ndarray) -> np.ndarray:
    return dt[:, None]


def rotor_step(wm: np.ndarray, w_other: np.ndarray, i_ref: np.ndarray, dt: np.ndarray, d: Drive,
               eng: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(motor-side speed at mid-stretch, at its end), (N, 2), of gears that are open: I_r w_m' = eta N k i - c_v w_m
    + f, |f| <= T_c (stick-slip), the drive step's explicit midpoint on the torque.  w_other: the engaged
    motors' speeds, which the shared supply sees."""
    k_h, k = 0.5 * _col(dt) / d.i_r, _col(dt) / d.i_r

    def torque(w: np.ndarray) -> np.ndarray:
        _volts, i = drivetrain_effects.supply(i_ref, np.where(eng, w_other, w), d)
        return d.eta * d.gear * d.kt * i - d.c_v * w

    t_m = d.dry(wm)

    def dry(free: np.ndarray, kk: np.ndarray) -> np.ndarray:
        fl, fr, sl, sr = friction.solve_batch(free[:, 0], free[:, 1], kk[:, 0], 0.0, 0.0, kk[:, 0],
                                              t_m[:, 0], t_m[:, 1], wm)
        return np.stack(friction.end_speeds_batch(free[:, 0], free[:, 1], kk[:, 0], 0.0, 0.0, kk[:, 0],
                                                  fl, fr, sl, sr), 1)

    wm_mid = dry(wm + k_h * torque(wm), k_h)
    return wm_mid, dry(wm + k * torque(wm_mid), k)


def phase(q: np.ndarray, v: np.ndarray, wm: np.ndarray, i_ref: np.ndarray, dt: np.ndarray, d: Drive, dc: PerRobot,
          eng: np.ndarray) -> list[np.ndarray]:
    """One stretch dt (N,) with the gears' modes eng (N, 2) held: [q, v, w_m at its end, the gear torque lambda
    on each wheel (0 where open), currents, supply V]."""
    wm_mid, wm1 = rotor_step(wm, v, i_ref, dt, d, eng)

    def torque(w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        volts, i = drivetrain_effects.supply(i_ref, np.where(eng, w, wm_mid), d)
        return np.where(eng, d.eta * d.gear * d.kt * i - d.c_v * w, 0.0), i, volts

    iw = np.where(eng, d.iw[:, None], d.iw[:, None] - d.i_r)
    q1, v1, tau, cur, volts = drivetrain_effects.drive_step(q, v, i_ref, dt, d, dc, torque, drivetrain_effects.inertia(d, iw),
                                                       np.where(eng, d.dry(v), 0.0))
    lam = np.where(eng, tau - d.i_r * (v1 - v) / _col(dt), 0.0)
    return [q1, v1, np.where(eng, v1, wm1), lam, cur, volts]


def impact(v: np.ndarray, wm: np.ndarray, closing: np.ndarray, d: Drive, eng: np.ndarray, alone: bool | np.ndarray = False
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wheel speeds, motor-side speeds, impulses P (N, 2) on the wheels) after the gaps `closing` close
    inelastically: (W + diag(1 / I_r)) P = w_m - w on them, P = 0 elsewhere.  W = J H^-1 J^T with the
    modes eng before the impact (the closing gears open), or 1 / (I_w - I_r) for a wheel that takes it
    alone (its tyre slips: `alone` (N,) bool)."""
    iw = np.where(eng, d.iw[:, None], d.iw[:, None] - d.i_r)
    a, bb, c = drivetrain_effects.inertia(d, iw)
    det = a * c - bb * bb
    w11, w12, w21, w22 = drivetrain_effects._response(c / det, -bb / det, -bb / det, a / det, d)
    w11, w22 = np.where(alone, 1.0 / iw[:, 0], w11), np.where(alone, 1.0 / iw[:, 1], w22)
    w12, w21 = np.where(alone, 0.0, w12), np.where(alone, 0.0, w21)
    cl, cr = closing[:, 0], closing[:, 1]
    k = 1.0 / d.i_r[:, 0]
    a11, a22 = np.where(cl, w11 + k, 1.0), np.where(cr, w22 + k, 1.0)
    a12, a21 = np.where(cl & cr, w12, 0.0), np.where(cl & cr, w21, 0.0)
    b1, b2 = np.where(cl, wm[:, 0] - v[:, 0], 0.0), np.where(cr, wm[:, 1] - v[:, 1], 0.0)
    det2 = a11 * a22 - a12 * a21
    p = np.stack([(a22 * b1 - a12 * b2) / det2, (a11 * b2 - a21 * b1) / det2], 1)
    v1 = v + np.stack([w11 * p[:, 0] + w12 * p[:, 1], w21 * p[:, 0] + w22 * p[:, 1]], 1)
    wm1 = np.where(closing | eng, v1, wm - p / d.i_r)
    return v1, wm1, p


def closing_fraction(gap: np.ndarray, rate0: np.ndarray, rate1: np.ndarray, dt: np.ndarray, stop: np.ndarray
                     ) -> np.ndarray:
    """(K, 2): the fraction of the stretch dt (K,) at which gap + dt (rate0 s + (rate1 - rate0) s^2 / 2)
    reaches `stop` (the play, signed), s in [0, 1], for gaps that reach it at s = 1 (bisection: exactly one
    root in between, the function being a quadratic <= 0 at 0 and > 0 at 1)."""
    sgn = np.sign(stop)
    lo, hi = np.zeros(gap.shape), np.ones(gap.shape)
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        beyond = sgn * (gap + _col(dt) * mid * (rate0 + 0.5 * (rate1 - rate0) * mid)) >= sgn * stop
        lo, hi = np.where(beyond, lo, mid), np.where(beyond, mid, hi)
    return hi


def substep(q: np.ndarray, v: np.ndarray, wm: np.ndarray, gap: np.ndarray, i_ref: ArrayLike, dt: PerRobot, d: Drive, dc: PerRobot,
            events: int = 0) -> list[np.ndarray]:
    """The drive step over dt with the gears' play: [q, v, w_m, gap at its end, the mean gear torque on each
    wheel over dt (N, 2) but for the impacts, currents, supply V, the impacts' jumps in wheel speed (N, 2)].
    The tyres' grip is judged without the impacts (traction_ok from v + the jumps): a real gear spreads them
    over its compliance's few ms (docs/effects.md)."""
    n = len(q)
    i_ref = np.broadcast_to(np.asarray(i_ref, dtype=float), (n, 2))
    dt = np.broadcast_to(np.asarray(dt, dtype=float), (n,))
    dc = np.broadcast_to(np.asarray(dc, dtype=float), (n,))
    eng = engaged_at(gap, d)
    out = phase(q, v, wm, i_ref, dt, d, dc, eng)
    pull = eng & (d.play > 0.0) & (np.sign(gap) * out[3] < 0.0)
    if pull.any():  # the gear would pull: it opens, and the stretch is taken again
        eng = eng & ~pull
        rows = np.flatnonzero(pull.any(1))
        _put(out, rows, phase(q[rows], v[rows], wm[rows], i_ref[rows], dt[rows], d.sub(rows), dc[rows], eng[rows]))
    gap1 = np.where(eng, gap, gap + 0.5 * _col(dt) * (wm + out[2] - v - out[1]))
    over = ~eng & (np.abs(gap1) > d.play)
    out[3] = out[3] * _col(dt)  # the gear's impulse over the stretch, until the end
    out.insert(3, np.clip(gap1, -d.play, d.play))
    out.append(np.zeros(v.shape))  # the impacts' jumps in wheel speed
    if over.any():
        rows = np.flatnonzero(over.any(1))
        rate1 = out[2][rows] - out[1][rows]
        _put(out, rows, _close(q[rows], v[rows], wm[rows], gap[rows], gap1[rows], rate1, over[rows], i_ref[rows],
                               dt[rows], d.sub(rows), dc[rows], eng[rows], events))
    out[4] = out[4] / _col(dt)
    return out


def _close(q: np.ndarray, v: np.ndarray, wm: np.ndarray, gap: np.ndarray, gap1: np.ndarray, rate1: np.ndarray,
           over: np.ndarray, i_ref: np.ndarray, dt: np.ndarray, d: Drive, dc: np.ndarray, eng: np.ndarray, events: int
           ) -> list[np.ndarray]:
    """`substep` for robots with a gap that closes within dt: the stretch until the first closes, the impact,
    then the rest of dt (substep again).  gap1, rate1: the gap and its rate at the end of dt had none closed.
    [q, v, w_m, gap, gear impulse over dt but the impacts', currents, V, the impacts' jumps in wheel speed]."""
    if events < MAX_EVENTS:
        frac = np.where(over, closing_fraction(gap, wm - v, rate1, dt, np.sign(gap1) * d.play), np.inf)
        first = frac.min(1)
        t1, closing = dt * first, over & (frac <= first[:, None])
    else:  # a last resort: the gaps close at the end of dt
        t1, closing = dt, over
    out = phase(q, v, wm, i_ref, t1, d, dc, eng)
    gap_a = gap + 0.5 * _col(t1) * (wm + out[2] - v - out[1])
    gap_a = np.where(closing, np.sign(gap1) * d.play, np.clip(gap_a, -d.play, d.play))
    v_a = out[1]
    out[1], out[2], _p = impact(v_a, out[2], closing, d, eng)
    impulse = out[3] * _col(t1)
    rest = dt - t1
    later = np.flatnonzero(rest > 0.0)
    res = [out[0], out[1], out[2], gap_a, impulse, out[4], out[5], out[1] - v_a]
    if later.size:
        tail = substep(out[0][later], out[1][later], out[2][later], gap_a[later], i_ref[later], rest[later],
                       d.sub(later), dc[later], events + 1)
        tail[4] = tail[4] * _col(rest[later]) + impulse[later]
        tail[7] = tail[7] + res[7][later]
        _put(res, later, tail)
    return res


def _put(out: list[np.ndarray], rows: np.ndarray, new: list[np.ndarray]) -> None:
    """out[k][rows] = new[k] for each array, in place (arrays copied first, as they may be views)."""
    for k, a in enumerate(new):
        full = out[k].copy()
        full[rows] = a
        out[k] = full


def after_contact(turned: np.ndarray, v1: np.ndarray, wm: np.ndarray, gap: np.ndarray, d: Drive
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wheel speeds, motor-side speeds, gaps) (K, 2) when a contact step (contact.slip_step_batch) replaced the
    rolling one, driving the wheels whose gear `substep` left engaged (wm, gap: its ends): those turn with
    their wheels (v1, gap kept).  The open ones' motor sides turned as in the rolling step, their wheels
    `turned` (K, 2) rad less than there; a gap that the wheel closes so closes inelastically with the wheel
    alone (a simplification: docs/effects.md, "backlash")."""
    eng = engaged_at(gap, d)
    moved = np.where(eng, gap, gap + turned)
    over = ~eng & (np.abs(moved) > d.play)
    gap1 = np.clip(moved, -d.play, d.play)
    wm1 = np.where(eng, v1, wm)
    if over.any():
        v1, wm1, _p = impact(v1, wm1, over, d, eng, alone=True)
    return v1, wm1, gap1
