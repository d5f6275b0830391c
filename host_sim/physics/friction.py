"""Dry (Coulomb) friction at the two wheel axles, stick-slip, solved at the velocity level.

Over a step each wheel's friction is a torque held constant within its bound; the step is linear in
it, a 2x2 problem with exactly one solution (a wheel reversing within the step gets its mean friction).
`solve` (Python floats, one robot) and `solve_batch` (numpy, N robots) compute the same thing
(tests/test_friction.py).  Model and equations: docs/motors.md (dry friction), docs/effects.md.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # annotations only: no import at run time
    from host_sim.physics.dynamics import PerRobot


def _clip(x: float, lim: float) -> float:
    return lim if x > lim else (-lim if x < -lim else x)


def solve(vl: float, vr: float, w11: float, w12: float, w21: float, w22: float, tl: float, tr: float,
          start: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float, bool, bool]:
    """(f_l, f_r, left sticks, right sticks) for end speeds v = (vl, vr) + W f, |f_i| <= T_i; start: the
    wheel speeds at the start of the step (a wheel that reverses in it: the mean friction)."""
    # both wheels keep turning the way they would without friction (the common case): done
    fl, fr = (-tl if vl > 0.0 else tl), (-tr if vr > 0.0 else tr)
    el, er = vl + w11 * fl + w12 * fr, vr + w21 * fl + w22 * fr
    if el * fl < 0.0 and er * fr < 0.0 and el * start[0] >= 0.0 and er * start[1] >= 0.0:
        return fl, fr, False, False
    fl, fr, stick_l, stick_r = _box(vl, vr, w11, w12, w21, w22, tl, tr)
    el, er = end_speeds(vl, vr, w11, w12, w21, w22, fl, fr, stick_l, stick_r)
    fl_c, cross_l = _reversal(start[0], el, fl, w11, tl)
    fr_c, cross_r = _reversal(start[1], er, fr, w22, tr)
    if cross_l and cross_r:
        return fl_c, fr_c, False, False
    if cross_l:
        fr = _clip(-(vr + w21 * fl_c) / w22, tr)
        return fl_c, fr, False, abs(fr) < tr
    if cross_r:
        fl = _clip(-(vl + w12 * fr_c) / w11, tl)
        return fl, fr_c, abs(fl) < tl, False
    return fl, fr, stick_l, stick_r


def _reversal(a: float, e: float, f: float, w: float, t: float) -> tuple[float, bool]:
    """(the mean friction, True) if a wheel that turned at speed a at the start of the step went through zero
    in it and slips the other way at its end, else (f, False).  e, f: its end speed and friction as
    time-stepping has them (stopped and sticking, or slipping); w its own response.  Under -T sign(a) all
    along it would end at e1 and reach zero at the fraction theta = a / (a - e1) of the step; the mean
    friction T sign(a) (1 - 2 theta) then ends it at e + w (f_mean - f), reversed if that is past zero."""
    if a == 0.0:
        return f, False
    s = 1.0 if a > 0.0 else -1.0
    e1 = e + w * (-t * s - f)
    if s * e1 >= 0.0:
        return f, False
    f_mean = t * s * (1.0 - 2.0 * a / (a - e1))
    return (f_mean, True) if s * (e + w * (f_mean - f)) < 0.0 else (f, False)


def _box(vl: float, vr: float, w11: float, w12: float, w21: float, w22: float, tl: float, tr: float
         ) -> tuple[float, float, bool, bool]:
    """The time-stepping friction: the right wheel's three states in turn, the least violating."""
    # the right wheel sticks: the left one sees the Schur complement
    s = w11 - w12 * w21 / w22
    fl = _clip(-(vl - w12 * vr / w22) / s, tl)
    fr = -(vr + w21 * fl) / w22
    viol = max(abs(fr) - tr, 0.0)
    best = (viol, fl, fr, abs(fl) < tl, True)
    for side in (1.0, -1.0):  # the right wheel slips forwards (+1) or backwards
        fr = -side * tr
        fl = _clip(-(vl + w12 * fr) / w11, tl)
        viol = max(-side * (vr + w21 * fl + w22 * fr), 0.0) / w22  # a speed against its friction, as a torque
        if viol < best[0]:
            best = (viol, fl, fr, abs(fl) < tl, False)
    _v, fl, fr, stick_l, stick_r = best
    return fl, fr, stick_l, stick_r


def end_speeds(vl: float, vr: float, w11: float, w12: float, w21: float, w22: float, fl: float, fr: float,
               stick_l: bool, stick_r: bool) -> tuple[float, float]:
    """v_free + W f, exactly 0 for a wheel that sticks (no creep by rounding error)."""
    return (0.0 if stick_l else vl + w11 * fl + w12 * fr), (0.0 if stick_r else vr + w21 * fl + w22 * fr)


def solve_batch(vl: np.ndarray, vr: np.ndarray, w11: PerRobot, w12: PerRobot, w21: PerRobot, w22: PerRobot, tl: PerRobot, tr: PerRobot,
                start: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`solve` for N robots: (f_l, f_r, left sticks, right sticks), each (N,); start (N, 2) the speeds at the
    step's start (None: 0).  Robots whose wheels both keep turning their way are done in a few
    operations; the others take `solve`'s candidates, vectorised."""
    fl = np.where(vl > 0.0, -tl, tl)
    fr = np.where(vr > 0.0, -tr, tr)
    el, er = vl + w11 * fl + w12 * fr, vr + w21 * fl + w22 * fr
    stick_l = np.zeros(vl.shape, dtype=bool)
    stick_r = np.zeros(vl.shape, dtype=bool)
    easy = (el * fl < 0.0) & (er * fr < 0.0)
    if start is not None:
        easy &= (el * start[:, 0] >= 0.0) & (er * start[:, 1] >= 0.0)
    near = np.flatnonzero(~easy)
    if 0 < near.size <= FEW:
        _solve_each(near, vl, vr, (w11, w12, w21, w22), tl, tr, start, (fl, fr, stick_l, stick_r))
    elif near.size:
        sub = (lambda a: a[near] if isinstance(a, np.ndarray) and a.ndim else a)
        w = (sub(w11), sub(w12), sub(w21), sub(w22))
        g = _three_candidates(vl[near], vr[near], *w, sub(tl), sub(tr))
        if start is not None:
            g = _crossings(vl[near], vr[near], w, sub(tl), sub(tr), g, start[near])
        fl[near], fr[near], stick_l[near], stick_r[near] = g
    return fl, fr, stick_l, stick_r


FEW = 32  # up to this many robots off the easy path, `solve` one by one beats numpy's per-call cost


def _solve_each(near: np.ndarray, vl: np.ndarray, vr: np.ndarray, w: tuple[PerRobot, ...], tl: PerRobot, tr: PerRobot,
                start: np.ndarray | None, out: tuple[np.ndarray, ...]) -> None:
    """`solve` for the robots `near`, written into out = (f_l, f_r, left sticks, right sticks); the same
    floating-point operations in the same order, so bit for bit the vectorised answer
    (tests/test_friction.py::test_batch_equals_scalar_bit_for_bit_on_either_path)."""
    def each(a: PerRobot) -> list[float]:
        return a[near].tolist() if isinstance(a, np.ndarray) and a.ndim else [float(a)] * near.size
    cols = [each(a) for a in (vl, vr, *w, tl, tr)]
    starts = start[near].tolist() if start is not None else [(0.0, 0.0)] * near.size
    fl, fr, stick_l, stick_r = out
    for j, i in enumerate(near.tolist()):
        fl[i], fr[i], stick_l[i], stick_r[i] = solve(*(c[j] for c in cols), start=tuple(starts[j]))


def _crossings(vl: np.ndarray, vr: np.ndarray, w: tuple[PerRobot, ...], tl: PerRobot, tr: PerRobot, g: tuple[np.ndarray, ...],
               start: np.ndarray) -> tuple[np.ndarray, ...]:
    """`solve`'s mean friction of the wheels that reverse in the step (`_reversal`), for K robots."""
    w11, w12, w21, w22 = w
    fl, fr, stick_l, stick_r = g
    el, er = end_speeds_batch(vl, vr, w11, w12, w21, w22, fl, fr, stick_l, stick_r)
    fl_c, cross_l = _reversal_batch(start[:, 0], el, fl, w11, tl)
    fr_c, cross_r = _reversal_batch(start[:, 1], er, fr, w22, tr)
    only_l, only_r = cross_l & ~cross_r, cross_r & ~cross_l
    fr_o = np.clip(-(vr + w21 * fl_c) / w22, -tr, tr)
    fl_o = np.clip(-(vl + w12 * fr_c) / w11, -tl, tl)
    fl = np.where(cross_l, fl_c, np.where(only_r, fl_o, fl))
    fr = np.where(cross_r, fr_c, np.where(only_l, fr_o, fr))
    stick_l = np.where(cross_l, False, np.where(only_r, np.abs(fl_o) < tl, stick_l))
    stick_r = np.where(cross_r, False, np.where(only_l, np.abs(fr_o) < tr, stick_r))
    return fl, fr, stick_l, stick_r


def _reversal_batch(a: np.ndarray, e: np.ndarray, f: np.ndarray, w: PerRobot, t: PerRobot) -> tuple[np.ndarray, np.ndarray]:
    """`_reversal` for K wheels."""
    s = np.sign(a)
    e1 = e + w * (-t * s - f)
    crossed = s * e1 < 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        f_mean = np.where(crossed, t * s * (1.0 - 2.0 * a / (a - e1)), f)
    cross = crossed & (s * (e + w * (f_mean - f)) < 0.0)
    return np.where(cross, f_mean, f), cross


def _three_candidates(vl: np.ndarray, vr: np.ndarray, w11: PerRobot, w12: PerRobot, w21: PerRobot, w22: PerRobot, tl: PerRobot, tr: PerRobot
                      ) -> tuple[np.ndarray, ...]:
    """`solve`'s three candidates (the right wheel sticks, slips forwards, backwards), the least violating."""
    s = w11 - w12 * w21 / w22
    fl = np.clip(-(vl - w12 * vr / w22) / s, -tl, tl)
    fr = -(vr + w21 * fl) / w22
    best_v = np.maximum(np.abs(fr) - tr, 0.0)
    best_fl, best_fr, best_sr = fl, fr, np.ones(vl.shape, dtype=bool)
    for side in (1.0, -1.0):
        fr = np.broadcast_to(-side * tr, vl.shape)
        fl = np.clip(-(vl + w12 * fr) / w11, -tl, tl)
        viol = np.maximum(-side * (vr + w21 * fl + w22 * fr), 0.0) / w22
        better = viol < best_v
        best_v = np.where(better, viol, best_v)
        best_fl, best_fr = np.where(better, fl, best_fl), np.where(better, fr, best_fr)
        best_sr = best_sr & ~better
    return best_fl, best_fr, np.abs(best_fl) < tl, best_sr


def end_speeds_batch(vl: np.ndarray, vr: np.ndarray, w11: PerRobot, w12: PerRobot, w21: PerRobot, w22: PerRobot, fl: np.ndarray,
                     fr: np.ndarray, stick_l: np.ndarray, stick_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`end_speeds` for N robots."""
    return (np.where(stick_l, 0.0, vl + w11 * fl + w12 * fr), np.where(stick_r, 0.0, vr + w21 * fl + w22 * fr))
