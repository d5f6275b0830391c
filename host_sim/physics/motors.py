"""DC gear motors (current-regulated, paper section 3.2, or on an H-bridge) and wheel encoders.

The driver delivers i_ref clipped to its limit and to what the battery can push against the back-EMF;
the wheel torque is eta N k_t i - c_v w (the axle's dry friction is solved in the step: friction.py).
Encoders count floor(theta / 2 pi * ticks_per_rev).  Scalar functions take Python floats; *_batch ones
arrays (N,) or (N, 2) with a RobotParams or a ParamBatch; bridge_* the H-bridge drives'.  Equations: docs/motors.md.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from numpy.typing import ArrayLike

from host_sim.physics.params import RobotParams, cached_per_params

if TYPE_CHECKING:  # annotations only: no import at run time
    from host_sim.physics.dynamics import Params, PerRobot

TWO_PI = 2.0 * math.pi


def current(i_ref: float, w: float, p: RobotParams) -> float:
    """The current (A) the driver delivers for a reference i_ref (A) at wheel speed w (rad/s)."""
    lim = p.current_limit
    i = lim if i_ref > lim else (-lim if i_ref < -lim else i_ref)
    emf = p.torque_constant * p.gear_ratio * w
    r = p.armature_resistance
    hi = (p.battery_voltage - emf) / r
    if i > hi:
        return hi
    lo = (-p.battery_voltage - emf) / r
    return lo if i < lo else i


@cached_per_params
def _consts(p: RobotParams) -> tuple[float, ...]:
    """(I_lim, k_e N, eta k_t N, V_bat / R, 1 / R, c_v, T_c), cached for the last RobotParams (frozen)."""
    n_kt = float(p.gear_ratio * p.torque_constant)
    c = (float(p.current_limit), n_kt, float(p.gear_efficiency) * n_kt,
         float(p.battery_voltage / p.armature_resistance), 1.0 / float(p.armature_resistance),
         float(p.viscous_friction), float(p.coulomb_friction))
    return c


def wheel_torque(i_ref: float, w: float, p: RobotParams) -> tuple[float, float]:
    """(torque on the wheel (N m) from the motor less the viscous friction, motor current (A)) for a current
    reference i_ref at wheel speed w.  The axle's dry friction is the step's (host_sim/physics/friction.py)."""
    lim, n_kt, eta_n_kt, v_r, inv_r, c_v, _t_c = _consts(p)
    i = lim if i_ref > lim else (-lim if i_ref < -lim else i_ref)
    emf_r = n_kt * w * inv_r
    if i > v_r - emf_r:
        i = v_r - emf_r
    elif i < -v_r - emf_r:
        i = -v_r - emf_r
    return eta_n_kt * i - c_v * w, i


def wheel_torque_slope(i_ref: float, w: float, p: RobotParams) -> tuple[float, float, float]:
    """(torque (N m), current (A), d torque / d w (N m s, <= 0)) at wheel speed w: wheel_torque and its
    slope, for a linearly implicit step of a wheel that spins freely (host_sim/physics/contact.py)."""
    lim, n_kt, eta_n_kt, v_r, inv_r, c_v, _t_c = _consts(p)
    i = lim if i_ref > lim else (-lim if i_ref < -lim else i_ref)
    emf_r = n_kt * w * inv_r
    slope = -c_v
    if i > v_r - emf_r:  # the battery, not the driver, sets the current: back-EMF damping
        i = v_r - emf_r
        slope -= eta_n_kt * n_kt * inv_r
    elif i < -v_r - emf_r:
        i = -v_r - emf_r
        slope -= eta_n_kt * n_kt * inv_r
    return eta_n_kt * i - c_v * w, i, slope


def _axis0(a: PerRobot, ndim: int) -> Any:
    """Per-robot parameter arrays (N,) broadcast against data of shape (N, ...)."""
    if isinstance(a, np.ndarray) and a.ndim == 1 and ndim > 1:
        return a.reshape((-1,) + (1,) * (ndim - 1))
    return a


def wheel_torque_batch(i_ref: ArrayLike, w: ArrayLike, p: Params) -> tuple[np.ndarray, np.ndarray]:
    """(torque, current) for arrays i_ref, w of shape (N,) or (N, 2); p RobotParams or ParamBatch."""
    w, nd, n_kt, _inv_r, i, _limited = _driver_batch(i_ref, w, p)
    torque = _axis0(p.gear_efficiency, nd) * n_kt * i - _axis0(p.viscous_friction, nd) * w
    return torque, i


def _driver_batch(i_ref: ArrayLike, w: ArrayLike, p: Params
                  ) -> tuple[np.ndarray, int, Any, Any, np.ndarray, np.ndarray]:
    """(w, its ndim, k_e N, 1 / R, the current the driver delivers, where the battery limits it): arrays."""
    i_ref = np.asarray(i_ref, dtype=float)
    w = np.asarray(w, dtype=float)
    nd = w.ndim
    lim = _axis0(p.current_limit, nd)
    n_kt = _axis0(p.gear_ratio * p.torque_constant, nd)
    inv_r = _axis0(1.0 / p.armature_resistance, nd)
    vb = _axis0(p.battery_voltage, nd)
    emf = n_kt * w
    i = np.minimum(np.maximum(i_ref, -lim), lim)
    hi, lo = (vb - emf) * inv_r, (-vb - emf) * inv_r
    limited = (i > hi) | (i < lo)
    return w, nd, n_kt, inv_r, np.minimum(np.maximum(i, lo), hi), limited


def wheel_torque_slope_batch(i_ref: ArrayLike, w: ArrayLike, p: Params) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """wheel_torque_slope for arrays i_ref, w of shape (N,) or (N, 2): (torque, current, slope)."""
    w, nd, n_kt, inv_r, i, limited = _driver_batch(i_ref, w, p)
    eta_n_kt = _axis0(p.gear_efficiency, nd) * n_kt
    c_v = _axis0(p.viscous_friction, nd)
    torque = eta_n_kt * i - c_v * w
    slope = -c_v - np.where(limited, eta_n_kt * n_kt * inv_r, 0.0)
    return torque, i, slope


def ticks_per_rev(p: RobotParams, wheel: int | None = None) -> float:
    """Encoder counts per wheel turn: the nominal, or wheel 0 (left) / 1 (right)'s own (the encoder_scale effect)."""
    if wheel is None:
        return p.ticks_per_rev
    return p.ticks_per_rev + (p.ticks_per_rev_delta_l if wheel == 0 else p.ticks_per_rev_delta_r)


def encoder_ticks(theta: float, p: RobotParams, wheel: int | None = None) -> int:
    """Cumulative encoder count for a wheel angle theta (rad): floor(theta / (2 pi) * ticks_per_rev),
    with wheel 0 / 1 that wheel's own counts per turn."""
    return math.floor(theta / TWO_PI * ticks_per_rev(p, wheel))


def encoder_ticks_batch(theta: ArrayLike, p: Params, wheels: bool = False) -> np.ndarray:
    """encoder_ticks for an array of angles (N,) or (N, 2) -> int64 array of the same shape.

    wheels: theta is (N, 2) (left, right), each wheel counted with its own counts per turn."""
    theta = np.asarray(theta, dtype=float)
    if wheels:
        tpr = np.stack([np.asarray(p.ticks_per_rev + p.ticks_per_rev_delta_l, dtype=float),
                        np.asarray(p.ticks_per_rev + p.ticks_per_rev_delta_r, dtype=float)], -1)
        return np.floor(theta / TWO_PI * tpr).astype(np.int64)
    return np.floor(theta / TWO_PI * _axis0(p.ticks_per_rev, theta.ndim)).astype(np.int64)


def encoder_angle(ticks: int, p: RobotParams, wheel: int | None = None) -> float:
    """The centre (rad) of tick `ticks`: encoder_ticks(encoder_angle(k)) == k for every k.

    The centre, not the lower edge: k * 2 pi / tpr, divided back by 2 pi / tpr,
    rounds to just below k for about one k in six, and floor then gives k - 1."""
    return (ticks + 0.5) * TWO_PI / ticks_per_rev(p, wheel)


def encoder_angle_batch(ticks: ArrayLike, p: Params) -> np.ndarray:
    """encoder_angle for an array of counts (N,) or (N, 2) -> float array of the same shape."""
    ticks = np.asarray(ticks, dtype=float)
    return (ticks + 0.5) * (TWO_PI / _axis0(p.ticks_per_rev, ticks.ndim))


# --------------------------------------------------------------------------- #
# H-bridge drives (voltage, duty, wheel_speed): docs/motors.md "Drives"
# --------------------------------------------------------------------------- #
MIN_CYCLE_TAU = 1e-12  # L f / R below this: the current follows the bridge at once (L = 0)


def bridge_duty(duty: ArrayLike, deadband: Any, dead_time: Any, frequency: Any) -> np.ndarray:
    """The duty the bridge delivers for a commanded signed duty: clipped to [-1, 1], the deadband taken off
    and the rest stretched back over [0, 1], then each cycle's on-phase shortened by the dead time."""
    duty = np.asarray(duty, dtype=float)
    m = np.minimum(np.abs(duty), 1.0)
    m = np.maximum(m - deadband, 0.0) / (1.0 - deadband)
    m = np.maximum(m - dead_time * frequency, 0.0)
    return np.where(duty < 0.0, -m, m)


def bridge_current(duty: ArrayLike, emf: ArrayLike, volts: Any, res: Any, inductance: Any, frequency: Any,
                   brake: Any) -> np.ndarray:
    """The motor current (A) averaged over a PWM cycle in periodic steady state: sign-magnitude PWM at signed
    duty d (the bridge's, bridge_duty) from a supply at `volts`, against the back-EMF `emf` (V), armature
    R `res` and L `inductance`, at `frequency`.  brake (slow decay): the linear (d V - e) / R.  Coast (fast
    decay): the off-phase drives the current back through the diodes against -V; where it reaches 0 within
    the cycle (discontinuous conduction, light load) the terminal shows e until the next cycle.  Arrays
    broadcast together; the closed form's derivation is in docs/motors.md."""
    sign, d, e = _mirrored(duty, emf)
    _k, _fall_on, _rise, x = _coasting(d, e, volts, res, inductance, frequency)
    return sign * _mean_current(d, e, volts, res, brake, x)


def bridge_currents(duty: ArrayLike, emf: ArrayLike, volts: Any, res: Any, inductance: Any, frequency: Any,
                    brake: Any) -> tuple[np.ndarray, np.ndarray]:
    """(the motor's mean current, the battery's) (A) over a PWM cycle in periodic steady state, for
    bridge_current's arguments.  The battery gives the motor's current while the bridge connects it: the
    on-phase and, coasting, the diodes' return against it.  Not (R i + e) i / V of the mean current i: the
    ripple's R <i^2> is drawn too, most of it at light duty (docs/motors.md, "The battery's current";
    tests/test_drives.py::test_the_battery_current_is_the_switched_circuits_cycle_average)."""
    sign, d, e = _mirrored(duty, emf)  # the mirror image: the battery's current keeps its sign
    k, fall_on, rise, x = _coasting(d, e, volts, res, inductance, frequency)
    on_target, off_target = volts - e, np.where(brake, -e, -volts - e)  # R i each phase relaxes towards
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        fall_off = -np.expm1(-(1.0 - d) / k)
        start = (off_target * fall_off + on_target * fall_on * (1.0 - fall_off)) / -np.expm1(-1.0 / k)
        end = on_target + (start - on_target) * (1.0 - fall_on)
        on = on_target * d + (start - on_target) * k * fall_on  # R x the charge of each phase, per period
        off = off_target * (1.0 - d) + (end - off_target) * k * fall_off
        broken = on_target * d - off_target * x - 2.0 * k * rise  # discontinuous: from 0, back to 0 at x
    coast = np.where(e >= volts, volts - e, np.where((e > -volts) & (x < 1.0 - d), broken, on - off))
    return sign * _mean_current(d, e, volts, res, brake, x), np.where(brake, on, coast) / res


def _mirrored(duty: ArrayLike, emf: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sign, |d|, e seen by |d|): a negative duty is the mirror image of a positive one."""
    duty, emf = np.asarray(duty, dtype=float), np.asarray(emf, dtype=float)
    sign = np.where(duty < 0.0, -1.0, 1.0)
    return sign, np.abs(duty), sign * emf


def _coasting(d: np.ndarray, e: np.ndarray, volts: Any, res: Any, inductance: Any, frequency: Any
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(k = L / (R T), 1 - e^(-d/k), R i at the end of an on-phase from 0, the share x of the cycle a coasting
    off-phase takes to bring it back to 0)."""
    k = np.maximum(inductance * frequency / res, MIN_CYCLE_TAU)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        fall_on = -np.expm1(-d / k)
        rise = (volts - e) * fall_on
        x = k * np.log1p(rise / (volts + e))
    return k, fall_on, rise, x


def _mean_current(d: np.ndarray, e: np.ndarray, volts: Any, res: Any, brake: Any, x: np.ndarray) -> np.ndarray:
    """The mean current for |d| against e: the linear average braking; coasting, by regime."""
    linear = (d * volts - e) / res
    continuous = ((2.0 * d - 1.0) * volts - e) / res
    with np.errstate(invalid="ignore"):
        broken = (d * volts - volts * x - e * (d + x)) / res
    coast = np.where(e >= volts, (volts - e) / res,
                     np.where((e > -volts) & (x < 1.0 - d), broken, continuous))
    return np.where(brake, linear, coast)
