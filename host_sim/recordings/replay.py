"""Replay a recording's inputs open loop from any recorded state: one robot, or N parameter sets at once.

`replay` runs one SimRobot, `replay_batch` a BatchSim; both read the recording through
`replay_inputs`, the one place that says what its timing, emitter power and start mean.
The state at row k comes from the recording alone (tracker pose, wheel angles and speeds
from the encoders, a slide the tracker saw: `sliding_rows`), so a simulator recording
replayed from row 0 repeats the run exactly (docs/recordings.md, docs/diagnosis.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from host_sim.physics import dynamics, motors
from host_sim.sensors import ir_sensor
from host_sim.robot.batch import BatchResult, BatchSim, robot_params
from host_sim.controller.hardware_io import Actuate
from host_sim.robot.sim_robot import SimRobot
from host_sim.physics.dynamics import ParamBatch
from host_sim.physics.params import DRIVES, RobotParams
from host_sim.recordings.recording import Recording
from host_sim.physics.world import World


class ReplayError(ValueError):
    pass


@dataclass
class ReplayResult:
    t: np.ndarray  # (n,) s
    enc: np.ndarray  # (n, 2) simulated encoder ticks
    pose: np.ndarray  # (n, 3) simulated pose of C
    ir_on: np.ndarray  # (n, S) for the S pairs of p.ir_bearings; (n, 0) for the drive alone (replay_drive)
    ir_amb: np.ndarray  # (n, S); (n, 0) for the drive alone
    start: int  # the recording row it started from


@dataclass
class ReplayInputs:
    """What rows start..stop-1 of a recording gave the robot, and how time passed between them."""

    cmd: np.ndarray  # (T, 2) commands in the recording's drive's unit (A for current), held from row j to row j + 1
    period: np.ndarray  # (T,) s from row j to row j + 1
    emitter: np.ndarray  # (T,) % emitter pulse width in force for row j's on-reading
    t0: float  # time of row start
    at_rest: bool  # the robot was at rest at row start (a simulator run's first row)


def starts_at_rest(rec: Recording, k: int) -> bool:
    """The simulator starts every run at rest; a robot's recording says nothing of it."""
    return k == 0 and rec.source == "simulator"


def replay_inputs(rec: Recording, start: int = 0, stop: int | None = None,
                  nominal_timing: bool | None = None) -> ReplayInputs:
    """The one reading of a recording's timing, emitter power and start, for every replay.

    Timing: whole nominal sample periods per row for fixed-step simulator
    recordings (nominal_timing None; two where a row was lost), else the
    recorded times (the last row lasts one sample period).  Emitter power: the recording's own
    emitter_pct column; for version-1 recordings without it, the sidecar's
    emitter_pct (default 60 %), 0 for a simulator run's first row (its
    emitters are not on until the first actuation).
    """
    stop = len(rec) if stop is None else stop
    if not 0 <= start < stop <= len(rec):
        raise ReplayError(f"rows {start}..{stop} do not fit the recording (0..{len(rec)})")
    if nominal_timing is None:
        nominal_timing = rec.source == "simulator" and rec.meta.get("mode") == "fixed"
    n = stop - start
    period = np.full(n, rec.sample_period)
    inner = np.arange(start, stop) + 1 < len(rec)
    recorded = np.diff(rec.t[start:min(stop + 1, len(rec))])[: int(inner.sum())]
    if not nominal_timing:
        period[inner] = recorded
    else:  # the exact period, not the times' rounding; a row the checks found missing leaves a step of two
        period[inner] = np.maximum(np.round(recorded / rec.sample_period), 1.0) * rec.sample_period
    if rec.emitter is not None:
        emitter = rec.emitter[start:stop].astype(float)
    else:
        emitter = np.full(n, float(rec.meta.get("emitter_pct", 60)))  # type: ignore[arg-type]
        if starts_at_rest(rec, start):
            emitter[0] = 0.0
    return ReplayInputs(rec.cmd[start:stop].astype(float), period, emitter, float(rec.t[start]),
                        starts_at_rest(rec, start))


def with_drive(rec: Recording, params: Any) -> Any:
    """params (a RobotParams, a sequence of them or a ParamBatch) with the drive the recording's commands are for
    (its sidecar's drive block: docs/recordings.md), whatever they said."""
    code = float(DRIVES.index(rec.drive))
    if isinstance(params, RobotParams):
        return params if params.drive == code else params.replace(drive=code)
    if isinstance(params, ParamBatch):
        if np.all(params.drive == code):
            return params
        return ParamBatch({k: (np.full(params.n, code) if k == "drive" else getattr(params, k)) for k in params.names})
    return [with_drive(rec, p) for p in params]


def state_at(rec: Recording, k: int, p: RobotParams) -> tuple[tuple[float, ...], tuple[float, float]]:
    """(q, v) of the model at row k, from the recording alone (on a bench without a tracker: at the origin)."""
    if rec.pose is None and rec.bench:
        theta = [motors.encoder_angle(int(rec.enc[k, i]), p, i) for i in range(2)]
        v = (0.0, 0.0) if starts_at_rest(rec, k) else wheel_speeds_at(rec, k, p)
        return dynamics.q_from_axle_pose(0.0, 0.0, 0.0, p, theta[0], theta[1]), (float(v[0]), float(v[1]))
    if rec.pose is None:
        raise ReplayError("replay from a recorded state needs the tracker pose (x, y, phi columns), "
                          "and this recording has none")
    n = len(rec)
    if not 0 <= k < n:
        raise ReplayError(f"row {k} is outside the recording (0..{n - 1})")
    x, y, phi = (float(v) for v in rec.pose[k])
    if starts_at_rest(rec, k):
        theta = [0.0, 0.0]  # the simulator starts every run at rest, the wheels at angle 0
    else:  # the middle of the recorded tick: the best guess, and never the tick below
        theta = [motors.encoder_angle(int(rec.enc[k, i]), p, i) for i in range(2)]
    v = (0.0, 0.0) if starts_at_rest(rec, k) else wheel_speeds_at(rec, k, p)
    q = dynamics.q_from_axle_pose(x, y, phi, p, theta[0], theta[1])
    return q, (float(v[0]), float(v[1]))


def state_or_origin(rec: Recording, k: int, p: RobotParams) -> tuple[tuple[float, ...], tuple[float, float]]:
    """state_at, or where the tracker has no pose at row k, the wheels' state at the origin (of an empty
    world: the encoders alone say nothing of where the robot is)."""
    if rec.tracked(k):
        return state_at(rec, k, p)
    theta = [motors.encoder_angle(int(rec.enc[k, w]), p, w) for w in range(2)]
    q = dynamics.q_from_axle_pose(0.0, 0.0, 0.0, p, theta[0], theta[1])
    v = (0.0, 0.0) if starts_at_rest(rec, k) else wheel_speeds_at(rec, k, p)
    return q, (float(v[0]), float(v[1]))


# A robot slides at a row when the tracker's velocity of C differs from what its wheels, rolling, would
# give by more than SLIDE_NOISE times the recording's own spread of that difference (the tracker's noise:
# the robot rolls most of the time) plus SLIDE_RELATIVE of the faster rim's speed (a wheel a few % larger
# than the twin's is not a slide), and by at least SLIDE_FLOOR (a simulator's exact tracker).
SLIDE_NOISE = 6.0
SLIDE_RELATIVE = 0.15
SLIDE_FLOOR = (0.01, 0.01, 0.1)  # m/s, m/s, rad/s: u, l, omega
SLOPE_ROWS = 2  # both velocities: the least-squares slope over rows k - 2 .. k + 2 (fewer at the ends)


def _slopes(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(n, m) the least-squares slope of each column of y (n, m) over SLOPE_ROWS rows either side (fewer
    at the ends; 0 where the times repeat)."""
    n, width = len(t), 2 * SLOPE_ROWS + 1
    out = np.zeros(y.shape)
    inner = range(SLOPE_ROWS, n - SLOPE_ROWS) if n >= width else range(0)
    if len(inner):
        tw = np.lib.stride_tricks.sliding_window_view(t, width)  # (K, width)
        yw = np.lib.stride_tricks.sliding_window_view(y, width, axis=0)  # (K, m, width)
        dt = tw - tw.mean(axis=1, keepdims=True)
        den = (dt * dt).sum(axis=1)
        num = np.einsum("kw,kmw->km", dt, yw - yw.mean(axis=2, keepdims=True))
        out[SLOPE_ROWS:n - SLOPE_ROWS] = num / np.where(den > 0, den, np.inf)[:, None]
    edges = [*range(SLOPE_ROWS), *range(n - SLOPE_ROWS, n)] if len(inner) else range(n)
    for k in edges:
        lo, hi = max(k - SLOPE_ROWS, 0), min(k + SLOPE_ROWS + 1, n)
        d = t[lo:hi] - t[lo:hi].mean()
        if float(d @ d) > 0:
            out[k] = d @ (y[lo:hi] - y[lo:hi].mean(axis=0)) / float(d @ d)
    return out


def tracked_velocity(rec: Recording) -> np.ndarray:
    """(n, 3) (u, l, omega) of C at every row from the tracker: u along the heading, l to its left."""
    assert rec.pose is not None
    slope = _slopes(rec.t, np.column_stack([rec.pose[:, 0], rec.pose[:, 1], np.unwrap(rec.pose[:, 2])]))
    c, s = np.cos(rec.pose[:, 2]), np.sin(rec.pose[:, 2])
    return np.column_stack([c * slope[:, 0] + s * slope[:, 1], c * slope[:, 1] - s * slope[:, 0], slope[:, 2]])


def rolling_velocity(rec: Recording, p: RobotParams) -> np.ndarray:
    """(n, 3) (u, l, omega) of C at every row if the wheels rolled as the encoders turned (smoothed as
    tracked_velocity, so that the two differ by a slide, not by their bandwidths)."""
    angle = np.column_stack([rec.enc[:, w] * (2 * math.pi / motors.ticks_per_rev(p, w)) for w in range(2)])
    speed = _slopes(rec.t, angle)
    rim_l = (p.wheel_radius + p.wheel_radius_delta_l) * speed[:, 0]
    rim_r = (p.wheel_radius + p.wheel_radius_delta_r) * speed[:, 1]
    return np.column_stack([0.5 * (rim_l + rim_r), 0.0 * rim_l, 0.5 * (rim_r - rim_l) / p.half_axle])


def sliding_rows(rec: Recording, p: RobotParams) -> tuple[np.ndarray, np.ndarray]:
    """(slides (n,) bool, body (n, 3)): the rows where the tracker says the robot slides over the floor,
    and the tracked (u, l, omega) of C at every row, which a replay started there gives its robot.

    A replay started at rest or rolling where the robot slid (braking on ice: the wheels stopped, the body
    still going; or pressed into a wall, the wheels turning, the body still) starts a way off the truth.
    Without a tracker, or on a bench, nothing slides."""
    n = len(rec)
    if rec.pose is None or n < 2 * SLOPE_ROWS + 1 or rec.bench:
        return np.zeros(n, dtype=bool), np.zeros((n, 3))
    body = tracked_velocity(rec)
    rolling = rolling_velocity(rec, p)
    diff = body - rolling
    noise = 1.4826 * np.median(np.abs(diff - np.median(diff, axis=0)), axis=0)
    rim = np.abs(rolling[:, 0]) + p.half_axle * np.abs(rolling[:, 2])  # the faster rim's speed
    scale = np.array([1.0, 1.0, 1.0 / p.half_axle])
    limit = np.maximum(SLIDE_NOISE * noise[None, :] + SLIDE_RELATIVE * rim[:, None] * scale[None, :],
                       np.array(SLIDE_FLOOR)[None, :])
    return (np.abs(diff) > limit).any(axis=1), body


def wheel_speeds_at(rec: Recording, k: int, p: RobotParams) -> tuple[float, float]:
    """Wheel speeds (rad/s) at row k from the encoder counts around it: second-order differences, central
    inside and one-sided (three rows) at the ends.

    A two-row difference at the first row is the mean speed over the first period, not the speed at its
    start: a robot starting from rest would start the twin already moving (and, with the drive's long time
    constant, keep it ahead for seconds).  The one-sided quadratic is exact for a constant acceleration.
    """
    n = len(rec)
    if n < 2:
        return (0.0, 0.0)
    if 0 < k < n - 1 or n == 2:
        lo, hi = (k - 1, k + 1) if 0 < k < n - 1 else (0, 1)
        dt = float(rec.t[hi] - rec.t[lo])
        coef = {lo: -1.0 / dt, hi: 1.0 / dt} if dt > 0 else {}
    else:
        rows = (k, k + 1, k + 2) if k == 0 else (k, k - 1, k - 2)
        coef = _one_sided(*(float(rec.t[j]) for j in rows), rows)
    if not coef:
        return (0.0, 0.0)
    return tuple(sum(c * float(rec.enc[j, w]) for j, c in coef.items()) * (2 * math.pi / motors.ticks_per_rev(p, w))
                 for w in range(2))  # type: ignore[return-value]


def _one_sided(t0: float, t1: float, t2: float, rows: tuple[int, int, int]) -> dict[int, float]:
    """Weights of rows (k, k +- 1, k +- 2) for the slope at t0 of the parabola through the three ({} if times repeat)."""
    h1, h2 = t1 - t0, t2 - t0
    if h1 == 0 or h2 == 0 or h1 == h2:
        return {}
    return {rows[0]: -(h1 + h2) / (h1 * h2), rows[1]: h2 / (h1 * (h2 - h1)), rows[2]: -h1 / (h2 * (h2 - h1))}


def replay(rec: Recording, p: RobotParams, world: World, start: int = 0, stop: int | None = None,
           substeps: int = 8, seed: int | None = None, nominal_timing: bool | None = None,
           exact_sensors: bool = False) -> ReplayResult:
    """Feed rows start..stop-1's current references to one model robot from the state at `start`.

    Timing and emitter power as `replay_inputs` reads them.
    seed: the sensor noise seed (None: noise-free sensors).

    The inputs are open loop, so the IR ring is read for all rows at once
    after the physics (vectorised, several times faster).  exact_sensors=True
    reads it row by row as the simulation did instead, drawing the noise in
    the same order: a simulator recording then replays bit for bit.
    """
    inputs = replay_inputs(rec, start, stop, nominal_timing)
    p = with_drive(rec, p)
    robot = SimRobot(world, p, seed=seed, noise=seed is not None, bench=rec.bench)
    robot.q, robot.v = state_at(rec, start, p)
    slides, body = sliding_rows(rec, p)
    if slides[start] and not inputs.at_rest:
        robot.slip = tuple(float(x) for x in body[start])  # type: ignore[assignment]
    robot.t = inputs.t0
    n = len(inputs.cmd)
    enc = np.zeros((n, 2), dtype=np.int64)
    pose = np.zeros((n, 3))
    ir_on = np.zeros((n, len(p.ir_bearings)), dtype=np.int64)
    ir_amb = np.zeros((n, len(p.ir_bearings)), dtype=np.int64)
    t = np.zeros(n)
    for j in range(n):
        t[j] = robot.t
        pose[j] = robot.pose
        robot.emitter_pct = int(inputs.emitter[j])
        if exact_sensors:
            s = robot.sense()
            ir_on[j] = s.adc_on
            ir_amb[j] = s.adc_off
        enc[j] = robot.encoder_ticks()
        left, right = inputs.cmd[j]
        if p.drive:  # not a current in mA: the command as it stands, in its drive's unit
            robot.i_ref = (float(left), float(right))
        else:
            robot.actuate(Actuate(round(left * 1000), round(right * 1000), robot.emitter_pct))
        h = float(inputs.period[j]) / substeps
        for _ in range(substeps):
            robot.advance(h)
    if not exact_sensors:
        ir_amb, ir_on = ir_sensor.read_sensors(world, pose, inputs.emitter, t, p, robot.rng, track=True)
    return ReplayResult(t, enc, pose, ir_on, ir_amb, start)


SEED_ROWS = 6  # recorded commands before a start that a delayed actuator may still be carrying out (0.2 s)


def replay_batch(rec: Recording, params_list: Any, start: int = 0, *, stop: int | None = None,
                 world: World | None = None, substeps: int = 8, sensors: bool = True,
                 seed: int | np.random.Generator | None = None, base: RobotParams | None = None,
                 nominal_timing: bool | None = None) -> BatchResult:
    """`replay` for N parameter sets at once (host_sim.robot.batch.BatchSim, vectorised).

    Every robot starts in the state the recording has at row `start` (state_at
    with that robot's parameters) and is fed the recorded current references.
    params_list: a RobotParams, a sequence of N, or a ParamBatch (with `base`).
    world: default the recording's own (its sidecar), no walls when it has none or no tracker placed the
    robot at `start` (state_or_origin: the robot then starts at the origin).
    """
    from host_sim.physics.world import world_from_dict

    inputs = replay_inputs(rec, start, stop, nominal_timing)
    tracked = rec.tracked(start)
    if world is None and tracked and isinstance(rec.meta.get("world"), dict):
        world = world_from_dict(rec.meta["world"], f"{rec.path or 'recording'} (sidecar world)")
    params, robots = robot_params(with_drive(rec, params_list), base)
    states = [state_or_origin(rec, start, p) for p in robots]
    q = np.array([s[0] for s in states], dtype=float).reshape(-1, 5)
    v = np.array([s[1] for s in states], dtype=float).reshape(-1, 2)
    sim = BatchSim(world, params, q=q, v=v, t=inputs.t0, base=base, cycle_s=rec.sample_period, substeps=substeps,
                   bench=rec.bench)
    slides, body = sliding_rows(rec, robots[0])
    if slides[start] and not inputs.at_rest:
        sim.start_sliding(np.ones(sim.n, dtype=bool), np.tile(body[start], (sim.n, 1)))
    if start > 0 and SEED_ROWS:  # actuator_delay: the recorded commands before `start` are still on their way
        before = replay_inputs(rec, max(start - SEED_ROWS, 0), start, nominal_timing)
        sim.seed_commands(inputs.t0 - np.cumsum(before.period[::-1])[::-1], before.cmd)
    result = sim.run_inputs(inputs.cmd, substeps=substeps, sensors=sensors, seed=seed, period=inputs.period,
                            emitter=inputs.emitter)
    result.start = start
    return result


def replay_drive(rec: Recording, p: RobotParams, start: int = 0, substeps: int = 8) -> ReplayResult:
    """The drive alone, open loop in an empty world from the state at `start` (state_or_origin): what a
    recording without a world (or without a tracker) can be compared on, the encoders (and the pose)."""
    res = replay_batch(rec, p, start, world=None, substeps=substeps, sensors=False)
    n = res.enc.shape[0]
    t = res.t if res.t.ndim == 1 else res.t[:, 0]
    empty = np.zeros((n, 0), dtype=np.int64)
    return ReplayResult(t, res.enc[:, 0], res.pose[:, 0], empty, empty.copy(), start)
