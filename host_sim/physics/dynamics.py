"""The robot's rolling dynamics (paper section 3.1): Lagrangian, Pfaffian constraints, reduced through S(q).

q = (x_c, y_c, phi, theta_l, theta_r) with (x_c, y_c) the centre of mass G, d = com_offset ahead of
the axle's centre C; v = (theta_l', theta_r').  The paper's matrices (`matrices`, `step_matrix`), the
closed form for one robot (`reduced_accel_fast`, `step`) and for N (`reduced_accel_batch`, `step_batch`
with a `ParamBatch`) are the same equations and the same second-order integrator.
Derivation, conventions and the integrator: docs/dynamics.md.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Union

import numpy as np
from numpy.typing import ArrayLike

from host_sim.physics.params import RobotParams, cached_per_params

Vec = Union[Sequence[float], np.ndarray]  # a state vector: tuple, list or numpy array
PerRobot = Union[float, np.ndarray]  # a value every robot shares, or an array of one per robot

# ----------------------------------------------------------------------------- #
# Parameters: the combinations the closed form needs
# ----------------------------------------------------------------------------- #

def effective_inertias(p: Params) -> tuple[Any, Any]:
    """(m_t, J_t): the effective translational mass (kg) and yaw inertia about C (kg m^2).

    m_t = m_c + 2 m_w + 2 I_w / r^2
    J_t = I_c + m_c d^2 + 2 m_w b^2 + 2 I_m + 2 b^2 I_w / r^2
    Works on RobotParams (floats) and on ParamBatch (arrays).
    """
    r, b, d = p.wheel_radius, p.half_axle, p.com_offset
    m_t = p.body_mass + 2 * p.wheel_mass + 2 * p.wheel_inertia / (r * r)
    j_t = (p.body_inertia + p.body_mass * d * d + 2 * p.wheel_mass * b * b + 2 * p.wheel_inertia_diam
           + 2 * b * b * p.wheel_inertia / (r * r))
    return m_t, j_t


@cached_per_params
def _coeffs(p: Params) -> tuple[Any, ...]:
    """(r, b, d, g = m_c d, m_t, J_t, 1/m_t, 1/J_t, r/2, r/(2b), 1/r, b/r, m_t J_t).

    Cached for the last RobotParams seen (they are frozen); a ParamBatch keeps its own."""
    if isinstance(p, ParamBatch):
        return p.dynamics_coeffs()
    m_t, j_t = effective_inertias(p)
    m_t, j_t = float(m_t), float(j_t)
    r, b = float(p.wheel_radius), float(p.half_axle)
    c = (r, b, float(p.com_offset), float(p.body_mass * p.com_offset), m_t, j_t, 1.0 / m_t, 1.0 / j_t,
         0.5 * r, 0.5 * r / b, 1.0 / r, b / r, m_t * j_t)
    return c


class ParamBatch:
    """Parameters of N robots: every scalar RobotParams name as a read-only float array of shape (N,).

    Anything that reads RobotParams attributes (the batch dynamics, the batch motors)
    reads a ParamBatch the same way and gets one value per robot.  Build it with
    `from_params([p0, p1, ...])`, `broadcast(p, n)`, or `from_vectors(values, names)`
    (identification: values has shape (N, len(names)), the other parameters from `base`).
    """

    def __init__(self, arrays: dict[str, np.ndarray]) -> None:
        n = None
        for name, a in arrays.items():
            a = np.array(a, dtype=float)
            if a.ndim != 1 or (n is not None and a.shape[0] != n):
                raise ValueError(f"ParamBatch: '{name}' must have shape ({n if n is not None else 'N'},), "
                                 f"got {a.shape}")
            n = a.shape[0]
            a.setflags(write=False)
            setattr(self, name, a)
        self.names = list(arrays)
        self.n = 0 if n is None else n
        self._dyn: tuple[np.ndarray, ...] | None = None

    @classmethod
    def from_params(cls, params: Sequence[RobotParams]) -> ParamBatch:
        names = RobotParams.scalar_names()
        return cls({k: np.array([float(getattr(p, k)) for p in params]) for k in names})

    @classmethod
    def broadcast(cls, p: RobotParams, n: int) -> ParamBatch:
        return cls({k: np.full(n, float(getattr(p, k))) for k in RobotParams.scalar_names()})

    @classmethod
    def from_vectors(cls, values: ArrayLike, names: Sequence[str], base: RobotParams | None = None) -> ParamBatch:
        values = np.asarray(values, dtype=float)
        if values.ndim != 2 or values.shape[1] != len(names):
            raise ValueError(f"values must have shape (N, {len(names)}), got {values.shape}")
        base = base or RobotParams()
        unknown = set(names) - set(RobotParams.scalar_names())
        if unknown:
            raise ValueError(f"unknown parameter names: {sorted(unknown)}")
        n = values.shape[0]
        arrays = {k: np.full(n, float(getattr(base, k))) for k in RobotParams.scalar_names()}
        for j, k in enumerate(names):
            arrays[k] = values[:, j].copy()
        return cls(arrays)

    def __len__(self) -> int:
        return self.n

    def __getattr__(self, name: str) -> np.ndarray:  # only for names not set in __init__
        raise AttributeError(f"ParamBatch has no parameter '{name}'")

    def robot(self, i: int, base: RobotParams | None = None) -> RobotParams:
        """The parameters of robot i as a RobotParams (the non-scalar ones from `base`)."""
        return (base or RobotParams()).replace(**{k: float(getattr(self, k)[i]) for k in self.names})

    def dynamics_coeffs(self) -> tuple[np.ndarray, ...]:
        if self._dyn is None:
            m_t, j_t = effective_inertias(self)
            r, b = self.wheel_radius, self.half_axle
            self._dyn = (r, b, self.com_offset, self.body_mass * self.com_offset, m_t, j_t, 1.0 / m_t, 1.0 / j_t,
                         0.5 * r, 0.5 * r / b, 1.0 / r, b / r, m_t * j_t)
        return self._dyn


# What the shared physics reads attribute by attribute: one robot's parameters (floats) or N robots' (arrays)
Params = Union[RobotParams, ParamBatch]


# ----------------------------------------------------------------------------- #
# The paper's matrices (numpy; recomputed at every call)
# ----------------------------------------------------------------------------- #
def mass_matrix(q: Vec, p: RobotParams) -> np.ndarray:
    """M(q), 5x5, from T = 1/2 q'^T M q' (docs/dynamics.md, "Kinetic energy")."""
    c, s = math.cos(q[2]), math.sin(q[2])
    b, d = p.half_axle, p.com_offset
    m = p.body_mass + 2 * p.wheel_mass
    inertia = p.body_inertia + 2 * p.wheel_mass * (d * d + b * b) + 2 * p.wheel_inertia_diam
    k = 2 * p.wheel_mass * d
    iw = p.wheel_inertia
    return np.array([
        [m, 0.0, k * s, 0.0, 0.0],
        [0.0, m, -k * c, 0.0, 0.0],
        [k * s, -k * c, inertia, 0.0, 0.0],
        [0.0, 0.0, 0.0, iw, 0.0],
        [0.0, 0.0, 0.0, 0.0, iw],
    ])


def coriolis(q: Vec, q_dot: Vec, p: RobotParams) -> np.ndarray:
    """V(q, q') = M' q' - dT/dq (5,): [2 m_w d phi'^2 cos phi, 2 m_w d phi'^2 sin phi, 0, 0, 0]."""
    k = 2 * p.wheel_mass * p.com_offset * q_dot[2] * q_dot[2]
    return np.array([k * math.cos(q[2]), k * math.sin(q[2]), 0.0, 0.0, 0.0])


def input_matrix(q: Vec, p: RobotParams) -> np.ndarray:
    """E(q), 5x2: the wheel torques (tau_l, tau_r) act on theta_l, theta_r."""
    return np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])


def constraint_matrix(q: Vec, p: RobotParams) -> np.ndarray:
    """A(q), 3x5, A q' = 0: lateral no-slip at the axle, rolling of the left and right wheel."""
    c, s = math.cos(q[2]), math.sin(q[2])
    b, d, r = p.half_axle, p.com_offset, p.wheel_radius
    return np.array([
        [-s, c, -d, 0.0, 0.0],
        [-c, -s, b, r, 0.0],
        [-c, -s, -b, 0.0, r],
    ])


def constraint_matrix_dot(q: Vec, q_dot: Vec, p: RobotParams) -> np.ndarray:
    """dA/dt = (dA/dphi) phi', 3x5."""
    c, s, w = math.cos(q[2]), math.sin(q[2]), q_dot[2]
    return np.array([
        [-c * w, -s * w, 0.0, 0.0, 0.0],
        [s * w, -c * w, 0.0, 0.0, 0.0],
        [s * w, -c * w, 0.0, 0.0, 0.0],
    ])


def null_space(q: Vec, p: RobotParams) -> np.ndarray:
    """S(q), 5x2, A S = 0, q' = S v with v = (theta_l', theta_r')."""
    c, s = math.cos(q[2]), math.sin(q[2])
    r, b, d = p.wheel_radius, p.half_axle, p.com_offset
    h, rho, k = 0.5 * r, 0.5 * d * r / b, 0.5 * r / b
    return np.array([
        [h * c + rho * s, h * c - rho * s],
        [h * s - rho * c, h * s + rho * c],
        [-k, k],
        [1.0, 0.0],
        [0.0, 1.0],
    ])


def null_space_dot(q: Vec, q_dot: Vec, p: RobotParams) -> np.ndarray:
    """dS/dt = (dS/dphi) phi', 5x2."""
    c, s, w = math.cos(q[2]), math.sin(q[2]), q_dot[2]
    r, b, d = p.wheel_radius, p.half_axle, p.com_offset
    h, rho = 0.5 * r, 0.5 * d * r / b
    return np.array([
        [(-h * s + rho * c) * w, (-h * s - rho * c) * w],
        [(h * c + rho * s) * w, (h * c - rho * s) * w],
        [0.0, 0.0],
        [0.0, 0.0],
        [0.0, 0.0],
    ])


def matrices(q: Vec, q_dot: Vec, p: RobotParams) -> tuple[np.ndarray, ...]:
    """(M, V, E, A, S, S_dot) at (q, q'): the paper's non-stationary matrices, recomputed each call."""
    return (mass_matrix(q, p), coriolis(q, q_dot, p), input_matrix(q, p), constraint_matrix(q, p),
            null_space(q, p), null_space_dot(q, q_dot, p))


def reduced_accel(q: Vec, v: Vec, tau: Vec, p: RobotParams) -> np.ndarray:
    """v' from  S^T M S v' + S^T (M S' v + V) = S^T E tau, through the matrices (the paper's path)."""
    va = np.asarray(v, dtype=float)
    s_mat = null_space(q, p)
    m, vv, e, _a, s_mat, s_dot = matrices(q, s_mat @ va, p)
    h = s_mat.T @ m @ s_mat
    rhs = s_mat.T @ (e @ np.asarray(tau, dtype=float)) - s_mat.T @ (m @ (s_dot @ va) + vv)
    return np.linalg.solve(h, rhs)


def _gyroscopic_matrix(q: Vec, q_dot_star: np.ndarray, p: RobotParams, s_mat: np.ndarray,
                       m: np.ndarray) -> np.ndarray:
    """C*, 2x2: S^T (M S'(q'*) w + V(q'*, S w)) as a linear map of w, with phi' frozen at q'*.

    V is a quadratic form in q'; its bilinear form is obtained by polarisation,
    V(a, b) = (V(a + b) - V(a - b)) / 4, so no structure of V is assumed here.
    """
    s_dot = null_space_dot(q, q_dot_star, p)
    cols = []
    for j in range(2):
        sw = s_mat[:, j]
        v_bil = 0.25 * (coriolis(q, q_dot_star + sw, p) - coriolis(q, q_dot_star - sw, p))
        cols.append(s_mat.T @ (m @ s_dot[:, j] + v_bil))
    return np.column_stack(cols)


def step_matrix(q: Vec, v: Vec, tau: Vec, dt: float, p: RobotParams) -> tuple[np.ndarray, np.ndarray]:
    """One step of the integrator (see the module docstring) evaluated through the matrices."""
    qa = np.asarray(q, dtype=float)
    va = np.asarray(v, dtype=float)
    ta = np.asarray(tau, dtype=float)
    s_mat = null_space(qa, p)
    m = mass_matrix(qa, p)
    h = s_mat.T @ m @ s_mat
    v_star = va + 0.5 * dt * reduced_accel(qa, va, ta, p)
    c_star = _gyroscopic_matrix(qa, s_mat @ v_star, p, s_mat, m)
    f = s_mat.T @ (input_matrix(qa, p) @ ta)
    v_new = np.linalg.solve(h + 0.5 * dt * c_star, (h - 0.5 * dt * c_star) @ va + dt * f)
    v_bar = 0.5 * (va + v_new)
    q_mid = qa.copy()
    q_mid[2] += 0.5 * dt * (s_mat[2] @ v_bar)
    return qa + dt * (null_space(q_mid, p) @ v_bar), v_new


# ----------------------------------------------------------------------------- #
# Closed form, one robot, pure-Python floats
# ----------------------------------------------------------------------------- #
def reduced_accel_fast(q: Vec, v: Vec, tau: Vec, p: RobotParams) -> tuple[float, float]:
    """v' in closed form (pure Python floats; q is not needed: the reduced model does not depend on it)."""
    r, b, _d, g, _mt, _jt, imt, ijt = _coeffs(p)[:8]
    wl, wr = v[0], v[1]
    tl, tr = tau[0], tau[1]
    u = 0.5 * r * (wl + wr)
    w = 0.5 * r * (wr - wl) / b
    ud = ((tl + tr) / r + g * w * w) * imt
    wd = (b * (tr - tl) / r - g * u * w) * ijt
    return (ud - b * wd) / r, (ud + b * wd) / r


def step(q: Vec, v: Vec, tau: Vec, dt: float, p: RobotParams) -> tuple[tuple[float, ...], tuple[float, float]]:
    """One fixed step (module docstring, docs/dynamics.md): returns (q_next, v_next) as tuples of floats."""
    r, b, d, g, mt, jt, _imt, ijt, hr, kw, ir, bir, mtjt = _coeffs(p)
    wl, wr = v[0], v[1]
    tl, tr = tau[0], tau[1]
    u = hr * (wl + wr)
    w = kw * (wr - wl)
    gam = bir * (tr - tl)
    hdt = 0.5 * dt
    # yaw rate predicted at mid-step, for the gyroscopic coefficient
    al = hdt * g * (w + hdt * (gam - g * u * w) * ijt)
    r1 = mt * u + al * w + dt * ir * (tl + tr)
    r2 = jt * w - al * u + dt * gam
    idet = 1.0 / (mtjt + al * al)
    u1 = (jt * r1 + al * r2) * idet
    w1 = (mt * r2 - al * r1) * idet
    x1 = ir * u1
    y1 = bir * w1
    wl1 = x1 - y1
    wr1 = x1 + y1
    sb = hdt * (u + u1)  # distance along the heading in the step
    wb = 0.5 * (w + w1)
    dwb = dt * d * wb
    phi = q[2]
    ph = phi + hdt * wb
    c, s = math.cos(ph), math.sin(ph)
    return ((q[0] + sb * c - dwb * s, q[1] + sb * s + dwb * c, phi + dt * wb,
             q[3] + hdt * (wl + wl1), q[4] + hdt * (wr + wr1)), (wl1, wr1))


# ----------------------------------------------------------------------------- #
# Closed form, N robots (numpy), per-robot parameters
# ----------------------------------------------------------------------------- #
def reduced_accel_batch(q: np.ndarray, v: np.ndarray, tau: np.ndarray, p: Params) -> np.ndarray:
    """v' for N robots: v, tau (N, 2) -> (N, 2); p a RobotParams (shared) or a ParamBatch of N."""
    r, b, _d, g, _mt, _jt, imt, ijt = _coeffs(p)[:8]
    wl, wr = v[:, 0], v[:, 1]
    tl, tr = tau[:, 0], tau[:, 1]
    u = 0.5 * r * (wl + wr)
    w = 0.5 * r * (wr - wl) / b
    ud = ((tl + tr) / r + g * w * w) * imt
    wd = (b * (tr - tl) / r - g * u * w) * ijt
    out = np.empty_like(v, dtype=float)
    out[:, 0] = (ud - b * wd) / r
    out[:, 1] = (ud + b * wd) / r
    return out


def step_batch(q: np.ndarray, v: np.ndarray, tau: np.ndarray, dt: float, p: Params,
               out: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """`step` for N robots: q (N, 5), v (N, 2), tau (N, 2) -> (q_next, v_next).

    p: a RobotParams shared by all, or a ParamBatch (one parameter set per robot).
    dt: a float or an array (N,).  out: optional (q_next, v_next) arrays to write into
    (they may be q and v themselves).
    """
    r, b, d, g, mt, jt, _imt, ijt, hr, kw, ir, bir, mtjt = _coeffs(p)
    wl, wr = v[:, 0], v[:, 1]
    tl, tr = tau[:, 0], tau[:, 1]
    u = hr * (wl + wr)
    w = kw * (wr - wl)
    gam = bir * (tr - tl)
    hdt = 0.5 * dt
    al = (hdt * g) * (w + (hdt * ijt) * (gam - g * u * w))
    r1 = mt * u + al * w + dt * ir * (tl + tr)
    r2 = jt * w - al * u + dt * gam
    idet = 1.0 / (mtjt + al * al)
    u1 = (jt * r1 + al * r2) * idet
    w1 = (mt * r2 - al * r1) * idet
    ub = dt * 0.5 * (u + u1)  # distance travelled along the heading in the step
    wb = 0.5 * (w + w1)
    ph = q[:, 2] + hdt * wb
    c, s = np.cos(ph), np.sin(ph)
    x1 = ir * u1
    y1 = bir * w1
    if out is None:
        qn, vn = np.empty(q.shape), np.empty(v.shape)
    else:
        qn, vn = out
    dwb = (dt * d) * wb
    qn[:, 0] = q[:, 0] + (ub * c - dwb * s)
    qn[:, 1] = q[:, 1] + (ub * s + dwb * c)
    qn[:, 3] = q[:, 3] + hdt * (wl + x1 - y1)
    qn[:, 4] = q[:, 4] + hdt * (wr + x1 + y1)
    qn[:, 2] = q[:, 2] + dt * wb
    vn[:, 0] = x1 - y1
    vn[:, 1] = x1 + y1
    return qn, vn


# ----------------------------------------------------------------------------- #
# Where things are
# ----------------------------------------------------------------------------- #
def axle_centre(q: Vec, p: RobotParams) -> tuple[float, float]:
    """(x, y) of C, the centre of the wheel axle: d behind (x_c, y_c) along the heading."""
    d = p.com_offset
    return q[0] - d * math.cos(q[2]), q[1] - d * math.sin(q[2])


def q_from_axle_pose(x: float, y: float, phi: float, p: RobotParams,
                     theta_l: float = 0.0, theta_r: float = 0.0) -> tuple[float, float, float, float, float]:
    """q for the axle centre C at (x, y) with heading phi."""
    d = p.com_offset
    return (x + d * math.cos(phi), y + d * math.sin(phi), phi, theta_l, theta_r)
