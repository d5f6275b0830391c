"""Odometry: how far each wheel goes per encoder count, from the encoders against the tracker, no dynamics.

Over each WINDOW_S window clear of the walls the tracked path (an arc) is (k_l a_l + k_r a_r) / 2
and the tracked turn (k_r a_r - k_l a_l) / (2 b), a_i the angle wheel i's encoder counted and k_i its
distance per radian of counts: a least-squares fit of (k_l, k_r, b), each equation weighed by its own scatter.
A wheel whose distance per count lies beyond its radius's tolerance by more than Z of its standard errors is
a mismatch no build holds: a wheel of another radius, or an encoder of another count
per turn, which kinematics cannot tell apart (docs/diagnosis.md, "Odometry").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from host_sim.physics.params import RobotParams
from host_sim.physics.world import World
from host_sim.recordings.recording import Recording

WINDOW_S = 0.5  # long enough for the tracker's noise to be small against a window's travel
WALL_CLEAR = 0.02  # m beyond the body's rim: a wheel pushing a wall slips, and counts without going
MIN_TURNED = 0.2  # rad: a window in which neither wheel turned this much says nothing of distance per count
MIN_WINDOWS = 20
OUTLIER = 5.0  # a window this many robust scatters off the fit (a knock, a tracker glitch) is left out
# A wheel is beyond its tolerance when its interval of Z standard errors lies wholly beyond the band.  On the
# reference plant's tuning split, whose tyres slip and flex, the distance per count lay within 2 standard
# errors of the plant's own in 113 of its 114 wheels (median error -0.05 %), so no margin is added for slip
# (docs/diagnosis.md, "Odometry";
# tests/test_odometry.py::test_a_wheel_beyond_its_tolerance_is_found_by_its_odometry_alone).
Z = 2.0


@dataclass(frozen=True)
class Odometry:
    """Each wheel's distance per count and the half-axle, as departures from the datasheet's (relative), with
    their standard errors, from `windows` windows spanning `span` (s)."""

    per_count: tuple[float, float]
    per_count_se: tuple[float, float]
    half_axle: float
    half_axle_se: float
    windows: int
    span: tuple[float, float]

    def beyond(self, band: float, implied: tuple[tuple[float, float], ...] = ((0.0, 0.0), (0.0, 0.0))) -> list[int]:
        """The wheels (0 left, 1 right) whose distance per count lies beyond band of the implied range (lo, hi)
        per wheel (the datasheet's, or what named effects make it over their intervals) by more than Z se."""
        return [w for w in (0, 1) if max(implied[w][0] - self.per_count[w], self.per_count[w] - implied[w][1])
                - Z * self.per_count_se[w] > band]

    def interval(self, w: int) -> tuple[float, float]:
        """Wheel w's departure in size (|relative|), give or take Z standard errors: (lo, hi)."""
        d, half = abs(self.per_count[w]), Z * self.per_count_se[w]
        return d - half, d + half

    def to_json(self) -> dict[str, object]:
        return {"per_count": list(self.per_count), "per_count_se": list(self.per_count_se),
                "half_axle": self.half_axle, "half_axle_se": self.half_axle_se, "windows": self.windows}


def per_count(p: RobotParams) -> tuple[float, float]:
    """Each wheel's distance per radian of the angle its counts make at ticks_per_rev a turn: its radius times
    the counts a turn is taken to hold over the ones its encoder gives (m)."""
    return tuple(float((p.wheel_radius + dr) * p.ticks_per_rev / (p.ticks_per_rev + dt))  # type: ignore[return-value]
                 for dr, dt in ((p.wheel_radius_delta_l, p.ticks_per_rev_delta_l),
                                (p.wheel_radius_delta_r, p.ticks_per_rev_delta_r)))


def _window_motions(rec: Recording, p: RobotParams, world: World | None) -> tuple[np.ndarray, np.ndarray]:
    """(K, 4) per window clear of the walls: the angles the encoders counted (rad), the tracked path (its
    arc) and the tracked turn; and (K, 2) the windows' start and end times."""
    assert rec.pose is not None
    n = max(1, int(round(WINDOW_S / rec.sample_period)))
    starts = np.arange(0, len(rec.t) - n, n)
    ends = starts + n
    tracked = rec.pose_rows
    clear = np.ones(len(rec.t), dtype=bool)
    if world is not None and world.n_walls:
        clear = world.nearest_wall(np.nan_to_num(rec.pose[:, :2]))[0] > p.body_radius + WALL_CLEAR
    blocked = np.concatenate([[0], np.cumsum(~clear)])  # rows not clear before each row
    run_clear = blocked[ends + 1] == blocked[starts]
    keep = tracked[starts] & tracked[ends] & run_clear
    starts, ends = starts[keep], ends[keep]
    angle = (rec.enc[ends] - rec.enc[starts]).astype(float) * (2.0 * math.pi / p.ticks_per_rev)
    turn = np.mod(rec.pose[ends, 2] - rec.pose[starts, 2] + math.pi, 2.0 * math.pi) - math.pi
    heading = rec.pose[starts, 2] + 0.5 * turn
    dxy = rec.pose[ends, :2] - rec.pose[starts, :2]
    # the chord of an arc along its mean heading, lengthened to the arc: (turn / 2) / sin(turn / 2)
    travel = (dxy[:, 0] * np.cos(heading) + dxy[:, 1] * np.sin(heading)) / np.sinc(turn / (2.0 * math.pi))
    moved = np.abs(angle).max(axis=1) >= MIN_TURNED
    motions = np.column_stack([angle, travel, turn])[moved]
    return motions, np.column_stack([rec.t[starts], rec.t[ends]])[moved]


def _fit(m: np.ndarray, x0: np.ndarray, scale: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k_l, k_r, b), their covariance and the residuals (K, 2) in their own units."""
    def resid(x: np.ndarray) -> np.ndarray:
        travel = 0.5 * (x[0] * m[:, 0] + x[1] * m[:, 1]) - m[:, 2]
        turn = (x[1] * m[:, 1] - x[0] * m[:, 0]) / (2.0 * x[2]) - m[:, 3]
        return np.concatenate([travel / scale[0], turn / scale[1]])
    sol = least_squares(resid, x0, x_scale=x0)
    cov = np.linalg.pinv(sol.jac.T @ sol.jac)
    r = sol.fun.reshape(2, -1).T * np.array(scale)
    return sol.x, cov, r


def measure_odometry(rec: Recording, p: RobotParams, world: World | None) -> Odometry | None:
    """The robot's odometry, or None without a tracker, on a bench, or with under MIN_WINDOWS windows."""
    if rec.pose is None or rec.bench:
        return None
    m, times = _window_motions(rec, p, world)
    if len(m) < MIN_WINDOWS:
        return None
    k0 = per_count(p)
    x0 = np.array([k0[0], k0[1], p.half_axle])
    x, _cov, r = _fit(m, x0, (1e-3, 1e-2))
    for _ in range(2):  # weigh each equation by its own scatter, and leave out the windows far off the fit
        scale = np.maximum(1.4826 * np.median(np.abs(r - np.median(r, axis=0)), axis=0), (1e-5, 1e-4))
        keep = (np.abs(r) <= OUTLIER * scale).all(axis=1)
        m, times = m[keep], times[keep]
        if len(m) < MIN_WINDOWS:
            return None
        x, cov, r = _fit(m, x, (float(scale[0]), float(scale[1])))
    dof = max(1, 2 * len(m) - 3)
    se = np.sqrt(np.diag(cov) * float((r / scale).ravel() @ (r / scale).ravel()) / dof)
    return Odometry((float(x[0] / k0[0] - 1.0), float(x[1] / k0[1] - 1.0)),
                    (float(se[0] / k0[0]), float(se[1] / k0[1])),
                    float(x[2] / p.half_axle - 1.0), float(se[2] / p.half_axle), len(m),
                    (float(times[0, 0]), float(times[-1, 1])))
