"""Contact: wheels on the floor that may slip, and the body's rim against walls.

While the wheels roll and no wall pushes, the robot is the reduced model (`traction_ok` checks the
ground forces fit the wheels' friction cones); otherwise `slip_step` takes the unconstrained planar
robot with wheel and wall impulses solved by projected Gauss-Seidel (time-stepping).  The scalar and
batch versions sit side by side (tests/test_contact.py checks them).  Model: docs/contact.md.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from host_sim.physics.params import RobotParams, cached_per_params

if TYPE_CHECKING:  # annotations only: no import at run time
    from host_sim.physics.dynamics import Params, PerRobot, Vec
    from host_sim.physics.world import World

GRAVITY = 9.81  # m/s^2
PGS_TOL = 1e-10  # m/s: a sweep that moves no velocity by more than this ends the solve
PGS_MAX_ITER = 100  # sweeps; past it (redundant contacts at a standstill, both wheels sliding on ice) the next
# step goes on from here
COMPACT_BELOW = 0.5  # share of a batch's robots still unsettled under which the sweeps go on with those alone
ALONE_FROM = 16  # at or under this many unsettled robots in a batch, each is swept to the end alone, in Python floats
STICK_MARGIN = 1e-9  # a wheel impulse this far inside its cone (relative) is sticking
NEWTON_STEPS = 6  # on a wheel's friction disc: the force within 1e-13 rad of opposite the slip
CONTACT_HYSTERESIS = 0.002  # m: a contact ends when the rim is this far from every wall
REACH_MARGIN = 2e-3  # m: a wall closer than the step's travel + this is a contact candidate


@cached_per_params
def consts(p: Params) -> tuple[Any, ...]:
    """(m, k = m_c d, J_C, D = m J_C - k^2, I_w, r, b, d, R, mu N, mu_wall, m g): RobotParams or ParamBatch."""
    m = p.body_mass + 2 * p.wheel_mass
    k = p.body_mass * p.com_offset
    j = (p.body_inertia + p.body_mass * p.com_offset ** 2 + 2 * p.wheel_mass * p.half_axle ** 2
         + 2 * p.wheel_inertia_diam)
    c: tuple[Any, ...] = (m, k, j, m * j - k * k, p.wheel_inertia, p.wheel_radius, p.half_axle, p.com_offset, p.body_radius,
         p.wheel_friction * m * GRAVITY / 2, p.wall_friction, m * GRAVITY)
    if isinstance(p, RobotParams):
        c = tuple(float(x) for x in c)
    return c


# --------------------------------------------------------------------------- #
# Rolling: do the wheels hold?
# --------------------------------------------------------------------------- #
def traction_ok(v0: Vec, v1: Vec, tau: Vec, dt: float, p: RobotParams) -> bool:
    """True if the rolling step v0 -> v1 under wheel torques tau needed ground forces inside the cones."""
    m, k, _j, _dd, iw, r, b, _d, _rr, cap, _mw, _mg = consts(p)
    f_l = (tau[0] - iw * (v1[0] - v0[0]) / dt) / r
    f_r = (tau[1] - iw * (v1[1] - v0[1]) / dt) / r
    if abs(f_l) > cap or abs(f_r) > cap:
        return False
    kw = 0.5 * r / b
    w0, w1 = kw * (v0[1] - v0[0]), kw * (v1[1] - v1[0])
    u_bar = 0.25 * r * (v0[0] + v0[1] + v1[0] + v1[1])
    f_n = m * u_bar * 0.5 * (w0 + w1) + k * (w1 - w0) / dt  # m (l' + u omega) + k omega', l = 0
    return abs(f_n) <= math.sqrt(cap * cap - f_l * f_l) + math.sqrt(cap * cap - f_r * f_r)


def traction_ok_batch(v0: np.ndarray, v1: np.ndarray, tau: np.ndarray, dt: PerRobot, p: Params) -> np.ndarray:
    """traction_ok for N robots: v0, v1, tau (N, 2) -> (N,) bool."""
    m, k, _j, _dd, iw, r, b, _d, _rr, cap, _mw, _mg = consts(p)
    f_l = (tau[:, 0] - iw * (v1[:, 0] - v0[:, 0]) / dt) / r
    f_r = (tau[:, 1] - iw * (v1[:, 1] - v0[:, 1]) / dt) / r
    kw = 0.5 * r / b
    w0, w1 = kw * (v0[:, 1] - v0[:, 0]), kw * (v1[:, 1] - v1[:, 0])
    u_bar = 0.25 * r * (v0[:, 0] + v0[:, 1] + v1[:, 0] + v1[:, 1])
    f_n = m * u_bar * 0.5 * (w0 + w1) + k * (w1 - w0) / dt
    cap2 = cap * cap
    with np.errstate(invalid="ignore"):
        room = np.sqrt(cap2 - f_l * f_l) + np.sqrt(cap2 - f_r * f_r)
    return (np.abs(f_l) <= cap) & (np.abs(f_r) <= cap) & (np.abs(f_n) <= room)


# --------------------------------------------------------------------------- #
# Which walls a step can reach
# --------------------------------------------------------------------------- #
def walls_in_reach(world: World, cx: float, cy: float, radius: float, within: float
                   ) -> tuple[list[tuple[float, float, float, int]], float]:
    """([(gap, nx, ny, wall index), ...] in wall order for the walls with gap < within, smallest gap
    (inf: none).

    gap = distance from C to the wall minus the body radius (negative: overlapping)."""
    if world.n_walls == 0:
        return [], math.inf
    dist, normal = world.wall_distances(np.array([[cx, cy]]))
    gaps = dist[0] - radius
    near = np.flatnonzero(gaps < within)
    return ([(float(gaps[i]), float(normal[0, i, 0]), float(normal[0, i, 1]), int(i)) for i in near],
            float(gaps.min()))


def walls_in_reach_batch(world: World, centres: np.ndarray, radius: PerRobot, within: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For K robots: gaps (K, W), normals (K, W, 2), wall indices (K, W) of the walls in reach, padded
    with gap = inf, and the smallest gap (K,).  W is the most walls any of them has in reach; walls
    keep their order."""
    dist, normal = world.wall_distances(centres)
    gaps = dist - np.reshape(radius, (-1, 1))
    near = gaps < np.reshape(within, (-1, 1))
    width = int(near.sum(1).max()) if near.size else 0
    order = np.argsort(~near, axis=1, kind="stable")[:, :width]  # the walls in reach first, in wall order
    rows = np.arange(len(centres))[:, None]
    g = np.where(near[rows, order], gaps[rows, order], np.inf)
    return g, normal[rows, order], order, gaps.min(1) if gaps.shape[1] else np.full(len(centres), np.inf)


# --------------------------------------------------------------------------- #
# The slipping / contact step
# --------------------------------------------------------------------------- #
def body_velocity(v: Vec, p: Params) -> tuple[Any, Any, Any]:
    """(u, l, omega) of a rolling robot from its wheel speeds (l = 0)."""
    r, b = p.wheel_radius, p.half_axle
    return 0.5 * r * (v[0] + v[1]), 0.0 * v[0], 0.5 * r * (v[1] - v[0]) / b


def _free_body(u: PerRobot, l: PerRobot, om: PerRobot, dt: PerRobot, m: PerRobot, k: PerRobot, j: PerRobot
               ) -> tuple[Any, Any, Any]:
    """The body's free motion over dt: (M - a G) nu1 = (M + a G) nu0, a = dt/2 omega (implicit midpoint
    on the gyroscopic terms, which do no work), solved by Cramer's rule.  Floats or arrays."""
    a = 0.5 * dt * om
    am, ak = a * m, a * k
    r1 = m * u + am * l + ak * om
    r2 = m * l + k * om - am * u
    r3 = k * l + j * om - ak * u
    det = m * (m * j - k * k) + am * (am * j - k * ak) - ak * (am * k - m * ak)
    return ((r1 * (m * j - k * k) + am * (r2 * j - k * r3) - ak * (r2 * k - m * r3)) / det,
            (m * (r2 * j - k * r3) - r1 * (am * j - k * ak) - ak * (am * r3 - ak * r2)) / det,
            (m * (m * r3 - k * r2) + am * (am * r3 - ak * r2) + r1 * (am * k - m * ak)) / det)


def _wheel_blocks(iwl: Any, iwr: Any, m: Any, k: Any, j: Any, radii: tuple[Any, Any], b: Any) -> list[tuple[Any, ...]]:
    """Per wheel (left, right): (s b, the heading row's M^-1 J^T on l and omega, on the wheel, and the
    inverse of the 2x2 block [heading, sideways] of J M^-1 J^T as a11, a12, a22, then W's entries and
    the wheel's radius).  iw*: the wheels' inertias in this step; radii: each wheel's.  Floats or arrays."""
    ju, jd = 1.0 / m, 1.0 / (m * j - k * k)
    blocks = []
    for side, iwi, r in ((1.0, iwl, radii[0]), (-1.0, iwr, radii[1])):
        sb = side * b
        wee = ju + m * b * b * jd + r * r / iwi
        wen = sb * k * jd
        wnn = j * jd
        idet = 1.0 / (wee * wnn - wen * wen)
        blocks.append((sb, k * sb * jd, -m * sb * jd, -r / iwi, wnn * idet, -wen * idet, wee * idet, wee, wen, wnn,
                       _eigen(wee, wen, wnn), r))
    return blocks


def _on_disc(be: Any, bn: Any, lim: PerRobot, eig: tuple[Any, Any, Any, Any]) -> tuple[Any, Any]:
    """The impulse on the disc |P| = lim minimising 1/2 P^T W P + P^T b (b = (be, bn)), when the
    unconstrained minimum lies outside it: P(lam) = -(W + lam I)^-1 b with |P(lam)| = lim, so that
    the slip velocity W P + b = -lam P is opposite to the friction (Coulomb's maximal dissipation).
    In W's eigenbasis (eig = cos, sin of its first eigenvector, eigenvalues mu1 >= mu2), Newton on
    1/|P(lam)| - 1/lim, which converges monotonically from below (More and Sorensen), from the
    lower bound |b| / lim - mu1; a fixed number of steps, then scaled onto the disc.  Floats or arrays."""
    if not isinstance(lim, np.ndarray) and lim <= 0.0:  # mu = 0: the disc is the point 0, no grip
        # (tests/test_contact.py::test_zero_wheel_friction_slides_freely_with_shared_parameters_and_with_drive_effects)
        return be * 0.0, bn * 0.0
    c, s, mu1, mu2 = eig
    # square roots, not powers: numpy's x ** -0.5 is its own (SIMD) power, which differs from libm's in the
    # last bit; a square root is exactly rounded everywhere, so a robot's figures are the same alone or in a batch
    sqrt = np.sqrt if isinstance(be, np.ndarray) else math.sqrt
    b1, b2 = c * be + s * bn, c * bn - s * be
    lam = sqrt(b1 * b1 + b2 * b2) / lim - mu1
    lam = lam * (lam > 0)
    for _ in range(NEWTON_STEPS):
        i1, i2 = 1.0 / (mu1 + lam), 1.0 / (mu2 + lam)
        q1, q2 = b1 * i1, b2 * i2
        size2 = q1 * q1 + q2 * q2
        # phi = size2^-1/2 - 1/lim, phi' = size2^-3/2 (q1^2 i1 + q2^2 i2)
        inv = 1.0 / sqrt(size2)
        lam = lam - (inv - 1.0 / lim) / (inv * inv * inv * (q1 * q1 * i1 + q2 * q2 * i2))
    q1, q2 = -b1 / (mu1 + lam), -b2 / (mu2 + lam)
    scale = lim / sqrt(q1 * q1 + q2 * q2)
    return (c * q1 - s * q2) * scale, (s * q1 + c * q2) * scale


def _eigen(wee: Any, wen: Any, wnn: Any) -> tuple[Any, Any, Any, Any]:
    """(cos, sin of the first eigenvector, eigenvalues mu1 >= mu2) of the symmetric [[wee, wen], [wen, wnn]]."""
    half = 0.5 * (wee - wnn)
    rad = (half * half + wen * wen) ** 0.5
    if isinstance(half, np.ndarray):
        theta = 0.5 * np.arctan2(wen, half)
        c, s = np.cos(theta), np.sin(theta)
    else:  # Python floats stay Python floats (numpy scalars are ten times slower)
        theta = 0.5 * math.atan2(wen, half)
        c, s = math.cos(theta), math.sin(theta)
    return c, s, 0.5 * (wee + wnn) + rad, 0.5 * (wee + wnn) - rad


def _wall_block(ne: PerRobot, nn: PerRobot, m: PerRobot, k: PerRobot, j: PerRobot, rad: PerRobot) -> tuple[Any, ...]:
    """A wall with normal (ne, nn) in the body frame: M^-1 J^T of its normal row on l, omega (nl, nw),
    of its tangent row (tl, tw), and the rows' inverse masses.  Floats or arrays."""
    ju, jd = 1.0 / m, 1.0 / (m * j - k * k)
    return (j * nn * jd, -k * nn * jd, (j * ne + k * rad) * jd, (-k * ne - m * rad) * jd,
            1.0 / (ne * ne * ju + j * nn * nn * jd),
            1.0 / (nn * nn * ju + (j * ne * ne + 2 * k * rad * ne + m * rad * rad) * jd))


def slip_step(q: Vec, v: Vec, body: tuple[float, float, float] | None, tau: Any, slope: Any, dt: float,
              p: RobotParams, walls: list[tuple[float, float, float, int]],
              warm: tuple[list[list[float]], list[list[float]]] | None = None, axle_friction: Any = None
              ) -> tuple[tuple[float, ...], tuple[float, float], tuple[float, float, float] | None, bool,
                         tuple[list[list[float]], list[list[float]]]]:
    """One step of the unconstrained robot with wheel friction and wall contacts.

    q, v: as dynamics; body: (u, l, omega) if slipping, None if rolling (then from v).
    tau, slope: wheel torques (N m, the motor less the viscous friction) and d tau / d w (N m s, <= 0) at v;
    axle_friction: (T_l, T_r) the axles' dry friction (default coulomb_friction).  walls: (gap, nx, ny, index)
    as walls_in_reach.  warm: the contact forces of the previous step (wheels [[F_e, F_n]] x 2,
    walls [[F_n, F_t]] in the order of `walls`; a wheel's entry may carry its axle's friction torque
    third, as the returned forces do), where the solve starts (warm start: in steady
    contact a few sweeps instead of a hundred; the solution is the same).  Returns (q, v, body or
    None if both wheels stick, a wall pushed, the contact forces for the next warm start).
    """
    m, k, j, _dd, iw, r, b, d, rad, cap, _mu_w, mg = consts(p)
    c, s = math.cos(q[2]), math.sin(q[2])
    u, l, om = body if body is not None else body_velocity(v, p)
    u, l, om = _free_body(u, l, om, dt, m, k, j)
    # Wheels: I_w (w1 - w0) = dt (tau + slope (w1 - w0)) + impulse, linearly implicit.
    iwl, iwr = iw - dt * slope[0], iw - dt * slope[1]
    nu = [u, l, om, v[0] + dt * tau[0] / iwl, v[1] + dt * tau[1] / iwr]
    wheels = _wheel_blocks(iwl, iwr, m, k, j, (r, r), b)
    contacts = []
    for gap, nx, ny, _index in walls:
        ne, nn = nx * c + ny * s, -nx * s + ny * c
        contacts.append((gap / dt, ne, nn) + _wall_block(ne, nn, m, k, j, rad))
    pw = [[f[0] * dt, f[1] * dt] for f in warm[0]] if warm else [[0.0, 0.0], [0.0, 0.0]]
    pc = [[f[0] * dt, f[1] * dt] for f in warm[1]] if warm else [[0.0, 0.0] for _ in contacts]
    t_l, t_r = (p.coulomb_friction,) * 2 if axle_friction is None else axle_friction
    # the axles' friction torques are warm-started with the rest: without them a wheel pressed still against
    # a wall takes tens of sweeps to find again the torque that holds it
    held = [min(max(f[2] * dt, -t * dt), t * dt) if len(f) > 2 else 0.0 for f, t in zip(warm[0], (t_l, t_r))] \
        if warm else [0.0, 0.0]
    axles = [(1.0 / iwl, t_l * dt, [held[0]]), (1.0 / iwr, t_r * dt, [held[1]])]
    _solve(nu, wheels, contacts, pw, pc, p, dt, start=warm is not None, axles=axles)
    u, l, om, wl, wr = nu
    # Pose with the new velocities (C moves as its constraints saw it: heading phi_n).
    cx = q[0] - d * c + dt * (u * c - l * s)
    cy = q[1] - d * s + dt * (u * s + l * c)
    phi1 = q[2] + dt * om
    q1 = (cx + d * math.cos(phi1), cy + d * math.sin(phi1), phi1, q[3] + dt * wl, q[4] + dt * wr)
    stick = cap * dt * (1.0 - STICK_MARGIN)
    rolling = math.hypot(*pw[0]) < stick and math.hypot(*pw[1]) < stick
    pushed = any(pn > 0.0 for pn, _pt in pc)
    forces = ([[pe / dt, pn / dt, a[2][0] / dt] for (pe, pn), a in zip(pw, axles)],
              [[pn / dt, pt / dt] for pn, pt in pc])
    return q1, (wl, wr), None if rolling else (u, l, om), pushed, forces


def _apply(nu: list[float], w: tuple[Any, ...], pe: float, pn: float, wheel: int, ju: float,
           lat_l: float, lat_w: float) -> None:
    """nu += M^-1 J^T (pe, pn) for wheel block w."""
    _sb, el, ew, er = w[:4]
    nu[0] += ju * pe
    nu[1] += el * pe + lat_l * pn
    nu[2] += ew * pe + lat_w * pn
    nu[3 + wheel] += er * pe


def _solve(nu: list[float], wheels: list[tuple[Any, ...]], contacts: list[tuple[Any, ...]],
           pw: list[list[float]], pc: list[list[float]], p: RobotParams, dt: float, start: bool,
           axles: list[tuple[float, float, list[float]]]) -> None:
    """Projected Gauss-Seidel on the contact impulses pw (wheels), pc (walls), updating nu in place.

    start: pw, pc hold a warm start, whose velocity change is applied first.  axles: per wheel (1 / its
    inertia in the step, the dry friction's bound on its impulse T dt, [the impulse]): the axle's
    stick-slip friction on the wheel's spin (host_sim/physics/friction.py), a row of its own."""
    m, k, j, dd, _iw, r, _b, _d, rad, cap, mu_w, mg = consts(p)
    ju, lat_l, lat_w = 1.0 / m, j / dd, -k / dd  # M^-1 J^T of the sideways row (0, 1, 0)
    if start:
        for i, w in enumerate(wheels):
            _apply(nu, w, pw[i][0], pw[i][1], i, ju, lat_l, lat_w)
            nu[3 + i] += axles[i][2][0] * axles[i][0]
        for (_g, ne, nn, nl, nw, tl, tw, _inn, _itt), (pn, pt) in zip(contacts, pc):
            nu[0] += (ne * pn - nn * pt) * ju
            nu[1] += nl * pn + tl * pt
            nu[2] += nw * pn + tw * pt
    lim = cap * dt
    b = wheels[0][0]
    for _ in range(PGS_MAX_ITER):
        before = (nu[0], nu[1], nu[2], nu[3], nu[4])
        for i, w in enumerate(wheels):
            pe0, pn0 = pw[i]
            pe, pn = _wheel_impulse(nu, i, w, pe0, pn0, lim)
            pw[i] = [pe, pn]
            _apply(nu, w, pe - pe0, pn - pn0, i, ju, lat_l, lat_w)
            inv_iw, bound, held = axles[i]
            pa = held[0] - nu[3 + i] / inv_iw
            pa = bound if pa > bound else (-bound if pa < -bound else pa)
            nu[3 + i] += (pa - held[0]) * inv_iw
            held[0] = pa
        for i, (gdt, ne, nn, nl, nw, tl, tw, inn, itt) in enumerate(contacts):
            pn0, pt0 = pc[i]
            pn = max(pn0 - (ne * nu[0] + nn * nu[1] + gdt) * inn, 0.0)
            dn = pn - pn0
            nu[0] += ne * ju * dn
            nu[1] += nl * dn
            nu[2] += nw * dn
            bound = mu_w * pn
            pt = min(max(pt0 - (-nn * nu[0] + ne * nu[1] - rad * nu[2]) * itt, -bound), bound)
            dt_ = pt - pt0
            nu[0] -= nn * ju * dt_
            nu[1] += tl * dt_
            nu[2] += tw * dt_
            pc[i] = [pn, pt]
        # settled when no velocity (of C, of the rim and the wheels' contact points) moved by PGS_TOL
        if max(abs(nu[0] - before[0]), abs(nu[1] - before[1]), abs(b * (nu[2] - before[2])),
               abs(r * (nu[3] - before[3])), abs(r * (nu[4] - before[4]))) < PGS_TOL:
            break


def slip_step_batch(q: np.ndarray, v: np.ndarray, body: np.ndarray, tau: np.ndarray, slope: np.ndarray, dt: PerRobot,
                    p: Params, gaps: np.ndarray, normals: np.ndarray, idx: np.ndarray | None = None,
                    warm_wheels: np.ndarray | None = None, warm_walls: np.ndarray | None = None,
                    radii: np.ndarray | None = None, body_force: tuple[Any, Any, Any] | None = None,
                    axle_friction: np.ndarray | None = None, yaw_damping: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`slip_step` for K robots: q (K, 5), v (K, 2), body (K, 3) (u, l, omega; for rolling robots
    from v), tau, slope (K, 2), dt float or (K,), gaps (K, W) and normals (K, W, 2) as
    walls_in_reach_batch; p a RobotParams or a ParamBatch, of which robots idx are these K;
    warm_wheels (2, 3, K: F_e, F_n, the axle torque) and warm_walls (2, W, K): the previous step's forces, as slip_step's warm.
    radii (K, 2): each wheel's radius (default wheel_radius); body_force: (F_e, F_n, M_C) (K,) each, forces
    on the body other than the wheels' and the walls' (the caster's drag, the tyres' scrub; host_sim/
    drive_effects.py), taken at the start of the step.  axle_friction (K, 2): each axle's dry friction T
    (default coulomb_friction), as slip_step's.  yaw_damping (K,) or 0.0: -dM_C/d omega of the body forces,
    taken linearly implicitly on the free body's yaw (the tyres' scrub, drive_effects.yaw_damping).
    Returns (q, v, body, rolling (K,), pushed (K,), wheel forces (2, 2, K), wall forces (2, W, K))."""
    cs = consts(p)
    if idx is not None:
        cs = tuple(x[idx] if isinstance(x, np.ndarray) else x for x in cs)
    m, k, j, dd, iw, r, b, d, rad, cap, _mu_w, _mg = cs
    n, n_walls = len(q), gaps.shape[1]
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    u, l, om = _free_body(body[:, 0], body[:, 1], body[:, 2], dt, m, k, j)
    if body_force is not None:  # M^-1 F: the heading row alone, (l, omega) coupled through k
        fe, fn, mc = body_force
        if np.any(yaw_damping):
            # Linearly implicit: the step's change of omega is dt m/D (M_C + M_w - s d omega), M_w the wheels'
            # moment about C, taken from the warm start (F_e at +-b); so a steady slide balances M_C = -M_w.
            # Robot by robot: one without it keeps its M_C to the bit, alone or in a batch.
            m_w = 0.0 if warm_wheels is None else b * (warm_wheels[1, 0] - warm_wheels[0, 0])
            mc = np.where(yaw_damping > 0.0, (mc + m_w) / (1.0 + dt * yaw_damping * m / dd) - m_w, mc)
        u, l, om = u + dt * fe / m, l + dt * (j * fn - k * mc) / dd, om + dt * (m * mc - k * fn) / dd
    iwl, iwr = iw - dt * slope[:, 0], iw - dt * slope[:, 1]
    nu = [u, l, om, v[:, 0] + dt * tau[:, 0] / iwl, v[:, 1] + dt * tau[:, 1] / iwr]
    wheels = _wheel_blocks(iwl, iwr, m, k, j, (r, r) if radii is None else (radii[:, 0], radii[:, 1]), b)
    ne = (normals[..., 0] * c[:, None] + normals[..., 1] * s[:, None]).T  # (W, K)
    nn = (-normals[..., 0] * s[:, None] + normals[..., 1] * c[:, None]).T
    contacts = [(gaps[:, w] / dt, ne[w], nn[w]) + _wall_block(ne[w], nn[w], m, k, j, rad) for w in range(n_walls)]
    pw = np.zeros((2, 2, n)) if warm_wheels is None else warm_wheels[:, :2] * dt
    pc = np.zeros((2, n_walls, n)) if warm_walls is None else warm_walls * dt
    with np.errstate(invalid="ignore"):  # walls padded with gap = inf
        t_c = axle_friction if axle_friction is not None else np.broadcast_to(
            np.reshape(np.asarray(_sub_robots(p.coulomb_friction, idx), dtype=float), (-1, 1)), (n, 2))
        held = (np.zeros((2, n)) if warm_wheels is None or warm_wheels.shape[1] < 3
                else np.clip(warm_wheels[:, 2] * dt, -t_c.T * dt, t_c.T * dt))
        axles = [(1.0 / iwl, t_c[:, 0] * dt, held[0].copy()), (1.0 / iwr, t_c[:, 1] * dt, held[1].copy())]
        _solve_batch(nu, wheels, contacts, pw, pc, cs, dt, start=warm_wheels is not None, axles=axles)
    u, l, om, wl, wr = nu
    cx = q[:, 0] - d * c + dt * (u * c - l * s)
    cy = q[:, 1] - d * s + dt * (u * s + l * c)
    phi1 = q[:, 2] + dt * om
    q1 = np.stack([cx + d * np.cos(phi1), cy + d * np.sin(phi1), phi1, q[:, 3] + dt * wl, q[:, 4] + dt * wr], 1)
    stick = cap * dt * (1.0 - STICK_MARGIN)
    rolling = (np.hypot(pw[0, 0], pw[0, 1]) < stick) & (np.hypot(pw[1, 0], pw[1, 1]) < stick)
    pushed = (pc[0] > 0.0).any(0) if n_walls else np.zeros(n, dtype=bool)
    wheel_forces = np.concatenate([pw, np.stack([axles[0][2], axles[1][2]])[:, None]], axis=1) / dt
    return q1, np.stack([wl, wr], 1), np.stack([u, l, om], 1), rolling, pushed, wheel_forces, pc / dt


def _solve_batch(nu: list[np.ndarray], wheels: list[tuple[Any, ...]], contacts: list[tuple[Any, ...]],
                 pw: np.ndarray, pc: np.ndarray, cs: tuple[PerRobot, ...], dt: PerRobot, start: bool,
                 axles: list[tuple[Any, Any, np.ndarray]]) -> None:
    """`_solve` for K robots (pw (2, 2, K), pc (2, W, K), nu five (K,) arrays, all updated in place):
    each robot stops at the sweep where its own impulses settle, as the scalar solve does.  axles as
    `_solve`'s, with (K,) arrays."""
    m, k, j, dd, _iw, r, _b, _d, rad, cap, mu_w, mg = cs
    ju, lat_l, lat_w = 1.0 / m, j / dd, -k / dd
    if start:
        _warm_start_batch(nu, wheels, contacts, pw, pc, (ju, lat_l, lat_w))
        for i, (inv_iw, _bound, held) in enumerate(axles):
            nu[3 + i] = nu[3 + i] + held * inv_iw
    lim = cap * dt
    b = np.abs(wheels[0][0])
    full = _solution(nu, pw, pc, axles)
    live: np.ndarray | None = None  # the robots still solved, once fewer than all (their indices in full)
    active = np.ones(len(nu[0]), dtype=bool)
    for sweep in range(PGS_MAX_ITER):
        before = [x.copy() for x in nu]
        _wheel_rows(nu, wheels, pw, axles, lim, (ju, lat_l, lat_w), active)
        _wall_rows(nu, contacts, pc, (ju, rad, mu_w), active)
        change = np.maximum(np.maximum(np.abs(nu[0] - before[0]), np.abs(nu[1] - before[1])),
                            np.maximum(np.abs(b * (nu[2] - before[2])),
                                       np.maximum(np.abs(r * (nu[3] - before[3])), np.abs(r * (nu[4] - before[4])))))
        active &= change >= PGS_TOL
        unsettled = int(active.sum())
        if not unsettled:
            break
        state = (nu, pw, pc, wheels, contacts, axles, lim, b, r, rad, ju, lat_l, lat_w, mu_w)
        if unsettled <= ALONE_FROM:
            # A few robots that settle slowly (sliding on ice: 0.9 a sweep) would take a sweep's numpy
            # calls each for a few numbers: each goes on alone, the same arithmetic in Python floats.
            for one in np.flatnonzero(active):
                _sweep_alone(state, int(one), PGS_MAX_ITER - 1 - sweep)
            break
        if unsettled < COMPACT_BELOW * active.size:
            # Most have settled (a tenth of the robots, over half the sweeps, in a slippery fit): the batch goes
            # on with the others only.  Element by element the same arithmetic, so the same numbers, sooner.
            keep = np.flatnonzero(active)
            _put_back(full, _solution(nu, pw, pc, axles), live)
            live = keep if live is None else live[keep]
            nu, pw, pc, wheels, contacts, axles, lim, b, r, rad, ju, lat_l, lat_w, mu_w = _take(state, keep)
            active = np.ones(len(keep), dtype=bool)
    if live is not None:
        _put_back(full, _solution(nu, pw, pc, axles), live)


def _wheel_rows(nu: list[np.ndarray], wheels: list[tuple[Any, ...]], pw: np.ndarray,
                axles: list[tuple[Any, Any, np.ndarray]], lim: PerRobot, lat: tuple[Any, Any, Any],
                active: np.ndarray) -> None:
    """One sweep of the wheels' rows (`_solve`'s, for K robots): each wheel's friction impulse, on its
    disc where it would leave it, then its axle's friction.  lat: (1 / m, j / D, -k / D)."""
    ju, lat_l, lat_w = lat
    for i, (sb, el, ew, er, a11, a12, a22, wee, wen, wnn, eig, ri) in enumerate(wheels):
        ve = nu[0] - sb * nu[2] - ri * nu[3 + i]
        pe0, pn0 = pw[i, 0].copy(), pw[i, 1].copy()
        pe, pn = pe0 - (a11 * ve + a12 * nu[1]), pn0 - (a12 * ve + a22 * nu[1])
        over = pe * pe + pn * pn > lim * lim
        if over.any():
            with np.errstate(divide="ignore", invalid="ignore"):
                de, dn = _on_disc(ve - (wee * pe0 + wen * pn0), nu[1] - (wen * pe0 + wnn * pn0), lim, eig)
            grip = lim > 0.0  # mu = 0: no grip at all
            pe = np.where(over, np.where(grip, de, 0.0), pe)
            pn = np.where(over, np.where(grip, dn, 0.0), pn)
        de, dn = np.where(active, pe - pe0, 0.0), np.where(active, pn - pn0, 0.0)
        pw[i, 0], pw[i, 1] = pe0 + de, pn0 + dn
        nu[0] += ju * de
        nu[1] += el * de + lat_l * dn
        nu[2] += ew * de + lat_w * dn
        nu[3 + i] += er * de
        _axle_row(nu, i, axles[i], active)


def _sweep_alone(state: tuple[Any, ...], one: int, sweeps: int) -> None:
    """Robot `one` of _solve_batch's state (nu, pw, pc, wheels, contacts, axles, lim, b, r, rad, ju,
    lat_l, lat_w, mu_w) swept until it settles, at most `sweeps` more times, in Python floats: each row
    the batch's arithmetic, operation for operation (so the same numbers), written back at the end."""
    nu_a, pw_a, pc_a, wheels, contacts, axles, lim, b, r, rad, ju, lat_l, lat_w, mu_w = _one_robot(state, one)
    nu = [float(x) for x in nu_a]
    pw = [[float(pw_a[i, 0]), float(pw_a[i, 1])] for i in range(2)]
    pc = [[float(pc_a[0, w]), float(pc_a[1, w])] for w in range(pc_a.shape[1])]
    held = [float(h) for _inv, _bound, h in axles]
    for _ in range(sweeps):
        before = list(nu)
        for i, w in enumerate(wheels):
            _sb, el, ew, er = w[:4]
            pe0, pn0 = pw[i]
            pe, pn = _wheel_impulse(nu, i, w, pe0, pn0, lim)
            de, dn = pe - pe0, pn - pn0
            pw[i] = [pe0 + de, pn0 + dn]
            nu[0] += ju * de
            nu[1] += el * de + lat_l * dn
            nu[2] += ew * de + lat_w * dn
            nu[3 + i] += er * de
            inv_iw, bound = axles[i][0], axles[i][1]
            da = min(max(held[i] - nu[3 + i] / inv_iw, -bound), bound) - held[i]
            nu[3 + i] += da * inv_iw
            held[i] += da
        for w, (gdt, ne, nn, nl, nw, tl, tw, inn, itt) in enumerate(contacts):
            pn0, pt0 = pc[w]
            dn = max(pn0 - (ne * nu[0] + nn * nu[1] + gdt) * inn, 0.0) - pn0
            nu[0] += ne * ju * dn
            nu[1] += nl * dn
            nu[2] += nw * dn
            bound = mu_w * (pn0 + dn)
            dt_ = min(max(pt0 - (-nn * nu[0] + ne * nu[1] - rad * nu[2]) * itt, -bound), bound) - pt0
            nu[0] -= nn * ju * dt_
            nu[1] += tl * dt_
            nu[2] += tw * dt_
            pc[w] = [pn0 + dn, pt0 + dt_]
        if max(abs(nu[0] - before[0]), abs(nu[1] - before[1]), abs(b * (nu[2] - before[2])),
               abs(r * (nu[3] - before[3])), abs(r * (nu[4] - before[4]))) < PGS_TOL:
            break
    nu_out, pw_out, pc_out, _wheels, _contacts, axles_out = state[:6]
    for k in range(5):
        nu_out[k][one] = nu[k]
    pw_out[:, :, one] = pw
    for w, (pn, pt) in enumerate(pc):
        pc_out[0, w, one], pc_out[1, w, one] = pn, pt
    for i in range(2):
        axles_out[i][2][one] = held[i]


def _wall_rows(nu: list[np.ndarray], contacts: list[tuple[Any, ...]], pc: np.ndarray, cs: tuple[Any, Any, Any],
               active: np.ndarray) -> None:
    """One sweep of the walls' rows (`_solve`'s, for K robots): each wall's normal impulse, clipped at 0,
    then its tangent impulse, clipped at +-mu_w P_n.  cs: (1 / m, R, mu_w)."""
    ju, rad, mu_w = cs
    for w, (gdt, ne, nn, nl, nw, tl, tw, inn, itt) in enumerate(contacts):
        pn0, pt0 = pc[0, w].copy(), pc[1, w].copy()
        pn = np.maximum(pn0 - (ne * nu[0] + nn * nu[1] + gdt) * inn, 0.0)
        dn = np.where(active, pn - pn0, 0.0)
        nu[0] += ne * ju * dn
        nu[1] += nl * dn
        nu[2] += nw * dn
        bound = mu_w * (pn0 + dn)
        pt = np.minimum(np.maximum(pt0 - (-nn * nu[0] + ne * nu[1] - rad * nu[2]) * itt, -bound), bound)
        dt_ = np.where(active, pt - pt0, 0.0)
        nu[0] -= nn * ju * dt_
        nu[1] += tl * dt_
        nu[2] += tw * dt_
        pc[0, w], pc[1, w] = pn0 + dn, pt0 + dt_


def _take(x: Any, keep: np.ndarray) -> Any:
    """x's values for the robots keep: robots along each array's last axis; tuples and lists entry by
    entry (as lists, which the solve updates in place); floats, shared by all, as they are."""
    if isinstance(x, (tuple, list)):
        return type(x)(_take(y, keep) for y in x)
    return x[..., keep] if isinstance(x, np.ndarray) and x.ndim else x


def _one_robot(x: Any, one: int) -> Any:
    """_take(x, one) with its numbers as Python floats (numpy's scalars are ten times slower), what stays an
    array (a robot's rows) as it is: one pass, as _sweep_alone does it for each robot it sweeps on alone."""
    kind = type(x)
    if kind is tuple or kind is list:
        return kind([_one_robot(y, one) for y in x])
    if kind is np.ndarray and x.ndim:
        y = x[..., one]
        return y if y.ndim else float(y)
    return float(x)


def _solution(nu: list[np.ndarray], pw: np.ndarray, pc: np.ndarray, axles: list[tuple[Any, Any, np.ndarray]]
              ) -> tuple[Any, ...]:
    """What a batch solve finds (nu, pw, pc, the axles' held impulses), as _put_back writes it."""
    return nu, pw, pc, [held for _inv, _bound, held in axles]


def _put_back(full: tuple[Any, ...], part: tuple[Any, ...], live: np.ndarray | None) -> None:
    """The solve's state (nu, pw, pc, the axles' held impulses) for the robots live, written into full."""
    if live is None:
        return
    for whole, some in zip(full, part):
        if isinstance(whole, list):
            for w, s_ in zip(whole, some):
                w[..., live] = s_
        else:
            whole[..., live] = some


def _wheel_impulse(nu: list[float], i: int, w: tuple[Any, ...], pe0: float, pn0: float, lim: float
                   ) -> tuple[float, float]:
    """Wheel i's friction impulse (Python floats) after its row of a sweep, from (pe0, pn0): the block's
    correction for the contact point's slip, onto the disc |P| <= lim where it would leave it."""
    sb, _el, _ew, _er, a11, a12, a22, wee, wen, wnn, eig, ri = w
    ve = nu[0] - sb * nu[2] - ri * nu[3 + i]
    pe, pn = pe0 - (a11 * ve + a12 * nu[1]), pn0 - (a12 * ve + a22 * nu[1])
    if pe * pe + pn * pn > lim * lim:
        return _on_disc(ve - (wee * pe0 + wen * pn0), nu[1] - (wen * pe0 + wnn * pn0), lim, eig) \
            if lim > 0.0 else (0.0, 0.0)  # mu = 0: no grip at all
    return pe, pn


def _axle_row(nu: list[np.ndarray], i: int, axle: tuple[Any, Any, np.ndarray], active: np.ndarray) -> None:
    """One sweep of wheel i's axle friction row (`_solve`'s, for K robots): the impulse that stops the
    wheel's spin, clipped to the dry friction's bound."""
    inv_iw, bound, held = axle
    pa = np.clip(held - nu[3 + i] / inv_iw, -bound, bound)
    da = np.where(active, pa - held, 0.0)
    nu[3 + i] += da * inv_iw
    held += da


def _sub_robots(a: PerRobot, idx: np.ndarray | None) -> Any:
    """A parameter's values for robots idx (a shared float as it is)."""
    return a[idx] if idx is not None and isinstance(a, np.ndarray) else a


def _warm_start_batch(nu: list[np.ndarray], wheels: list[tuple[Any, ...]], contacts: list[tuple[Any, ...]],
                      pw: np.ndarray, pc: np.ndarray, lat: tuple[Any, Any, Any]) -> None:
    """`_solve_batch`'s warm start: the velocity change of the impulses pw, pc it starts from."""
    ju, lat_l, lat_w = lat
    for i, (_sb, el, ew, er) in enumerate(w[:4] for w in wheels):
        pe, pn = pw[i]
        nu[0] += ju * pe
        nu[1] += el * pe + lat_l * pn
        nu[2] += ew * pe + lat_w * pn
        nu[3 + i] += er * pe
    for w, (_g, ne, nn, nl, nw, tl, tw, _inn, _itt) in enumerate(contacts):
        pn, pt = pc[0, w], pc[1, w]
        nu[0] += (ne * pn - nn * pt) * ju
        nu[1] += nl * pn + tl * pt
        nu[2] += nw * pn + tw * pt
