"""The drive with the library's effects switched on: N robots, numpy.

While every drive effect is absent BatchSim takes the nominal drive (drivetrain.py), unchanged; with any
present it takes this one, whose equations are the nominal ones generalised per wheel and with the supply,
the caster and the tyres' scrub (docs/effects.md, "Where the effects are computed").  The H-bridge drives
(docs/motors.md "Drives") and the bench (bench_step) take it too.  SimRobot, a view of a BatchSim of one,
comes here too, so both twins are the same code.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cached_property
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from host_sim.physics import effects, friction, motors

if TYPE_CHECKING:  # annotations only
    from host_sim.physics.dynamics import ParamBatch, Params, PerRobot

SMOOTHING_SPEED = 0.1  # rad/s at the wheel: the caster's drag is smoothed over it
SCRUB_SMOOTHING_SPEED = 0.01  # rad/s at the wheel: and the tyres' scrub over this, a near-Coulomb torque (stepped
# linearly implicitly: yaw_damping).  Smoothed over 0.1, a fitted twin of the reference plant's torsional friction
# stayed 5-6 fit points short of a perfect twin on the wheels; over 0.01 it matches it
CASTER_BEHIND = 0.045  # m: the caster sits on the body's axis this far behind C (3/4 of the body radius)
MIN_ROTOR_SHARE = 0.05  # the motor side's inertia is at least this share of wheel_inertia (backlash)
SUPPLY_NEWTON = 8  # Newton steps on the supply voltage (converged to 1e-12 V_bat once the limits in force are found)
HOLD_BISECTIONS = 30  # halvings of the duty's [-1, 1]: 2e-9 of full duty
# RobotParams fields that switch this path on when any robot has them away from 0: the library's (effects.py).
FIELDS = effects.fields_needing("drivetrain_effects")
# and these, which only a drive other than current reads (that drive takes this path anyway)
BRIDGE_FIELDS = ("drive", "armature_resistance_delta_l", "armature_resistance_delta_r")
STICTION_FIELDS = ("stiction_l", "stiction_r")  # breakaway friction: the build's, not a library effect
CURRENT, VOLTAGE, DUTY, WHEEL_SPEED = range(4)  # params.DRIVES, as RobotParams.drive holds them
SLOPE_STEP = 1e-4  # rad/s: the bridge current's slope in the wheel speed by a central difference over this


def active(p: Params) -> bool:
    """True if any drive effect is present or any drive is not current (p a RobotParams or a ParamBatch)."""
    return any(np.any(np.asarray(getattr(p, f)) != 0.0) for f in FIELDS + BRIDGE_FIELDS + STICTION_FIELDS)


def _pair(a: PerRobot, b: PerRobot) -> np.ndarray:
    return np.stack([np.asarray(a, dtype=float), np.asarray(b, dtype=float)], axis=-1)


@dataclass
class Drive:
    """Per-robot constants of the drive with effects: (N,) arrays, (N, 2) per wheel (left, right)."""

    radius: np.ndarray  # (N, 2) m
    kt: np.ndarray  # (N, 2) N m/A
    t_c: np.ndarray  # (N, 2) N m
    stiction: np.ndarray  # (N, 2) the breakaway friction beyond t_c, as a fraction of it
    w_s: np.ndarray  # (N, 1) rad/s, the Stribeck speed
    c_v: np.ndarray  # (N, 2) N m s/rad
    lim: np.ndarray  # (N, 1) A
    gear: np.ndarray  # (N, 1)
    eta: np.ndarray  # (N, 1)
    res: np.ndarray  # (N, 1) ohm, armature
    v_bat: np.ndarray  # (N,) V
    r_int: np.ndarray  # (N,) ohm
    i_e: np.ndarray  # (N,) A the electronics draw
    caster: np.ndarray  # (N,) N
    scrub: np.ndarray  # (N,) N m
    b: np.ndarray  # (N,) m
    g: np.ndarray  # (N,) m_c d
    iw: np.ndarray  # (N,)
    m: np.ndarray  # (N,) m_c + 2 m_w
    h: tuple[np.ndarray, np.ndarray, np.ndarray]  # H in (u, omega): A, B, C
    cap: np.ndarray  # (N,) mu N per wheel
    play: np.ndarray  # (N, 2) rad, half the backlash: the gear's gap is in [-play, play]
    j_b: np.ndarray  # (N,) kg m^2, the body's yaw inertia about C without the wheels' spin (H's C = j_b + ...)
    i_r: np.ndarray  # (N, 1) kg m^2, the motor side (rotor through the gear) at the wheel: backlash.py
    kind: np.ndarray  # (N, 1) the drive (CURRENT, VOLTAGE, DUTY, WHEEL_SPEED)
    brake: np.ndarray  # (N, 1) bool: the bridge's off-phase brakes (slow decay), else coasts
    deadband: np.ndarray  # (N, 1) fraction of full duty
    dead_time: np.ndarray  # (N, 1) s
    f_pwm: np.ndarray  # (N, 1) Hz
    ind: np.ndarray  # (N, 1) H
    res_w: np.ndarray  # (N, 2) ohm, each motor's armature (the bridge drives')

    @classmethod
    def of(cls, p: ParamBatch) -> Drive:
        """From a ParamBatch."""
        r = _pair(p.wheel_radius + p.wheel_radius_delta_l, p.wheel_radius + p.wheel_radius_delta_r)
        col = (lambda a: np.asarray(a, dtype=float)[:, None])
        b, iw = np.asarray(p.half_axle, dtype=float), np.asarray(p.wheel_inertia, dtype=float)
        m = p.body_mass + 2 * p.wheel_mass
        j_b = p.body_inertia + p.body_mass * p.com_offset ** 2 + 2 * p.wheel_mass * b * b + 2 * p.wheel_inertia_diam
        il2, ir2 = 1.0 / r[:, 0] ** 2, 1.0 / r[:, 1] ** 2
        h = (m + iw * (il2 + ir2), iw * b * (ir2 - il2), j_b + iw * b * b * (il2 + ir2))
        # the rotor's share of wheel_inertia: all of it but the wheel's own spin inertia (2 I_m, a thin
        # wheel's), at least MIN_ROTOR_SHARE of it (docs/effects.md, "backlash")
        i_r = np.maximum(iw - 2.0 * np.asarray(p.wheel_inertia_diam, dtype=float), MIN_ROTOR_SHARE * iw)
        return cls(radius=r,
                   kt=_pair(p.torque_constant + p.torque_constant_delta_l, p.torque_constant + p.torque_constant_delta_r),
                   t_c=_pair(p.coulomb_friction + p.coulomb_friction_delta_l,
                             p.coulomb_friction + p.coulomb_friction_delta_r),
                   stiction=_pair(p.stiction_l, p.stiction_r), w_s=col(p.stribeck_speed),
                   c_v=_pair(p.viscous_friction + p.viscous_friction_delta_l,
                             p.viscous_friction + p.viscous_friction_delta_r),
                   lim=col(p.current_limit), gear=col(p.gear_ratio), eta=col(p.gear_efficiency),
                   res=col(p.armature_resistance), v_bat=np.asarray(p.battery_voltage, dtype=float),
                   r_int=np.asarray(p.battery_resistance, dtype=float),
                   i_e=np.asarray(p.electronics_current, dtype=float), caster=np.asarray(p.caster_drag, dtype=float),
                   scrub=np.asarray(p.turning_resistance, dtype=float), b=b,
                   g=np.asarray(p.body_mass * p.com_offset, dtype=float), iw=iw, m=np.asarray(m, dtype=float),
                   h=(np.asarray(h[0]), np.asarray(h[1]), np.asarray(h[2])),
                   cap=np.asarray(p.wheel_friction * m * 9.81 / 2, dtype=float),
                   play=0.5 * _pair(p.backlash_l, p.backlash_r), j_b=np.asarray(j_b, dtype=float),
                   i_r=col(i_r), kind=col(p.drive).astype(np.int64), brake=col(p.pwm_decay) == 1.0,
                   deadband=col(p.driver_deadband), dead_time=col(p.dead_time), f_pwm=col(p.pwm_frequency),
                   ind=col(p.motor_inductance),
                   res_w=_pair(p.armature_resistance + p.armature_resistance_delta_l,
                               p.armature_resistance + p.armature_resistance_delta_r))

    def dry(self, w: np.ndarray) -> np.ndarray:
        """(N, 2) each axle's dry friction bound at wheel speeds w (N, 2) (the step's start): t_c (1 + stiction
        exp(-(w / w_s)^2)), the breakaway at rest falling to t_c in motion (Stribeck), held over the step
        (tests/test_friction.py::test_breakaway_friction_holds_a_wheel_coulomb_friction_lets_turn)."""
        if not self.sticky:
            return self.t_c
        return self.t_c * (1.0 + self.stiction * np.exp(-(w / self.w_s) ** 2))

    def sub(self, s: np.ndarray) -> Drive:
        """Robots s only."""
        parts = {f.name: getattr(self, f.name) for f in fields(self)}  # not the cached values below: a sub-batch takes its own
        return Drive(**{k: (tuple(x[s] for x in v) if isinstance(v, tuple) else v[s])  # type: ignore[arg-type]
                        for k, v in parts.items()})

    @cached_property
    def r_mean(self) -> np.ndarray:
        """(N,) m, the wheels' mean radius: the body forces' smoothing, taken once, not every step."""
        return self.radius.mean(1)

    # Whether any robot of the batch has each: asked at every step, the same for the batch's life, and a
    # sub-batch's its own (tests/test_effects_drive.py::test_a_sub_batch_asks_again_which_effects_its_own_robots_have)
    @cached_property
    def bridged(self) -> bool:
        return bool(np.any(self.kind))

    @cached_property
    def all_bridged(self) -> bool:
        return bool(np.all(self.kind))

    @cached_property
    def resistive(self) -> bool:
        return bool(np.any(self.r_int))

    @cached_property
    def dragged(self) -> bool:
        return bool(self.caster.any())

    @cached_property
    def scrubbed(self) -> bool:
        return bool(self.scrub.any())

    @cached_property
    def sticky(self) -> bool:
        return bool(self.stiction.any())


# --------------------------------------------------------------------------- #
# Motors and supply
# --------------------------------------------------------------------------- #
def _currents(c: np.ndarray, emf: np.ndarray, volts: np.ndarray, res: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(current (N, 2), the most V allows each way (hi, lo)): the driver's clipped reference c within them."""
    hi, lo = (volts[:, None] - emf) / res, (-volts[:, None] - emf) / res
    return np.minimum(np.maximum(c, lo), hi), hi, lo


def _current_slope(c: np.ndarray, hi: np.ndarray, lo: np.ndarray, res: np.ndarray) -> np.ndarray:
    """d current / d V (N, 2) of _currents: asked only by supply's Newton, for a battery with a resistance."""
    return np.where(c > hi, 1.0, np.where(c < lo, -1.0, 0.0)) / res


def supply(i_ref: ArrayLike, w: np.ndarray, d: Drive) -> tuple[np.ndarray, np.ndarray]:
    """(V (N,), currents (N, 2)): V = V_bat - R_int (i_e + sum(u i) / V), with the currents V allows.

    The drivers switch (PWM): each bridge passes the motor's power u i (u = R i + k_e N w, its
    terminal voltage) to the battery side, so the battery delivers i_e + sum(u i) / V, not
    i_e + |i_l| + |i_r| (the two agree only at full duty, u = V).  Newton on V from V_bat: the
    currents are piecewise linear in V, so it is exact once the limits in force are found."""
    if d.bridged:
        return _bridge_supply(np.asarray(i_ref, dtype=float), w, d)
    c = np.minimum(np.maximum(np.asarray(i_ref, dtype=float), -d.lim), d.lim)
    emf = d.kt * d.gear * w
    volts = d.v_bat.copy()
    i, hi, lo = _currents(c, emf, volts, d.res)
    if not d.resistive:
        return volts, i
    di = _current_slope(c, hi, lo, d.res)
    for _ in range(SUPPLY_NEWTON):
        u = d.res * i + emf
        power = (u * i).sum(1)
        gv = volts - d.v_bat + d.r_int * (d.i_e + power / volts)
        if not np.any(np.abs(gv) > 1e-12 * d.v_bat):  # the limits in force were found: exact
            break
        d_power = ((d.res * i + u) * di).sum(1)  # d(sum u i)/dV through the clipped currents
        slope = np.maximum(1.0 + d.r_int * (d_power / volts - power / volts ** 2), 0.5)
        volts = np.clip(volts - gv / slope, 0.05 * d.v_bat, d.v_bat)
        i, hi, lo = _currents(c, emf, volts, d.res)
        di = _current_slope(c, hi, lo, d.res)
    return volts, i


def _drive_currents(cmd: np.ndarray, w: np.ndarray, volts: np.ndarray, d: Drive) -> np.ndarray:
    """(N, 2) motor currents for commands cmd in each robot's drive's unit, the supply at volts (N,): the current
    drive's clipped reference, an H-bridge's cycle average for the others (motors.bridge_current)."""
    emf = d.kt * d.gear * w
    vb = volts[:, None]
    i = motors.bridge_current(_duty(cmd, vb, d), emf, vb, d.res_w, d.ind, d.f_pwm, d.brake)
    if d.all_bridged:
        return i
    return np.where(d.kind == CURRENT, _currents(np.clip(cmd, -d.lim, d.lim), emf, volts, d.res)[0], i)


def _drawn(cmd: np.ndarray, w: np.ndarray, volts: np.ndarray, d: Drive) -> tuple[np.ndarray, np.ndarray]:
    """(motor currents (N, 2), what each driver draws from the battery (N, 2)): a bridge's cycle averages
    (motors.bridge_currents, the ripple's draw included), a current driver's power (R i + e) i / V."""
    emf = d.kt * d.gear * w
    vb = volts[:, None]
    i, drawn = motors.bridge_currents(_duty(cmd, vb, d), emf, vb, d.res_w, d.ind, d.f_pwm, d.brake)
    if d.all_bridged:
        return i, drawn
    fed = _currents(np.clip(cmd, -d.lim, d.lim), emf, volts, d.res)[0]
    current = d.kind == CURRENT
    return np.where(current, fed, i), np.where(current, (d.res * fed + emf) * fed / vb, drawn)


def _duty(cmd: np.ndarray, vb: np.ndarray, d: Drive) -> np.ndarray:
    """(N, 2) the duty each bridge delivers for commands cmd at the supply vb (N, 1): a duty drive's command,
    the others' volts across the motor over the supply (motors.bridge_duty)."""
    return motors.bridge_duty(np.where(d.kind == DUTY, cmd, cmd / vb), d.deadband, d.dead_time, d.f_pwm)


def holding_volts(w: np.ndarray, d: Drive) -> np.ndarray:
    """(N, 2) the volts across each motor (a voltage command) whose bridge current holds its wheel at speed w
    against the dry and viscous friction, (T(w) sign(w) + c_v w) / (eta N k_t) (T: Drive.dry), with the
    bridge's own law (coast decay at light load is not the linear average): bisection on the duty, at the
    battery's open-circuit voltage.  Where a set-point robot's loop stands after holding w
    (BatchSim.hold_speeds)."""
    want = (d.dry(w) * np.sign(w) + d.c_v * w) / (d.eta * d.gear * d.kt)
    emf, vb = d.kt * d.gear * w, d.v_bat[:, None]
    lo, hi = -np.ones_like(w), np.ones_like(w)
    for _ in range(HOLD_BISECTIONS):
        mid = 0.5 * (lo + hi)
        i = motors.bridge_current(motors.bridge_duty(mid, d.deadband, d.dead_time, d.f_pwm), emf, vb, d.res_w,
                                  d.ind, d.f_pwm, d.brake)
        lo, hi = np.where(i < want, mid, lo), np.where(i < want, hi, mid)
    return 0.5 * (lo + hi) * vb


def _bridge_supply(cmd: np.ndarray, w: np.ndarray, d: Drive) -> tuple[np.ndarray, np.ndarray]:
    """supply() where some drive is not current: the battery delivers i_e plus what each driver draws
    (_drawn); Newton on V from V_bat, the slope by a difference."""
    cmd = np.broadcast_to(cmd, w.shape)
    volts = d.v_bat.copy()
    if not d.resistive:
        return volts, _drive_currents(cmd, w, volts, d)

    def residual(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i, drawn = _drawn(cmd, w, v, d)
        return v - d.v_bat + d.r_int * (d.i_e + drawn.sum(1)), i

    gv, i = residual(volts)
    for _ in range(2 * SUPPLY_NEWTON):
        if not np.any(np.abs(gv) > 1e-12 * d.v_bat):
            break
        step = 1e-6 * d.v_bat
        slope = (residual(volts + step)[0] - gv) / step
        volts = np.clip(volts - gv / np.maximum(slope, 0.5), 0.05 * d.v_bat, d.v_bat)
        gv, i = residual(volts)
    return volts, i


def wheel_torque(i_ref: ArrayLike, w: np.ndarray, d: Drive) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(torque on each wheel (N, 2), current (N, 2), supply V (N,)): motors.wheel_torque per wheel (the motor
    less the viscous friction; the dry friction is the step's)."""
    volts, i = supply(i_ref, w, d)
    tau = d.eta * d.gear * d.kt * i - d.c_v * w
    return tau, i, volts


def wheel_torque_slope(i_ref: ArrayLike, w: np.ndarray, d: Drive
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(torque, current, d torque / d w at fixed V) per wheel (N, 2), motors.wheel_torque_slope's, and
    the supply V (N,)."""
    volts, i = supply(i_ref, w, d)
    if d.bridged:  # the bridge's current: its slope by a central difference at this V
        cmd = np.broadcast_to(np.asarray(i_ref, dtype=float), w.shape)
        di = (_drive_currents(cmd, w + SLOPE_STEP, volts, d) - _drive_currents(cmd, w - SLOPE_STEP, volts, d))
        n_kt = d.kt * d.gear
        return (d.eta * n_kt * i - d.c_v * w, i, -d.c_v + d.eta * n_kt * di / (2.0 * SLOPE_STEP), volts)
    c = np.minimum(np.maximum(np.asarray(i_ref, dtype=float), -d.lim), d.lim)
    n_kt = d.kt * d.gear
    limited = c != i
    tau = d.eta * n_kt * i - d.c_v * w
    slope = -d.c_v - np.where(limited, d.eta * n_kt * n_kt / d.res, 0.0)
    return tau, i, slope, volts


# --------------------------------------------------------------------------- #
# Body forces and the reduced dynamics in (u, omega)
# --------------------------------------------------------------------------- #
def body_forces(u: np.ndarray, lat: np.ndarray, om: np.ndarray, d: Drive) -> tuple[np.ndarray, ...]:
    """(F_e, F_n, M_C): caster drag and scrub torque on the body, along e, n and about C.

    The caster at C - a e moves at (u, l - a omega); its drag opposes that, smoothed like the axles'
    Coulomb friction (eps_v = r w_eps at the rim), the scrub torque opposes omega (eps_w, _scrub_eps)."""
    ve, vn = u, lat - CASTER_BEHIND * om
    if d.dragged:
        speed = np.hypot(ve, vn)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = np.where(speed > 0.0, d.caster * np.tanh(speed / (d.r_mean * SMOOTHING_SPEED)) / speed, 0.0)
    else:  # no caster drag in the batch: k is +0 for every robot, and -k its -0, the same figures for less
        # (tests/test_effects_drive.py::test_a_sub_batch_asks_again_which_effects_its_own_robots_have)
        k = np.zeros_like(ve)
    f_e, f_n = -k * ve, -k * vn
    # without a scrub, 0 * om: tanh keeps om's sign, so the same zeros, signs and all
    turn = np.tanh(om / _scrub_eps(d)) if d.scrubbed else om
    m_c = -CASTER_BEHIND * f_n - d.scrub * turn  # (-a e) x (F_n n) = -a F_n
    return f_e, f_n, m_c


def _scrub_eps(d: Drive) -> np.ndarray:
    """eps_w = r w_eps / b: the yaw rate over which the scrub torque is smoothed (its rim speed r w_eps)."""
    return d.r_mean * SCRUB_SMOOTHING_SPEED / d.b


def yaw_damping(om: np.ndarray, d: Drive) -> np.ndarray | float:
    """-dM_C/d omega of the scrub (N m s/rad, >= 0): the steps take it linearly implicitly, so that a torque
    this sharp (dt T_s / eps_w up to ten times the body's yaw inertia, at 5 ms and T_s's bound) holds a yaw
    rate near 0 rather than overshooting it at every step.  0.0 when no robot has a scrub: no work on the step."""
    if not d.scrubbed:
        return 0.0
    eps = _scrub_eps(d)
    t = np.tanh(om / eps)
    return d.scrub * (1.0 - t * t) / eps


def _uw(v: np.ndarray, d: Drive) -> tuple[np.ndarray, np.ndarray]:
    rl, rr = d.radius[:, 0] * v[:, 0], d.radius[:, 1] * v[:, 1]
    return 0.5 * (rl + rr), 0.5 * (rr - rl) / d.b


def _gen_forces(tau: np.ndarray, u: np.ndarray, om: np.ndarray, d: Drive) -> tuple[np.ndarray, np.ndarray]:
    """The generalised forces on (u, omega): wheel torques through the radii, plus the body forces."""
    fl, fr = tau[:, 0] / d.radius[:, 0], tau[:, 1] / d.radius[:, 1]
    f_e, _f_n, m_c = body_forces(u, 0.0 * u, om, d)
    return fl + fr + f_e, d.b * (fr - fl) + m_c


def _solve_x(v: np.ndarray, tau: np.ndarray, d: Drive, h: tuple[np.ndarray, ...] | None = None
             ) -> tuple[np.ndarray, ...]:
    """(u, omega, and H^-1 (f + gyroscopic terms) in (u, omega)) at wheel speeds v under wheel torques tau."""
    u, om = _uw(v, d)
    fu, fw = _gen_forces(tau, u, om, d)
    fu, fw = fu + d.g * om * om, fw - d.g * u * om
    a, bb, c = d.h if h is None else h
    det = a * c - bb * bb
    return u, om, (c * fu - bb * fw) / det, (a * fw - bb * fu) / det


def _wheels(x_u: PerRobot, x_w: PerRobot, d: Drive) -> tuple[Any, Any]:
    """Wheel speeds (left, right) of a motion (u, omega): (u -+ b omega) / r_i."""
    return (x_u - d.b * x_w) / d.radius[:, 0], (x_u + d.b * x_w) / d.radius[:, 1]


def _response(i11: PerRobot, i12: PerRobot, i21: PerRobot, i22: PerRobot, d: Drive
              ) -> tuple[Any, Any, Any, Any]:
    """W (w11, w12, w21, w22): the wheel speeds' response to wheel torques through the inverse (i..) of a
    system matrix in (u, omega): a torque f_i gives the generalised forces (f_i / r_i)(1, -+ b)."""
    el, er = 1.0 / d.radius[:, 0], 1.0 / d.radius[:, 1]
    w11, w21 = _wheels(el * (i11 - d.b * i12), el * (i21 - d.b * i22), d)
    w12, w22 = _wheels(er * (i11 + d.b * i12), er * (i21 + d.b * i22), d)
    return w11, w12, w21, w22


def accel(v: np.ndarray, tau: np.ndarray, d: Drive) -> np.ndarray:
    """v' (N, 2): H (u', omega') = f + (g omega^2, -g u omega), then the wheels' (u' -+ b omega') / r_i."""
    _u, _om, ud, wd = _solve_x(v, tau, d)
    return np.stack(_wheels(ud, wd, d), 1)


def inertia(d: Drive, iw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H in (u, omega), (A, B, C), with each wheel's own spin inertia iw (N, 2) (Drive.h has d.iw for both)."""
    kl, kr = iw[:, 0] / d.radius[:, 0] ** 2, iw[:, 1] / d.radius[:, 1] ** 2
    return d.m + kl + kr, d.b * (kr - kl), d.j_b + d.b * d.b * (kl + kr)


def drive_step(q: np.ndarray, v: np.ndarray, i_ref: ArrayLike, dt: PerRobot, d: Drive, dc: PerRobot, torque: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
               h: tuple[np.ndarray, ...] | None = None, t_c: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """drive.drive_step_batch with the effects: (q_next, v_next, wheel torques (dry friction included),
    currents, supply V).  The same predictor with the half step's dry friction, then the linearly implicit
    midpoint step in (u, omega) and the step's dry friction (friction.solve_batch).

    torque(w) -> (wheel torques, currents, V) at wheel speeds w (default wheel_torque), h the inertia in
    (u, omega) (default d.h) and t_c (N, 2) the dry friction on the wheels (default d.dry(v)): the backlash's
    open gear (backlash.py) drives a wheel with none of them."""
    torque = torque or (lambda w: wheel_torque(i_ref, w, d))
    a, bb, c = d.h if h is None else h
    t_c = d.dry(v) if t_c is None else t_c
    hdt = 0.5 * dt if np.ndim(dt) == 0 else 0.5 * np.asarray(dt)
    tau, _i, _v = torque(v)
    # the scrub's damping, linearly implicit: each (half) step's yaw inertia c grows by its step times it
    damp = yaw_damping(_uw(v, d)[1], d)
    ch = c + hdt * damp
    u, om, ud, wd = _solve_x(v, tau, d, (a, bb, ch))
    det = a * ch - bb * bb
    hr = _response(hdt * ch / det, -hdt * bb / det, -hdt * bb / det, hdt * a / det, d)
    vl, vr = v[:, 0] + hdt * (ud - d.b * wd) / d.radius[:, 0], v[:, 1] + hdt * (ud + d.b * wd) / d.radius[:, 1]
    fl, fr, sl, sr = friction.solve_batch(vl, vr, *hr, t_c[:, 0], t_c[:, 1], v)
    v_mid = np.stack(friction.end_speeds_batch(vl, vr, *hr, fl, fr, sl, sr), 1)
    tau, cur, volts = torque(v_mid)
    # the step without dry friction; its gyroscopic coefficient from the yaw rate the predictor reached
    fu, fw = _gen_forces(tau, u, om, d)
    fh_u, fh_w = fl / d.radius[:, 0] + fr / d.radius[:, 1], d.b * (fr / d.radius[:, 1] - fl / d.radius[:, 0])
    wd = (a * (fw + fh_w - d.g * u * om) - bb * (fu + fh_u + d.g * om * om)) / det
    al = hdt * d.g * (om + hdt * wd)
    cs = c + dt * damp
    r1 = a * u + (bb + al) * om + dt * fu
    r2 = (bb - al) * u + cs * om + dt * fw
    idet = 1.0 / (a * cs - bb * bb + al * al)
    u1, w1 = (cs * r1 - (bb - al) * r2) * idet, (a * r2 - (bb + al) * r1) * idet
    vl, vr = _wheels(u1, w1, d)
    k = dt * idet  # the inverse of [[a, bb - al], [bb + al, cs]], times dt
    w = _response(k * cs, -k * (bb - al), -k * (bb + al), k * a, d)
    fl, fr, sl, sr = friction.solve_batch(vl, vr, *w, t_c[:, 0], t_c[:, 1], v)
    v1 = np.stack(friction.end_speeds_batch(vl, vr, *w, fl, fr, sl, sr), 1)
    q1 = _advance(q, v, v1, u, om, dt, d, dc)
    return q1, v1, tau + np.stack([fl, fr], 1), cur, volts


def _advance(q: np.ndarray, v: np.ndarray, v1: np.ndarray, u: np.ndarray, om: np.ndarray, dt: Any, d: Drive,
             dc: PerRobot) -> np.ndarray:
    """q_next from the end speeds v1: the pose at the mean velocities (dynamics.step_batch)."""
    hdt = 0.5 * dt
    u1, w1 = _uw(v1, d)
    sb, wb = hdt * (u + u1), 0.5 * (om + w1)
    ph = q[:, 2] + hdt * wb
    cs, sn = np.cos(ph), np.sin(ph)
    dwb = dt * dc * wb
    qn = np.empty_like(q)
    qn[:, 0] = q[:, 0] + (sb * cs - dwb * sn)
    qn[:, 1] = q[:, 1] + (sb * sn + dwb * cs)
    qn[:, 2] = q[:, 2] + dt * wb
    qn[:, 3:5] = q[:, 3:5] + (hdt if np.ndim(dt) == 0 else hdt[:, None]) * (v + v1)
    return qn


def traction_ok(v0: np.ndarray, v1: np.ndarray, tau: np.ndarray, dt: PerRobot, d: Drive, iw: np.ndarray | None = None) -> np.ndarray:
    """contact.traction_ok_batch with per-wheel radii; the caster carries its own sideways force.  tau: the
    torques on the wheels as iw (default d.iw, both) turn with them (backlash.py: the gear's, on the wheel's own)."""
    iw = d.iw[:, None] if iw is None else iw
    f = (tau - iw * (v1 - v0) / (dt if np.ndim(dt) == 0 else np.asarray(dt)[:, None])) / d.radius
    u0, w0 = _uw(v0, d)
    u1, w1 = _uw(v1, d)
    ub, wb = 0.5 * (u0 + u1), 0.5 * (w0 + w1)
    _fe, f_cn, _m = body_forces(ub, 0.0 * ub, wb, d)
    f_n = d.m * ub * wb + d.g * (w1 - w0) / dt - f_cn
    cap2 = d.cap * d.cap
    with np.errstate(invalid="ignore"):
        room = np.sqrt(cap2 - f[:, 0] ** 2) + np.sqrt(cap2 - f[:, 1] ** 2)
    return (np.abs(f[:, 0]) <= d.cap) & (np.abs(f[:, 1]) <= d.cap) & (np.abs(f_n) <= room)


def body_velocity(v: np.ndarray, d: Drive) -> np.ndarray:
    """(N, 3) (u, l, omega) of rolling robots."""
    u, om = _uw(v, d)
    return np.stack([u, 0.0 * u, om], 1)


def ticks_per_rev(p: Params) -> np.ndarray:
    """(N, 2) encoder counts per wheel turn, each wheel's own."""
    return _pair(p.ticks_per_rev + p.ticks_per_rev_delta_l, p.ticks_per_rev + p.ticks_per_rev_delta_r)


def delayed_reference(hist_t: list[float], hist_i: list[np.ndarray], t: float, dt: float,
                      delay: np.ndarray) -> np.ndarray:
    """(N, 2): the mean over [t, t + dt] of the commands as they reach the drivers `delay` (N,) late.

    hist_t / hist_i: issue times (ascending) and commands (N, 2); before the first, no current."""
    a, b = t - delay, t + dt - delay
    out = np.zeros(hist_i[0].shape) if hist_i else np.zeros((len(delay), 2))
    for k, (tk, ik) in enumerate(zip(hist_t, hist_i)):
        end = hist_t[k + 1] if k + 1 < len(hist_t) else np.inf
        w = np.clip(np.minimum(end, b) - np.maximum(tk, a), 0.0, None) / dt
        out += w[:, None] * ik
    return out


def bench_step(q: np.ndarray, v: np.ndarray, i_ref: ArrayLike, dt: PerRobot, d: Drive
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One step on a stand (a bench recording: wheels off the floor, the body held): each wheel spins alone with
    its own inertia, its motor and its axle's friction, the pose stays.  (q_next, v_next, currents, supply V):
    drive_step's midpoint with the half step's dry friction, each wheel's response dt / I_w."""
    hdt = np.broadcast_to(0.5 * np.asarray(dt, dtype=float), d.iw.shape)  # (N,): a float or each robot's own
    inv = 1.0 / d.iw
    zero = np.zeros(len(d.iw))
    tau, _i, _v = wheel_torque(i_ref, v, d)
    h = hdt * inv  # (N,): each wheel's response to its torque over the half step
    free = v + h[:, None] * tau
    t_c = d.dry(v)
    fl, fr, sl, sr = friction.solve_batch(free[:, 0], free[:, 1], h, zero, zero, h, t_c[:, 0], t_c[:, 1], v)
    v_mid = np.stack(friction.end_speeds_batch(free[:, 0], free[:, 1], h, zero, zero, h, fl, fr, sl, sr), 1)
    tau, cur, volts = wheel_torque(i_ref, v_mid, d)
    k = 2.0 * hdt * inv
    free = v + k[:, None] * tau
    fl, fr, sl, sr = friction.solve_batch(free[:, 0], free[:, 1], k, zero, zero, k, t_c[:, 0], t_c[:, 1], v)
    v1 = np.stack(friction.end_speeds_batch(free[:, 0], free[:, 1], k, zero, zero, k, fl, fr, sl, sr), 1)
    q1 = q.copy()
    q1[:, 3:5] = q[:, 3:5] + hdt[:, None] * (v + v1)
    return q1, v1, cur, volts
