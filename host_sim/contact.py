"""Contact: wheels on the floor that may slip, and the body's rim against walls.  Scalar and batch side by side.

Model and equations: docs/dynamics.md, "Contact".  In short:

* While both wheels roll without slipping and no wall pushes, the robot is
  the paper's reduced Lagrangian model (host_sim/dynamics.py, advanced by
  host_sim/drive.py).  `traction_ok` checks, after each such step, that the
  ground forces the no-slip constraints needed (longitudinal F_l, F_r at the
  wheels, lateral F_n at the axle) fit in the friction cones of the wheels:
  |(F_i, a_i)| <= mu N with a_l + a_r = F_n, N = (m_c + 2 m_w) g / 2 per wheel.
* Otherwise (a wheel slips, or the step would take the body into a wall) the
  step is `slip_step`: the unconstrained planar robot, generalised velocity
  nu = (u, l, omega, w_l, w_r) (velocity of C along the heading and to the
  left, yaw rate, wheel speeds), with contact impulses solved at the velocity
  level (time-stepping, Moreau / Stewart-Trinkle):
    - each wheel: Coulomb friction on the slip velocity of its contact point
      (u -+ b omega - r w_i along the heading, l sideways), |P| <= mu N dt;
    - each wall within reach: a normal impulse P_n >= 0 keeping the rim out of
      the wall (speculative: v_n + gap / dt >= 0, complementary to P_n), and
      Coulomb friction |P_t| <= mu_wall P_n at the rim point C - R n;
  solved by projected Gauss-Seidel to a fixed tolerance.  The body's
  gyroscopic terms are taken by the implicit midpoint rule (they do no work),
  the wheels' motor torque linearly implicitly (stable for a free-spinning
  wheel at any step), the pose with the new velocities (no push-out).
  When both wheels end the step inside their friction cones the robot is
  rolling again and goes back to the reduced model.

`walls_in_reach` (scalar) / `walls_in_reach_batch` pick the walls a step can
reach from World.wall_distances.  `slip_step` / `slip_step_batch` and
`traction_ok` / `traction_ok_batch` are the scalar and batch versions of the
same computation (tests/test_contact.py checks them against each other).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from host_sim.params import RobotParams

GRAVITY = 9.81  # m/s^2
PGS_TOL = 1e-10  # impulse change (in units of m g dt) below which the solve has converged
PGS_MAX_ITER = 500
STICK_MARGIN = 1e-9  # a wheel impulse this far inside its cone (relative) is sticking
REACH_MARGIN = 2e-3  # m: a wall closer than the step's travel + this is a contact candidate

_last: tuple[Any, tuple[float, ...]] | None = None


def consts(p: Any) -> tuple[Any, ...]:
    """(m, k = m_c d, J_C, D = m J_C - k^2, I_w, r, b, d, R, mu N, mu_wall, m g): RobotParams or ParamBatch."""
    global _last
    last = _last
    if last is not None and last[0] is p:
        return last[1]
    m = p.body_mass + 2 * p.wheel_mass
    k = p.body_mass * p.com_offset
    j = (p.body_inertia + p.body_mass * p.com_offset ** 2 + 2 * p.wheel_mass * p.half_axle ** 2
         + 2 * p.wheel_inertia_diam)
    c = (m, k, j, m * j - k * k, p.wheel_inertia, p.wheel_radius, p.half_axle, p.com_offset, p.body_radius,
         p.wheel_friction * m * GRAVITY / 2, p.wall_friction, m * GRAVITY)
    if isinstance(p, RobotParams):
        c = tuple(float(x) for x in c)
    _last = (p, c)
    return c


# --------------------------------------------------------------------------- #
# Rolling: do the wheels hold?
# --------------------------------------------------------------------------- #
def traction_ok(v0: Any, v1: Any, tau: Any, dt: float, p: RobotParams) -> bool:
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


def traction_ok_batch(v0: np.ndarray, v1: np.ndarray, tau: np.ndarray, dt: Any, p: Any) -> np.ndarray:
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
def walls_in_reach(world: Any, cx: float, cy: float, radius: float, within: float
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


def walls_in_reach_batch(world: Any, centres: np.ndarray, radius: Any, within: Any
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
def body_velocity(v: Any, p: Any) -> tuple[Any, Any, Any]:
    """(u, l, omega) of a rolling robot from its wheel speeds (l = 0)."""
    r, b = p.wheel_radius, p.half_axle
    return 0.5 * r * (v[0] + v[1]), 0.0 * v[0], 0.5 * r * (v[1] - v[0]) / b


def slip_step(q: Any, v: Any, body: tuple[float, float, float] | None, tau: Any, slope: Any, dt: float,
              p: RobotParams, walls: list[tuple[float, float, float, int]],
              warm: tuple[list[list[float]], list[list[float]]] | None = None
              ) -> tuple[tuple[float, ...], tuple[float, float], tuple[float, float, float] | None, bool,
                         tuple[list[list[float]], list[list[float]]]]:
    """One step of the unconstrained robot with wheel friction and wall contacts.

    q, v: as dynamics; body: (u, l, omega) if slipping, None if rolling (then from v).
    tau, slope: wheel torques (N m) and d tau / d w (N m s, <= 0) at v.  walls: (gap, nx, ny, index)
    as walls_in_reach.  warm: the contact forces of the previous step (wheels [[F_e, F_n]] x 2,
    walls [[F_n, F_t]] in the order of `walls`), where the solve starts (warm start: in steady
    contact a few sweeps instead of a hundred; the solution is the same).  Returns (q, v, body or
    None if both wheels stick, a wall pushed, the contact forces for the next warm start).
    """
    m, k, j, dd, iw, r, b, d, rad, cap, mu_w, mg = consts(p)
    phi = q[2]
    c, s = math.cos(phi), math.sin(phi)
    if body is None:
        u, l, om = 0.5 * r * (v[0] + v[1]), 0.0, 0.5 * r * (v[1] - v[0]) / b
    else:
        u, l, om = body
    # Free motion: (M - a G) nu1 = (M + a G) nu0, a = dt/2 omega (gyroscopic, no work), by Cramer.
    a = 0.5 * dt * om
    am, ak = a * m, a * k
    r1 = m * u + am * l + ak * om
    r2 = m * l + k * om - am * u
    r3 = k * l + j * om - ak * u
    det = m * (m * j - k * k) + am * (am * j - k * ak) - ak * (am * k - m * ak)
    u = (r1 * (m * j - k * k) + am * (r2 * j - k * r3) - ak * (r2 * k - m * r3)) / det
    l = (m * (r2 * j - k * r3) - r1 * (am * j - k * ak) - ak * (am * r3 - ak * r2)) / det
    om = (m * (m * r3 - k * r2) + am * (am * r3 - ak * r2) + r1 * (am * k - m * ak)) / det
    # Wheels: I_w (w1 - w0) = dt (tau + slope (w1 - w0)) + impulse, linearly implicit.
    iwl, iwr = iw - dt * slope[0], iw - dt * slope[1]
    wl, wr = v[0] + dt * tau[0] / iwl, v[1] + dt * tau[1] / iwr
    # Velocity changes per unit impulse, M^-1 J^T, and the local inverse masses.
    ju, jd = 1.0 / m, 1.0 / dd
    lat_l, lat_w = j * jd, -k * jd  # the sideways row (0, 1, 0)
    wheels = []
    for side, iwi in ((1.0, iwl), (-1.0, iwr)):
        sb = side * b
        el, ew = k * sb * jd, -m * sb * jd  # the heading row (1, 0, -s b, -r)
        wee = ju + m * b * b * jd + r * r / iwi
        wen = sb * k * jd
        wnn = j * jd
        idet = 1.0 / (wee * wnn - wen * wen)
        wheels.append((sb, el, ew, -r / iwi, wnn * idet, -wen * idet, wee * idet))
    contacts = []
    for gap, nx, ny, _index in walls:
        ne, nn = nx * c + ny * s, -nx * s + ny * c
        nl, nw = j * nn * jd, -k * nn * jd
        tl_, tw = (j * ne + k * rad) * jd, (-k * ne - m * rad) * jd
        wnn_ = ne * ne * ju + j * nn * nn * jd
        wtt = nn * nn * ju + (j * ne * ne + 2 * k * rad * ne + m * rad * rad) * jd
        contacts.append((gap / dt, ne, nn, nl, nw, tl_, tw, 1.0 / wnn_, 1.0 / wtt))
    lim = cap * dt
    tol = PGS_TOL * mg * dt
    if warm is None:
        pw = [[0.0, 0.0], [0.0, 0.0]]
        pc = [[0.0, 0.0] for _ in contacts]
    else:
        pw = [[f[0] * dt, f[1] * dt] for f in warm[0]]
        pc = [[f[0] * dt, f[1] * dt] for f in warm[1]]
        for i, (sb, el, ew, er, _a11, _a12, _a22) in enumerate(wheels):
            pe, pn = pw[i]
            u += ju * pe
            l += el * pe + lat_l * pn
            om += ew * pe + lat_w * pn
            if i == 0:
                wl += er * pe
            else:
                wr += er * pe
        for i, (_gdt, ne, nn, nl, nw, tl_, tw, _inn, _itt) in enumerate(contacts):
            pn, pt = pc[i]
            u += (ne * pn - nn * pt) * ju
            l += nl * pn + tl_ * pt
            om += nw * pn + tw * pt
    for _ in range(PGS_MAX_ITER):
        change = 0.0
        for i, (sb, el, ew, er, a11, a12, a22) in enumerate(wheels):
            ve = u - sb * om - r * (wl if i == 0 else wr)
            pe0, pn0 = pw[i]
            pe, pn = pe0 - (a11 * ve + a12 * l), pn0 - (a12 * ve + a22 * l)
            size = math.hypot(pe, pn)
            if size > lim:
                pe, pn = pe * lim / size, pn * lim / size
            de, dn = pe - pe0, pn - pn0
            pw[i] = [pe, pn]
            u += ju * de
            l += el * de + lat_l * dn
            om += ew * de + lat_w * dn
            if i == 0:
                wl += er * de
            else:
                wr += er * de
            change = max(change, abs(de), abs(dn))
        for i, (gdt, ne, nn, nl, nw, tl_, tw, inn, itt) in enumerate(contacts):
            pn0, pt0 = pc[i]
            pn = pn0 - (ne * u + nn * l + gdt) * inn
            pn = pn if pn > 0.0 else 0.0
            dn = pn - pn0
            u += ne * ju * dn
            l += nl * dn
            om += nw * dn
            pt = pt0 - (-nn * u + ne * l - rad * om) * itt
            bound = mu_w * pn
            pt = bound if pt > bound else (-bound if pt < -bound else pt)
            dt_ = pt - pt0
            u += -nn * ju * dt_
            l += tl_ * dt_
            om += tw * dt_
            pc[i] = [pn, pt]
            change = max(change, abs(dn), abs(dt_))
        if change < tol:
            break
    # Pose with the new velocities (C moves as its constraints saw it: heading phi_n).
    cx, cy = q[0] - d * c, q[1] - d * s
    cx += dt * (u * c - l * s)
    cy += dt * (u * s + l * c)
    phi1 = phi + dt * om
    q1 = (cx + d * math.cos(phi1), cy + d * math.sin(phi1), phi1, q[3] + dt * wl, q[4] + dt * wr)
    stick = lim * (1.0 - STICK_MARGIN)
    rolling = math.hypot(*pw[0]) < stick and math.hypot(*pw[1]) < stick
    pushed = any(pn > 0.0 for pn, _pt in pc)
    forces = ([[pe / dt, pn / dt] for pe, pn in pw], [[pn / dt, pt / dt] for pn, pt in pc])
    return q1, (wl, wr), None if rolling else (u, l, om), pushed, forces


def slip_step_batch(q: np.ndarray, v: np.ndarray, body: np.ndarray, tau: np.ndarray, slope: np.ndarray, dt: Any,
                    p: Any, gaps: np.ndarray, normals: np.ndarray, idx: np.ndarray | None = None,
                    warm_wheels: np.ndarray | None = None, warm_walls: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`slip_step` for K robots: q (K, 5), v (K, 2), body (K, 3) (u, l, omega; for rolling robots
    from v), tau, slope (K, 2), dt float or (K,), gaps (K, W) and normals (K, W, 2) as
    walls_in_reach_batch; p a RobotParams or a ParamBatch, of which robots idx are these K;
    warm_wheels (2, 2, K) and warm_walls (2, W, K): the previous step's forces, as slip_step's warm.
    Returns (q, v, body, rolling (K,), pushed (K,), wheel forces (2, 2, K), wall forces (2, W, K))."""
    cs = consts(p)
    if idx is not None:
        cs = tuple(x[idx] if isinstance(x, np.ndarray) else x for x in cs)
    m, k, j, dd, iw, r, b, d, rad, cap, mu_w, mg = cs
    n = len(q)
    phi = q[:, 2]
    c, s = np.cos(phi), np.sin(phi)
    u, l, om = body[:, 0].copy(), body[:, 1].copy(), body[:, 2].copy()
    a = 0.5 * dt * om
    am, ak = a * m, a * k
    r1 = m * u + am * l + ak * om
    r2 = m * l + k * om - am * u
    r3 = k * l + j * om - ak * u
    det = m * (m * j - k * k) + am * (am * j - k * ak) - ak * (am * k - m * ak)
    u = (r1 * (m * j - k * k) + am * (r2 * j - k * r3) - ak * (r2 * k - m * r3)) / det
    l = (m * (r2 * j - k * r3) - r1 * (am * j - k * ak) - ak * (am * r3 - ak * r2)) / det
    om = (m * (m * r3 - k * r2) + am * (am * r3 - ak * r2) + r1 * (am * k - m * ak)) / det
    iwl, iwr = iw - dt * slope[:, 0], iw - dt * slope[:, 1]
    wl, wr = v[:, 0] + dt * tau[:, 0] / iwl, v[:, 1] + dt * tau[:, 1] / iwr
    ju, jd = 1.0 / m, 1.0 / dd
    lat_l, lat_w = j * jd, -k * jd
    wheels = []
    for side, iwi in ((1.0, iwl), (-1.0, iwr)):
        sb = side * b
        wee = ju + m * b * b * jd + r * r / iwi
        wen = sb * k * jd
        wnn = j * jd
        idet = 1.0 / (wee * wnn - wen * wen)
        wheels.append((sb, k * sb * jd, -m * sb * jd, -r / iwi, wnn * idet, -wen * idet, wee * idet))
    nx, ny = normals[..., 0], normals[..., 1]
    cc, ss = c[:, None], s[:, None]
    ne, nn = nx * cc + ny * ss, -nx * ss + ny * cc  # (K, W)
    jw, kw_, mw_, rw = (np.reshape(x, (-1, 1)) if np.ndim(x) else x for x in (j, k, m, rad))
    jdw, juw = (np.reshape(x, (-1, 1)) if np.ndim(x) else x for x in (jd, ju))
    nl, nw = jw * nn * jdw, -kw_ * nn * jdw
    tl_, tw = (jw * ne + kw_ * rw) * jdw, (-kw_ * ne - mw_ * rw) * jdw
    inn = 1.0 / (ne * ne * juw + jw * nn * nn * jdw)
    itt = 1.0 / (nn * nn * juw + (jw * ne * ne + 2 * kw_ * rw * ne + mw_ * rw * rw) * jdw)
    gdt = gaps / (np.reshape(dt, (-1, 1)) if np.ndim(dt) else dt)
    lim = cap * dt
    tol = PGS_TOL * mg * dt
    n_walls = gaps.shape[1]
    if warm_wheels is None:
        pw = np.zeros((2, 2, n))
    else:
        pw = warm_wheels * dt
        for i, (sb, el, ew, er, _a11, _a12, _a22) in enumerate(wheels):
            pe, pn = pw[i]
            u += ju * pe
            l += el * pe + lat_l * pn
            om += ew * pe + lat_w * pn
            if i == 0:
                wl += er * pe
            else:
                wr += er * pe
    if warm_walls is None:
        pc = np.zeros((2, n_walls, n))
    else:
        pc = warm_walls * dt
        for w in range(n_walls):
            pn, pt = pc[0, w], pc[1, w]
            u += (ne[:, w] * pn - nn[:, w] * pt) * ju
            l += nl[:, w] * pn + tl_[:, w] * pt
            om += nw[:, w] * pn + tw[:, w] * pt
    mu_wv = np.broadcast_to(mu_w, (n,))
    active = np.ones(n, dtype=bool)
    for _ in range(PGS_MAX_ITER):
        change = np.zeros(n)
        for i, (sb, el, ew, er, a11, a12, a22) in enumerate(wheels):
            ve = u - sb * om - r * (wl if i == 0 else wr)
            pe0, pn0 = pw[i]
            pe, pn = pe0 - (a11 * ve + a12 * l), pn0 - (a12 * ve + a22 * l)
            size = np.hypot(pe, pn)
            scale = np.where(size > lim, lim / np.where(size > 0, size, 1.0), 1.0)
            de = np.where(active, pe * scale - pe0, 0.0)
            dn = np.where(active, pn * scale - pn0, 0.0)
            pw[i, 0] += de
            pw[i, 1] += dn
            u += ju * de
            l += el * de + lat_l * dn
            om += ew * de + lat_w * dn
            if i == 0:
                wl += er * de
            else:
                wr += er * de
            change = np.maximum(change, np.maximum(np.abs(de), np.abs(dn)))
        for w in range(n_walls):
            pn0, pt0 = pc[0, w], pc[1, w]
            e_, n_ = ne[:, w], nn[:, w]
            with np.errstate(invalid="ignore"):
                pn = np.maximum(pn0 - (e_ * u + n_ * l + gdt[:, w]) * inn[:, w], 0.0)
            dn = np.where(active, pn - pn0, 0.0)
            u += e_ * ju * dn
            l += nl[:, w] * dn
            om += nw[:, w] * dn
            pn = pn0 + dn
            pt = pt0 - (-n_ * u + e_ * l - rad * om) * itt[:, w]
            bound = mu_wv * pn
            pt = np.minimum(np.maximum(pt, -bound), bound)
            dt_ = np.where(active, pt - pt0, 0.0)
            u += -n_ * ju * dt_
            l += tl_[:, w] * dt_
            om += tw[:, w] * dt_
            pc[0, w] = pn
            pc[1, w] = pt0 + dt_
            change = np.maximum(change, np.maximum(np.abs(dn), np.abs(dt_)))
        active &= change >= tol
        if not active.any():
            break
    cx, cy = q[:, 0] - d * c, q[:, 1] - d * s
    cx = cx + dt * (u * c - l * s)
    cy = cy + dt * (u * s + l * c)
    phi1 = phi + dt * om
    q1 = np.stack([cx + d * np.cos(phi1), cy + d * np.sin(phi1), phi1, q[:, 3] + dt * wl, q[:, 4] + dt * wr], 1)
    stick = lim * (1.0 - STICK_MARGIN)
    rolling = (np.hypot(pw[0, 0], pw[0, 1]) < stick) & (np.hypot(pw[1, 0], pw[1, 1]) < stick)
    pushed = (pc[0] > 0.0).any(0) if n_walls else np.zeros(n, dtype=bool)
    return q1, np.stack([wl, wr], 1), np.stack([u, l, om], 1), rolling, pushed, pw / dt, pc / dt
