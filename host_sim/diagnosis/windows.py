"""Multiple shooting: the twin replays a recording in short windows, each from the recorded state.

Each window's twin starts LEAD_ROWS rows early from the recorded state and runs open loop on the recorded
current references; all windows run at once on the batch path (host_sim.robot.batch.BatchSim).  Without a
tracker every window starts at the origin of an empty world.  See docs/diagnosis.md, "Windows".
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from host_sim.sensors import ir_sensor
from host_sim.robot.batch import IR_FIELDS, SUBSTEPS, BatchSim, robot_params, step_parts
from host_sim.physics.motors import ticks_per_rev
from host_sim.physics.params import RobotParams
from host_sim.recordings.checks import LATE_PERIODS
from host_sim.recordings.recording import Recording
from host_sim.recordings.replay import SEED_ROWS, ReplayError, replay_inputs, sliding_rows, state_or_origin
from host_sim.physics.world import World

DEFAULT_SECONDS = (1.0, 5.0)
# The windows start this far into the recording, so that none starts on a whole second.  The identification
# manoeuvre changes its set-points on whole seconds (and on multiples of 0.6 s), and a window that starts
# on a step starts its twin at a wheel speed (a central difference of the encoders) that already holds the
# step's acceleration: the twin ran ahead, and fits read a robot 4 % heavier where none was.
OFFSET_S = 0.5
POSE_DOUBT_RAD = 0.02  # a tracker's heading is good to a few tenths of a degree; its position, at the
# sensors' range (~0.1 m), to about as much: a reading that changes this much within 1.1 degrees is not judged
POSE_DOUBT_COUNTS = 50.0
CONTACT_MARGIN = 0.005  # m beyond the body's radius: within it, the robot touches a wall
# The datasheet's farthest calibration point (physics/params.py: ~28 counts at 25 cm): beyond it the IR law is
# an extrapolation (channels.IR_EXTRAPOLATED_TOLERANCE).
IR_CALIBRATED_RANGE = 0.25
FACING_COS = -0.17  # a sensor whose axis is within 100 degrees of the way to a touched wall faces it
# The twin steps SUBSTEPS times a period; a robot that slides over the floor (ice) spins its wheels up and
# down within milliseconds, which 5 ms steps blur, and a fit then reads the blur as an actuator delay.  So
# where the tracker sees slides in SLIDING_SHARE of the windows away from the walls, FINE_SUBSTEPS
# (tests/test_slides.py::test_windows_step_finer_where_the_robot_slides).
FINE_SUBSTEPS = 16
SLIDING_SHARE = 0.05
# Each window's twin starts LEAD_ROWS rows early and replays them (run_windows), so that it enters the window
# with what those rows set going: a speed that holds the last command's acceleration (the encoders' central
# difference at a command step is off by B * di * T / 4, B the wheel's acceleration per ampere), a gear's gap,
# a slide, the commands on their way through a delay.  Its wheel speeds are then set right by the slope of
# the counts' residual over the lead-in.  Only rows before the window are used: a held-out window stays held
# out (tests/test_diagnosis.py::test_each_window_twin_enters_from_its_lead_in).
LEAD_ROWS = 6


@dataclass
class Windows:
    """W windows of T rows each: window w covers recording rows start[w] .. start[w] + T - 1."""

    start: np.ndarray  # (W,) first row of each window
    rows: int  # T, rows per window
    held_out: np.ndarray  # (W,) bool: judged only, never fitted on
    substeps: int = SUBSTEPS  # the twin's steps per period in every window (judge_slides)
    sliding: np.ndarray | None = None  # (W,) bool: the robot slides where the window's twin starts (judge_slides)
    body: np.ndarray | None = None  # (W, 3) the tracked (u, l, omega) of C where each window's twin starts
    lead: int = LEAD_ROWS  # rows the twin replays before each window (0: it starts on the window's first row)
    lead_slides: np.ndarray | None = None  # (W,) bool: the tracker sees the robot slide in the lead-in (judge_slides)
    left_out: int = 0  # windows of the grid left out: their twin would live through a late or lost row
    # initial_states' answers, by rows and the fields they read: every fit evaluates the same windows again
    states: dict[tuple[Any, ...], Any] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        if len(self.start) and int(np.min(self.start)) < self.lead:
            raise ValueError(f"a window starts at row {int(np.min(self.start))}, before its {self.lead} rows of "
                             f"lead-in: start the windows later or shorten the lead")

    def select(self, keep: np.ndarray) -> Windows:
        """These windows only (keep: (W,) bool or indices), with what judge_slides found of each."""
        return Windows(self.start[keep], self.rows, self.held_out[keep], self.substeps,
                       None if self.sliding is None else self.sliding[keep],
                       None if self.body is None else self.body[keep], self.lead,
                       None if self.lead_slides is None else self.lead_slides[keep], self.left_out)

    @property
    def twin_start(self) -> np.ndarray:
        """(W,) the row each window's twin starts on: `lead` rows before the window."""
        return self.start - self.lead

    @property
    def lead_index(self) -> np.ndarray:
        """(W, lead + 1) the rows of each window's lead-in and the window's first."""
        return self.twin_start[:, None] + np.arange(self.lead + 1)[None, :]

    @property
    def index(self) -> np.ndarray:
        """(W, T) recording row of every window row."""
        return self.start[:, None] + np.arange(self.rows)[None, :]

    def __len__(self) -> int:
        return len(self.start)


def stratified_held_out(windows: Windows, times: np.ndarray, spans: list[tuple[float, float]],
                        hold_out_every: int = 3) -> np.ndarray:
    """The held-out windows, with a share of those that show a located mismatch (they overlap `spans`, s;
    times: the recording's t).  make_windows holds out every third window whatever it shows; a mismatch
    seen in a few windows only (a weak motor that shows when the firmware backs out of a stall, twice in
    90 s) can then fall wholly in the training windows, and no fit, however right, improves the held-out
    ones.  If the split holds out fewer of these windows than one in `hold_out_every` (at least one of
    two), it is redrawn apart for them and for the rest, each in time order: the evidence is split
    between fitting and judging as the whole run is.  Otherwise it is kept."""
    t0 = times[windows.start]
    t1 = times[windows.start + windows.rows - 1]
    shows = np.zeros(len(windows), dtype=bool)
    for a, b in spans:
        shows |= (t0 < b) & (t1 > a)
    n = int(shows.sum())
    wanted = max(1, n // hold_out_every) if n >= 2 else 0  # what every third gives a run that shows it all
    if int((windows.held_out & shows).sum()) >= wanted:
        return windows.held_out
    held = np.zeros(len(windows), dtype=bool)
    evidence, rest = np.flatnonzero(shows), np.flatnonzero(~shows)
    held[evidence[np.arange(n) % hold_out_every == 1]] = True  # the second, fifth, ...: one of two is judged
    held[rest[np.arange(len(rest)) % hold_out_every == hold_out_every - 1]] = True
    return held


def judge_slides(rec: Recording, windows: Windows, p: RobotParams, contact: np.ndarray) -> None:
    """Set the windows that start with the robot sliding (replay.sliding_rows, with p's wheels: judged once,
    so that no fit moves a window between sliding and rolling) and the twin's steps per period:
    FINE_SUBSTEPS if the robot slides in SLIDING_SHARE of the windows away from the walls (contact: (W,)
    bool, those touching one), else SUBSTEPS."""
    slides, body = sliding_rows(rec, p)
    windows.sliding = slides[windows.twin_start]  # windows start OFFSET_S in: never at a simulator run's rest
    windows.body = body[windows.twin_start]
    windows.lead_slides = slides[windows.lead_index].any(axis=1)
    free = ~contact
    sliding = slides[windows.index].any(axis=1) & free
    windows.substeps = FINE_SUBSTEPS if free.any() and sliding.sum() >= SLIDING_SHARE * free.sum() else SUBSTEPS


def make_windows(rec: Recording, seconds: float, hold_out_every: int = 3) -> Windows:
    """Back-to-back windows of `seconds` over the recording from OFFSET_S on, but those whose twin would live
    through a late or lost row (late_rows); every `hold_out_every`-th is held out.

    Held-out windows are interleaved in time (windows 2, 5, 8, ...), so the
    fit is judged on every part of the run, not only on its end.
    """
    start, rows, lead, late = _grid(rec, seconds)
    if late.all():
        raise ReplayError(f"every window of {seconds:g} s holds a late or lost row (over {LATE_PERIODS:g} periods "
                          f"after the row before): the twin cannot follow the robot through a row whose command "
                          f"is not recorded")
    start = start[~late]
    held_out = (np.arange(len(start)) % hold_out_every) == hold_out_every - 1
    return Windows(start, rows, held_out, lead=lead, left_out=int(late.sum()))


def can_lay(rec: Recording, seconds: float) -> bool:
    """make_windows lays at least one window of `seconds` over the recording."""
    try:
        return not _grid(rec, seconds)[3].all()
    except ReplayError:
        return False


def grid_starts(rec: Recording, seconds: float) -> tuple[np.ndarray, int, int]:
    """(each window's first row, rows per window, the rows before the first): the back-to-back windows of
    `seconds` from OFFSET_S on, every one's last row with a row after it, which closes its period."""
    rows = max(2, int(round(seconds / rec.sample_period)))
    offset = int(OFFSET_S / rec.sample_period)  # rounded down: 12 rows of 40 ms, never a multiple of 0.6 s
    return np.arange(offset, len(rec) - rows, rows), rows, offset


def _grid(rec: Recording, seconds: float) -> tuple[np.ndarray, int, int, np.ndarray]:
    """(each window's first row, rows per window, lead-in rows, (W,) bool: the window holds a late row)."""
    start, rows, offset = grid_starts(rec, seconds)
    if not len(start):
        raise ReplayError(f"the recording has {len(rec)} rows, too short for one window of {seconds:g} s "
                          f"({rows} rows at {rec.sample_period * 1000:g} ms, from {offset * rec.sample_period:g} s)")
    lead = min(LEAD_ROWS, offset)
    return start, rows, lead, late_rows(rec, start - lead, start + rows)


def late_rows(rec: Recording, first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """(W,) bool: a step from row first[w] to row last[w] lasts over LATE_PERIODS of the recording's periods
    (the median step).  A late row's command held for its whole step, or a lost row's command not recorded:
    the recording cannot say which, and a twin that holds the command the robot changed diverges for the
    speed's memory (tests/test_diagnosis.py::test_a_window_that_holds_a_lost_row_is_left_out)."""
    steps = np.diff(rec.t)
    if not len(steps):
        return np.zeros(len(first), dtype=bool)
    long_step = np.concatenate([[0], np.cumsum(steps > LATE_PERIODS * float(np.median(steps)))])
    return long_step[last] > long_step[first]


@dataclass
class WindowRun:
    """The twin's readings in every window (index [w, j] = recording row windows.index[w, j]).

    With N parameter sets, axis 1 is the set: arrays (W, N, T, ...)."""

    enc: np.ndarray  # (W, N, T, 2) encoder counts, unquantised (float): smooth in the parameters, for fitting
    pose: np.ndarray  # (W, N, T, 3) pose of C
    vbat: np.ndarray | None = None  # (W, N, T) V, the battery voltage the twin senses


def initial_states(rec: Recording, rows: np.ndarray, p: RobotParams) -> tuple[np.ndarray, np.ndarray]:
    """(q (W, 5), v (W, 2)) at the given rows: replay.state_or_origin, the origin standing in for a missing tracker."""
    q = np.empty((len(rows), 5))
    v = np.empty((len(rows), 2))
    for i, k in enumerate(rows):
        q[i], v[i] = state_or_origin(rec, int(k), p)
    return q, v


def _states(windows: Windows, rec: Recording, rows: np.ndarray, p: RobotParams) -> tuple[np.ndarray, np.ndarray]:
    """initial_states, kept in windows.states: a state reads of p only the centre of mass's offset and the
    encoders' counts per turn (replay.state_at), so the parameter sets of a fit share it
    (tests/test_diagnosis.py::test_window_states_are_kept_by_what_they_read).  Read-only arrays."""
    key = (rows.tobytes(), p.com_offset, ticks_per_rev(p, 0), ticks_per_rev(p, 1))
    kept = windows.states.get(key)
    if kept is None or kept[0] is not rec:
        q, v = initial_states(rec, rows, p)
        q.flags.writeable = v.flags.writeable = False
        kept = windows.states[key] = (rec, q, v)
    return kept[1], kept[2]


# The IR model's own fields (batch.IR_FIELDS named ir_*, and the leakage; not the body's radius, which meets the
# walls): a window run, which reads no sensor, is the same for robots that differ in these alone
# (tests/test_diagnosis.py::test_a_twin_that_differs_in_its_sensors_alone_is_run_once).
SENSOR_FIELDS = tuple(f for f in IR_FIELDS if f.startswith("ir_") or f == "ambient_leakage")


def run_key(p: RobotParams) -> str:
    """What run_windows reads of p: p but its SENSOR_FIELDS, by repr (floats round-trip exactly)."""
    return repr(tuple(getattr(p, f.name) for f in fields(p) if f.name not in SENSOR_FIELDS))


def run_windows(rec: Recording, windows: Windows, params: Any, world: World | None, *,
                base: RobotParams | None = None, substeps: int | None = None) -> WindowRun:
    """Replay every window for every parameter set (physics only; see sensors_on_track): in one batch
    per set of step parts (batch.step_parts), so that a few robots with a gear's play do not slow the rest.

    params: one RobotParams, a sequence of N, or a ParamBatch of N (with base).
    world: the walls (without a tracker the twin drives in an empty world).
    """
    groups = by_step_parts(params) if isinstance(params, (list, tuple)) else []
    if len(groups) > 1:
        runs = [_run_windows(rec, windows, [params[i] for i in ix], world, base, substeps) for ix in groups]
        order = np.argsort(np.concatenate(groups))
        return WindowRun(*(np.concatenate([getattr(run, f) for run in runs], axis=1)[:, order]
                           for f in ("enc", "pose", "vbat")))
    return _run_windows(rec, windows, params, world, base, substeps)


def by_step_parts(robots: list[RobotParams] | tuple[RobotParams, ...]) -> list[list[int]]:
    """The robots' indices grouped by the parts of the step they set going (batch.step_parts), in order."""
    groups: dict[tuple[bool, ...], list[int]] = {}
    for i, p in enumerate(robots):
        groups.setdefault(step_parts(p), []).append(i)
    return list(groups.values())


def _run_windows(rec: Recording, windows: Windows, params: Any, world: World | None, base: RobotParams | None,
                 substeps: int | None) -> WindowRun:
    substeps = windows.substeps if substeps is None else substeps
    batch_params, robots = robot_params(params, base)
    n_sets = len(robots)
    inputs = replay_inputs(rec)
    idx = windows.index  # (W, T)
    n_win, n_rows = idx.shape
    first = windows.twin_start
    # Robot w * N + s of the batch is window w with parameter set s.
    q = np.empty((n_win, n_sets, 5))
    v = np.empty((n_win, n_sets, 2))
    on_track = np.empty((n_win, n_sets, 3))  # where each window's twin stands on its first row
    cold = np.empty((n_win, n_sets, 2))  # and its wheel speeds from the encoders there
    for s, p in enumerate(robots):
        q[:, s], v[:, s] = _states(windows, rec, first, p)
        if windows.lead:
            q_k, cold[:, s] = _states(windows, rec, windows.start, p)
            on_track[:, s] = q_k[:, :3]
    per_robot = robots[0] if n_sets == 1 else [p for _w in range(n_win) for p in robots]
    sim = BatchSim(world if rec.pose is not None else None, per_robot, q=q.reshape(-1, 5), v=v.reshape(-1, 2),
                   base=base, substeps=substeps, bench=rec.bench)
    # Each window's twin lives its own rows' recorded durations, a late row (the board's loop overran) or a
    # missed cycle as long as it lasted (tests/test_diagnosis.py::test_a_board_whose_loop_overran_matches).
    period = np.repeat(inputs.period[idx].T, n_sets, axis=1)  # (T, W * N)
    # A set-point robot's own loop has been holding its wheels: its twin does not wind up from 0 in each window
    # (tests/test_simulation.py::test_sim_runs_a_wheel_speed_robot_and_its_recording_replays).
    sim.hold_speeds()
    sim.loop_counts_whole = False  # the loop's twin sees the counts' mean: its residuals smooth in its parameters
    _seed_commands(sim, rec, inputs.cmd, first, n_sets)
    sim.engage_gears(np.repeat(_last_push(inputs.cmd, first), n_sets, axis=0))
    if windows.sliding is not None and windows.body is not None:  # where the tracker saw the robot slide
        sim.start_sliding(np.repeat(windows.sliding, n_sets), np.repeat(windows.body, n_sets, axis=0))
    tpr = _ticks_per_rev(robots, n_win)
    if windows.lead:
        _lead_in(rec, windows, sim, inputs, n_sets, tpr, substeps, world, robots[0], cold.reshape(-1, 2))
        sim.place(on_track.reshape(-1, 3))  # the window starts on the recorded pose, as without a lead-in
    cmd = np.repeat(inputs.cmd[idx.T][:, :, None, :], n_sets, axis=2).reshape(n_rows, n_win * n_sets, 2)
    res = sim.run_inputs(cmd, substeps=substeps, sensors=False, period=period)
    assert res.theta is not None and res.vbat is not None
    counts = res.theta * (tpr / (2 * np.pi))
    enc = counts.reshape(n_rows, n_win, n_sets, 2).transpose(1, 2, 0, 3)
    pose = res.pose.reshape(n_rows, n_win, n_sets, 3).transpose(1, 2, 0, 3)
    return WindowRun(enc, pose, res.vbat.reshape(n_rows, n_win, n_sets).transpose(1, 2, 0))


def _lead_in(rec: Recording, windows: Windows, sim: BatchSim, inputs: Any, n_sets: int, tpr: np.ndarray,
             substeps: int, world: World | None, p: RobotParams, cold: np.ndarray) -> None:
    """Replay the `lead` rows before every window (LEAD_ROWS), then set each twin's wheel speeds right by the
    least-squares slope of the counts' residual over them (the rows before the window and its first).  What
    else the twin carries into the window (a gear's gap, a slide, the commands in a delay) it keeps.

    The slope is a speed error the wheels carry on only where they roll free.  A wheel spinning on ice has
    its speed set by the floor within milliseconds: where the recorded robot or its twin slides, the twin
    enters as the lead-in leaves it
    (tests/test_slides.py::test_the_lead_in_counts_steer_the_twin_only_where_it_rolls).  A lead-in at a wall
    starts the twin from a tracked pose that may be a millimetre into the wall, and its contact throws the
    wheels: where the recorded robot comes within CONTACT_MARGIN of a wall, or its twin touches one, the twin
    enters rolling at the wheel speeds the encoders give on the window's first row (`cold`, (W * N, 2)), as
    without a lead-in (tests/test_diagnosis.py::test_a_window_whose_lead_in_is_at_a_wall_starts_as_without_one)."""
    lead = windows.lead
    rows = windows.lead_index[:, :-1]  # (W, lead)
    n_win = len(windows)
    cmd = np.repeat(inputs.cmd[rows.T][:, :, None, :], n_sets, axis=2).reshape(lead, n_win * n_sets, 2)
    period = np.repeat(inputs.period[rows].T, n_sets, axis=1)  # (lead, W * N): each row's recorded duration
    theta = np.empty((lead + 1, n_win * n_sets, 2))
    slid = np.repeat(windows.lead_slides if windows.lead_slides is not None else np.zeros(n_win, bool), n_sets)
    walled = np.repeat(near_a_wall(rec, windows.lead_index, p, world), n_sets)
    for j in range(lead):
        res = sim.run_inputs(cmd[j:j + 1], substeps=substeps, sensors=False, period=period[j:j + 1])
        assert res.theta is not None
        theta[j] = res.theta[0]
        slid |= sim.slipping
        walled |= sim.in_contact | (res.collisions > 0)
    theta[lead] = sim.encoder_angles()
    twin = theta * (tpr / (2 * np.pi))  # (lead + 1, W * N, 2)
    seen = np.repeat(rec.enc[windows.lead_index.T], n_sets, axis=1)
    # the slope over the rows' recorded times: a late row in the lead-in is as long as it was
    times = np.repeat(rec.t[windows.lead_index.T], n_sets, axis=1)  # (lead + 1, W * N)
    times = times - times.mean(axis=0)
    slope = np.einsum("jr,jrw->rw", times, seen - twin) / (times * times).sum(axis=0)[:, None]  # counts per s
    dv = np.where((slid | walled)[:, None], 0.0, slope * (2 * np.pi) / tpr)
    v = np.where(walled[:, None], cold, sim.v + dv)
    if sim.rotor_speed is not None:  # a gear's motor side turns on with its wheel
        sim.rotor_speed = np.where(walled[:, None], cold, sim.rotor_speed + dv)
    sim.v = v
    sim.slipping &= ~walled


def near_a_wall(rec: Recording, rows: np.ndarray, p: RobotParams, world: World | None) -> np.ndarray:
    """(W,) bool: the tracker sees the robot within CONTACT_MARGIN of a wall in any of rows[w] ((W, K)
    recording rows); False throughout without a tracker or walls."""
    if rec.pose is None or world is None or not world.n_walls:
        return np.zeros(len(rows), dtype=bool)
    dist = world.nearest_wall(rec.pose[rows.reshape(-1), :2])[0]
    return np.asarray((dist.reshape(rows.shape) < p.body_radius + CONTACT_MARGIN).any(axis=1))


def _last_push(cmd: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(W, 2) the sign of each wheel's last non-zero recorded command before each window: the side its gear's
    backlash is closed on (with no current the gear stays where it was), 0 if none."""
    rows = np.arange(len(cmd))[:, None]
    last = np.maximum.accumulate(np.where(cmd != 0.0, rows, -1), axis=0)  # (n, 2) last non-zero row so far
    before = np.where(start[:, None] > 0, last[np.maximum(start - 1, 0)], -1)
    return np.where(before >= 0, np.sign(cmd[np.maximum(before, 0), [0, 1]]), 0.0)


def _seed_commands(sim: BatchSim, rec: Recording, cmd: np.ndarray, start: np.ndarray, n_sets: int) -> None:
    """The recorded commands of the rows before each window, as sent before the twin's start (actuator_delay),
    each at its recorded time before that start (the twin's clock reads 0 there)."""
    rows = start[None, :] - np.arange(SEED_ROWS, 0, -1)[:, None]  # (K, W)
    before = np.where(rows[..., None] >= 0, cmd[np.maximum(rows, 0)], 0.0)  # (K, W, 2)
    # rows before the recording's first: no command, at the nominal period before it
    at = np.where(rows >= 0, rec.t[np.maximum(rows, 0)], rec.t[0] + rows * rec.sample_period) - rec.t[start]
    sim.seed_commands(np.repeat(at, n_sets, axis=1), np.repeat(before, n_sets, axis=1))


def _ticks_per_rev(robots: list[RobotParams], n_win: int) -> np.ndarray:
    """(W * N, 2) counts per wheel turn of every batch robot (window-major), each wheel's own."""
    per_set = np.array([[p.ticks_per_rev + p.ticks_per_rev_delta_l, p.ticks_per_rev + p.ticks_per_rev_delta_r]
                        for p in robots])
    return np.tile(per_set, (n_win, 1))


def sensors_on_track(rec: Recording, rows: np.ndarray, robots: list[RobotParams], world: World,
                     seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The twin's IR ring (on, ambient), each (N, *rows.shape, S), read at the recorded poses of `rows`.

    The readings are not rounded to counts (as the encoder counts of
    run_windows): the residuals are then smooth in the parameters, so a fit
    sees the effect of a small step (a latency of a fraction of a
    millisecond moves a reading by a fraction of a count).  A twin with an
    ir_latency reads, for row k, the recorded (tracker) pose at t_k -
    ir_latency, linear between the rows (ir_sensor.pose_at), as the
    simulator's robot does between its control instants.
    """
    assert rec.pose is not None
    inputs = replay_inputs(rec)
    rng = np.random.default_rng(seed) if seed is not None else None
    flat = rows.reshape(-1)
    n_ir = len(robots[0].ir_bearings)
    on = np.empty((len(robots), flat.size, n_ir))
    amb = np.empty_like(on)
    for s, p in enumerate(robots):
        poses, t = rec.pose[flat], rec.t[flat]
        if p.ir_latency > 0:
            t = t - p.ir_latency
            poses = ir_sensor.pose_at(rec.t, rec.pose, t)
        amb[s], on[s] = ir_sensor.read_sensors(world, poses, inputs.emitter[flat], t, p, rng, quantise=False)
    shape = (len(robots), *rows.shape, n_ir)
    return on.reshape(shape), amb.reshape(shape)


def axis_distances(rec: Recording, rows: np.ndarray, p: RobotParams, world: World) -> np.ndarray:
    """(*rows.shape, S): the distance (m) from each sensor to the wall along its axis at the recorded pose
    (beyond its reach where none): what the near rule of unjudged_readings and the far one of
    IR_CALIBRATED_RANGE are judged on."""
    assert rec.pose is not None
    dist = ir_sensor.reflection(world, rec.pose[rows.reshape(-1)], p)[0]
    return dist.reshape(*rows.shape, len(p.ir_bearings))


def unjudged_readings(rec: Recording, rows: np.ndarray, p: RobotParams, world: World,
                      axis: np.ndarray | None = None) -> np.ndarray:
    """(*rows.shape, S) bool: the twin's reflected light at the recorded pose is ill-conditioned there
    (axis: axis_distances at these rows, if the caller has them).

    A sensor's ray that grazes a wall's end (or a corner) hits or misses it as the pose moves by the
    tracker's noise: the twin would read 500 counts or nothing from the same recorded pose.  Such a reading
    says nothing about the robot, and a fit would turn the sensor to explain it.  Judged instead: readings
    that change by less than POSE_DOUBT_COUNTS (or half of themselves) with the heading turned by
    +-POSE_DOUBT_RAD.

    Nor is a sensor that faces a wall the robot touches (FACING_COS): it reads the wall within millimetres
    of its mount, where the contact decides the reading (a hull pressed into the wall, a bumper's give) more
    than the IR law.  Nor is a wall nearer the sensor than where the far law C/x^2 takes over (ir_near_peak *
    ir_blend, 3.75 cm): nearer, the law is the paper's average of its near and far laws, which none of the
    datasheet's calibration points (5, 15 and 25 cm) reaches, so a part's own curve there is its optics'
    (the diodes' spacing, its window).  Both rules are
    tests/test_diagnosis.py::test_a_reading_the_recorded_pose_cannot_settle_is_not_judged.
    """
    assert rec.pose is not None
    inputs = replay_inputs(rec)
    flat = rows.reshape(-1)
    refl = []
    for turn in (0.0, -POSE_DOUBT_RAD, POSE_DOUBT_RAD):
        poses = rec.pose[flat] + np.array([0.0, 0.0, turn])
        amb, on = ir_sensor.read_sensors(world, poses, inputs.emitter[flat], rec.t[flat], p, None,
                                               quantise=False)
        refl.append(on - amb)
    spread = np.ptp(np.stack(refl), axis=0)
    doubt = spread > np.maximum(POSE_DOUBT_COUNTS, 0.5 * np.abs(refl[0]))
    dist, away = world.nearest_wall(rec.pose[flat, :2])  # away: the unit normal from the wall to C
    bearing = rec.pose[flat, 2:3] + np.asarray(p.ir_bearings)
    facing = -(np.cos(bearing) * away[:, :1] + np.sin(bearing) * away[:, 1:]) > FACING_COS
    doubt |= (dist < p.body_radius + CONTACT_MARGIN)[:, None] & facing
    if axis is None:
        axis = axis_distances(rec, rows, p, world)
    doubt |= axis.reshape(doubt.shape) < p.ir_near_peak * p.ir_blend
    return doubt.reshape(*rows.shape, len(p.ir_bearings))

