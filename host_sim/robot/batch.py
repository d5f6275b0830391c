"""Batch mode: N robots stepped together, vectorised numpy (N parameter sets, or N robots).

The core of identification: N candidate robots in the same recorded state, fed the same current
references, their encoders, IR ring and pose compared with the recording.  `BatchSim.substep` is every
robot's step, N = 1 (SimRobot is a view of a BatchSim of one) or many; `run_inputs` applies one row of
references per control period and returns a `BatchResult`.
Equations: docs/dynamics.md ("One robot and the batch"), docs/contact.md; the effects: docs/effects.md.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, TypeGuard, Union, cast

import numpy as np
from numpy.typing import ArrayLike

from host_sim.physics import contact, drivetrain, drivetrain_effects, dynamics, backlash, effects, motors, speed_loop
from host_sim.sensors import ir_sensor
from host_sim.physics.dynamics import ParamBatch, Params, PerRobot
from host_sim.controller.hardware_io import CYCLE_S
from host_sim.physics.params import RobotParams
from host_sim.physics.world import World


SUBSTEPS = 8
VECTOR_CONTACTS_FROM = 64  # robots in one contact step from which the vectorised solve is the faster
# RobotParams fields the IR model reads: robots that agree on all of them
# share one ir_sensor.read_sensors call.
IR_FIELDS = tuple(f.name for f in dataclasses.fields(RobotParams)
                  if f.name.startswith("ir_") or f.name in ("body_radius", "sensor_range", "adc_bits",
                                                             "ambient_leakage"))
# What BatchSim takes as its robots' parameters (docs/dynamics.md, "One robot and the batch")
ParamSets = Union[RobotParams, Sequence[RobotParams], ParamBatch]


@dataclass
class BatchResult:
    """Readings of N robots at T control instants (row j: before row j's command acts)."""

    t: np.ndarray  # (T,) s, or (T, N) where each robot lived its own durations (run_inputs' period (T, N))
    enc: np.ndarray  # (T, N, 2) cumulative encoder ticks, int64
    pose: np.ndarray  # (T, N, 3) x, y (m), phi (rad) of C, the wheel-axle centre
    ir_on: np.ndarray | None  # (T, N, 8) ADC counts, emitters on; None without sensors
    ir_amb: np.ndarray | None  # (T, N, 8) ADC counts, emitters off
    collisions: np.ndarray  # (N,) contacts started during the run
    substeps: int
    start: int = 0  # the recording row it started from (replay_batch)
    theta: np.ndarray | None = None  # (T, N, 2) what the encoders count (rad at the wheel), unquantised
    vbat: np.ndarray | None = None  # (T, N) V, the battery voltage the robot senses (sags with battery_resistance)

    @property
    def periods(self) -> int:
        return int(self.enc.shape[0])


def _is_array(a: object) -> TypeGuard[np.ndarray]:
    return isinstance(a, np.ndarray) and a.ndim >= 1


def _sub(a: PerRobot, idx: np.ndarray) -> PerRobot:
    """a[idx] for a per-robot array, a itself for a shared scalar."""
    return a[idx] if _is_array(a) else a


class _PerWheel:
    """A ParamBatch seen with every per-robot array widened to (N, 2), one column per wheel.

    motors.wheel_torque_batch then computes on (N, 2) arrays throughout instead of
    broadcasting (N, 1) parameters against (N, 2) speeds, which numpy does about
    twice as slowly; the numbers are the same, element by element.
    """

    def __init__(self, batch: ParamBatch) -> None:
        self._batch = batch

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._batch, name)
        if isinstance(value, np.ndarray) and value.ndim == 1:
            value = np.repeat(value[:, None], 2, axis=1)
            setattr(self, name, value)  # computed once
        return value


class _SubParams:
    """Robots s of a parameter set (RobotParams shared, or per-robot arrays), for the motor model."""

    def __init__(self, p: Params | _PerWheel, s: np.ndarray) -> None:
        self._p, self._s = p, s

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._p, name)
        return value[self._s] if isinstance(value, np.ndarray) and value.ndim >= 1 else value


class _WrittenBack:
    """A state array of BatchSim that a float step of one robot may hold apart (BatchSim._one_state): reading
    or setting it writes that state back first."""

    def __init__(self, field: str, doc: str) -> None:
        self.field, self.__doc__ = field, doc

    def __get__(self, sim: Any, owner: type | None = None) -> Any:
        if sim is None:
            return self
        if sim._one_state is not None:
            sim._write_back()
        return getattr(sim, self.field)

    def __set__(self, sim: Any, value: np.ndarray) -> None:
        if sim._one_state is not None:
            sim._write_back()
        setattr(sim, self.field, value)


class BatchSim:
    """N robots stepped together: state q (N, 5), v (N, 2) as in host_sim/physics/dynamics.py."""

    _ir_history: ir_sensor.PoseHistory | None = None  # the poses at the last readings, for ir_latency

    def __init__(self, world: World | None, params: ParamSets,
                 poses: ArrayLike | None = None, *, q: ArrayLike | None = None, v: ArrayLike | None = None, t: float = 0.0,
                 base: RobotParams | None = None, cycle_s: float = CYCLE_S, substeps: int = SUBSTEPS,
                 emitter_pct: float = 60.0, initial_emitter_pct: float | None = None, bench: bool = False) -> None:
        """
        world: the walls (None: no walls).  params: one RobotParams (shared), N of them, or a ParamBatch.
        poses: (N, 3) x, y, phi of C, wheel angles 0, at rest; or q (N, 5) and
        v (N, 2) directly (default: every robot at the world's start pose).
        base: the non-scalar parameters (IR polynomial coefficients) when
        params is a ParamBatch.  emitter_pct: the IR emitter power (%) every
        actuation sets; initial_emitter_pct: the power in force at the first
        reading (default emitter_pct; 0 for a robot that has not actuated yet).  bench: the
        body held, the wheels off the floor (docs/recordings.md).
        """
        if substeps < 1 or not cycle_s > 0:
            raise ValueError("substeps must be >= 1" if substeps < 1 else "cycle_s must be > 0")
        self.world = world if world is not None else World(name="no walls", size=(1.0, 1.0), walls=[])
        self.cycle_s = float(cycle_s)
        self.substeps = int(substeps)
        self.emitter_pct = float(emitter_pct)
        self.base = base or RobotParams()
        self.bench = bool(bench)
        n_hint = None
        for arr, width in ((poses, 3), (q, 5)):
            if arr is not None:
                a = np.asarray(arr, dtype=float)
                if a.ndim != 2 or a.shape[1] != width:
                    raise ValueError(f"{'poses' if width == 3 else 'q'} must have shape (N, {width}), got {a.shape}")
                n_hint = a.shape[0]
        self._set_params(params, n_hint)
        self._set_state(poses, q, v)
        # backlash: the motor sides' speeds (rad/s at the wheel), each turning with its wheel at the start
        self.rotor_speed = self.v.copy() if self.gear_gap is not None else None
        n = self.n
        self.t: PerRobot = float(t)  # s; (N,) once the robots live their own durations (run_inputs)
        self.emitter_now = float(emitter_pct if initial_emitter_pct is None else initial_emitter_pct)
        self.collisions = np.zeros(n, dtype=np.int64)
        self.in_contact = np.zeros(n, dtype=bool)
        # Broad phase of the wall test: where G and phi were at each robot's last
        # test, and the smallest wall gap then.
        self._chk = np.zeros((n, 3))
        self._gap = np.full(n, -1.0)
        self.slipping = np.zeros(n, dtype=bool)  # a wheel slips: the body velocity is extra state
        self.body = np.zeros((n, 3))  # (u, l, omega) of the robots that slip
        # the last contact step's forces, where the next one starts
        self._warm = np.zeros(n, dtype=bool)
        # Fewer robots than this in a contact step: contact.slip_step one by one, else slip_step_batch.
        self.vector_contacts_from = VECTOR_CONTACTS_FROM
        self._robots_cache: dict[int, RobotParams] = {}
        self._wheel_force = np.zeros((2, 3, n))  # per wheel: F_e, F_n at the tyre, the axle's friction torque
        self._wall_force = np.zeros((2, n, max(self.world.n_walls, 1)))
        self._walls = self.world.n_walls > 0
        self.current = np.zeros((n, 2))  # A, the motor currents of the last substep (mid-step)
        # V, what the robot senses: at rest only the electronics draw
        self.vbat = np.array(self.params.battery_voltage - self.params.battery_resistance
                             * self.params.electronics_current, dtype=float)
        # actuator_delay: the commands as issued (time, (N, 2)); the drivers see them late
        self._hist_t: list[float] = []
        self._hist_i: list[np.ndarray] = []

    def set_world(self, world: World) -> None:
        """The robots, where they stand, in an edited world (walls drawn or moved around them)."""
        self.world = world
        self._gap[:] = -1.0  # the broad phase's gaps were measured against the old walls
        self._warm[:] = False  # contact forces are kept by wall index, which the edit may have changed
        self._one_gap, self._one_forces = -1.0, None  # the same for _substep_one
        self._wall_force = np.zeros((2, self.n, max(world.n_walls, 1)))
        self._walls = world.n_walls > 0

    def place(self, poses: ArrayLike) -> None:
        """Put the robots at (x, y, phi) `poses` ((N, 3), q's first three) as they are otherwise (speeds,
        gears, slides, commands on their way): a replayed window starts on its recorded pose."""
        self.q[:, :3] = np.asarray(poses, dtype=float)
        self._gap[:] = -1.0  # the broad phase measured its gaps where the robots were
        self._warm[:] = False
        self._one_gap, self._one_forces = -1.0, None  # the same for _substep_one

    def start_sliding(self, slides: ArrayLike, body: ArrayLike) -> None:
        """Robots `slides` ((N,) bool) start sliding over the floor with body velocity (u, l, omega) of C
        `body` ((N, 3)), not rolling at their wheels' speeds: a replay from a row where the tracker saw the
        robot slide (replay.sliding_rows)."""
        slides = np.asarray(slides, dtype=bool)
        self.slipping[slides] = True
        self.body[slides] = np.asarray(body, dtype=float)[slides]

    def seed_commands(self, times: Iterable[ArrayLike], cmds: Iterable[ArrayLike]) -> None:
        """The commands issued before now (times ascending, s: (K,), or (K, N) each robot's own; cmds
        (K, N, 2) or (K, 2), A): what a delayed actuator still has on its way when the run starts.
        Without it: no current before the first."""
        for t, c in zip(times, cmds):
            self._hist_t.append(float(t) if np.ndim(t) == 0 else np.array(t, dtype=float))
            self._hist_i.append(np.broadcast_to(np.asarray(c, dtype=float), (self.n, 2)).copy())

    # ------------------------------------------------------------------ set-up
    def _set_state(self, poses: ArrayLike | None, q: ArrayLike | None, v: ArrayLike | None) -> None:
        """q and v given, or robots at rest at poses of C (default the world's start)."""
        n = self.n
        if q is not None:
            self.q = np.array(q, dtype=float)
            if self.q.shape != (n, 5):
                raise ValueError(f"q must have shape ({n}, 5), got {self.q.shape}")
            self.v = np.zeros((n, 2)) if v is None else np.array(v, dtype=float)
            if self.v.shape != (n, 2):
                raise ValueError(f"v must have shape ({n}, 2), got {self.v.shape}")
            return
        if poses is None:
            poses = np.tile(np.asarray(self.world.start, dtype=float), (n, 1))
        pz = np.asarray(poses, dtype=float)
        d = self._d
        self.q = np.zeros((n, 5))
        self.q[:, 0] = pz[:, 0] + d * np.cos(pz[:, 2])
        self.q[:, 1] = pz[:, 1] + d * np.sin(pz[:, 2])
        self.q[:, 2] = pz[:, 2]
        self.v = np.zeros((n, 2))

    def _set_params(self, params: ParamSets, n_hint: int | None) -> None:
        if isinstance(params, RobotParams):
            n = n_hint if n_hint is not None else 1
            robots: list[RobotParams] | None = [params]
            shared: RobotParams | None = params
            batch = ParamBatch.broadcast(params, n)
        elif isinstance(params, ParamBatch):
            batch, robots = params, None
            n = batch.n
            shared = batch.robot(0, self.base) if all(
                np.all(getattr(batch, k) == getattr(batch, k)[0]) for k in batch.names) and n else None
        else:
            robots = list(params)
            if not robots or not all(isinstance(p, RobotParams) for p in robots):
                raise TypeError("params: a RobotParams, a non-empty sequence of RobotParams, or a ParamBatch")
            n = len(robots)
            batch = ParamBatch.from_params(robots)
            shared = robots[0] if all(p == robots[0] for p in robots) else None
        if n_hint is not None and n != n_hint:
            raise ValueError(f"{n} parameter sets for {n_hint} robots")
        if n < 1:
            raise ValueError("no robots")
        self.n = n
        self.params = batch  # one value per robot, always
        # What the motors and the dynamics read: the shared RobotParams (floats,
        # faster; the same numbers) when every robot has the same parameters.
        self._p: Params = shared if shared is not None else batch
        # _PerWheel reads as the ParamBatch it widens
        self._p_motors: Params = shared if shared is not None else cast(ParamBatch, _PerWheel(batch))
        self._d = shared.com_offset if shared is not None else batch.com_offset
        self._r = shared.body_radius if shared is not None else batch.body_radius
        self._wheel_radius = shared.wheel_radius if shared is not None else batch.wheel_radius
        self._half_axle = shared.half_axle if shared is not None else batch.half_axle
        self._shared = shared is not None
        self._set_drive(batch)
        self._floats = n == 1 and self._fx is None and self._delay is None and self._speed is None  # _substep_one
        self._gear_engaged = np.ones((self.n, 2), dtype=bool)  # at the end of the rolling substep under way
        self._per_wheel_ticks = bool(np.any(batch.ticks_per_rev_delta_l != 0) or np.any(batch.ticks_per_rev_delta_r != 0))
        # IR groups: (indices or None for all, RobotParams).
        if shared is not None:
            self._ir_groups: list[tuple[np.ndarray | None, RobotParams]] = [(None, shared)]
        elif robots is not None:
            groups: dict[tuple[Any, ...], list[int]] = {}
            for i, p in enumerate(robots):
                groups.setdefault(tuple(getattr(p, f) for f in IR_FIELDS), []).append(i)
            self._ir_groups = [(np.array(ix), robots[ix[0]]) for ix in groups.values()]
        else:
            scalar = [f for f in IR_FIELDS if f in batch.names]
            table = np.stack([getattr(batch, f) for f in scalar], 1)
            _, first, inverse = np.unique(table, axis=0, return_index=True, return_inverse=True)
            inverse = inverse.reshape(-1)
            self._ir_groups = [(np.flatnonzero(inverse == g), batch.robot(int(i), self.base))
                               for g, i in enumerate(first)]
        if len(self._ir_groups) == 1:
            self._ir_groups = [(None, self._ir_groups[0][1])]

    def _set_drive(self, batch: ParamBatch) -> None:
        """The drive's optional parts: effects, actuator delay, gears' play, the wheel_speed drive's loop."""
        # The library's drive effects, the bridge drives and the bench (host_sim/physics/drivetrain_effects.py):
        # None while all are absent (the fast path).
        self._fx = drivetrain_effects.Drive.of(batch) if drivetrain_effects.active(batch) or self.bench else None
        self._delay = batch.actuator_delay.copy() if np.any(batch.actuator_delay != 0.0) else None
        # backlash: the gear's gap per wheel (motor angle / N - wheel angle), the play's middle at the start;
        # on a bench a wheel spins with its gear as one (bench_step)
        self.gear_gap = np.zeros((self.n, 2)) if (
            self._fx is not None and np.any(self._fx.play) and not self.bench) else None
        on = batch.drive == drivetrain_effects.WHEEL_SPEED  # the wheel_speed drive's own loop (speed_loop.py)
        self._speed = speed_loop.SpeedLoop(batch.speed_kp, batch.speed_ki, batch.speed_loop_period, on) \
            if on.any() else None
        self.loop_counts_whole = True  # the loop measures whole counts, as a board does (_loop_angles)

    # ------------------------------------------------------------------ state
    # A BatchSim of one in floats keeps q, v and current as Python floats between its steps (numpy's cost to
    # write them back each step is half the step's); reading or setting any of them writes them back first.
    _one_state: tuple[Any, Any, Any] | None = None
    # and its own broad phase and contact forces (_chk, _gap and _warm with the forces, for one robot)
    _one_checked_at, _one_gap = (0.0, 0.0, 0.0), -1.0
    _one_forces: tuple[list[list[float]], dict[int, list[float]]] | None = None

    q = _WrittenBack("_q", "(N, 5): x_G, y_G, phi, theta_l, theta_r as in host_sim/physics/dynamics.py.")
    v = _WrittenBack("_v", "(N, 2) rad/s, the wheels' speeds.")
    current = _WrittenBack("_current", "(N, 2) A, the motor currents of the last substep (mid-step).")

    def floats_of_one(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(q, v) of the first robot as Python floats, without writing a float step's state back."""
        if self._one_state is not None:
            return tuple(self._one_state[0]), tuple(self._one_state[1])
        return tuple(self._q.tolist()[0]), tuple(self._v.tolist()[0])

    def _write_back(self) -> None:
        """The floats of _substep_one into q, v and current (the arrays are the state again)."""
        q, v, current = self._one_state  # type: ignore[misc]
        self._one_state = None
        self._q[0], self._v[0], self._current[0] = q, v, current

    @property
    def pose(self) -> np.ndarray:
        """(N, 3): x, y, phi of C, the centre of the wheel axle."""
        q = self.q
        out = np.empty((self.n, 3))
        out[:, 0] = q[:, 0] - self._d * np.cos(q[:, 2])
        out[:, 1] = q[:, 1] - self._d * np.sin(q[:, 2])
        out[:, 2] = q[:, 2]
        return out

    def encoder_ticks(self) -> np.ndarray:
        """(N, 2) int64 cumulative ticks (left, right)."""
        if self._per_wheel_ticks or self.gear_gap is not None:
            return motors.encoder_ticks_batch(self.encoder_angles(), self.params, wheels=True)
        return motors.encoder_ticks_batch(self.q[:, 3:5], self._p)

    def _loop_angles(self) -> np.ndarray:
        """(N, 2) the wheel angles a set-point robot's loop measures: its counts at the board's datasheet
        2 pi / ticks_per_rev a count, so an encoder of another scale drives its wheel off the set-point
        (tests/test_drives.py::test_a_set_point_loop_counts_at_the_boards_scale_and_its_twin_is_smooth).
        Whole counts unless loop_counts_whole is off: the diagnosis's twin, whose residuals must change
        smoothly with its parameters, sees their mean, the encoder's angle."""
        counts = self.encoder_ticks() if self.loop_counts_whole else \
            self.encoder_angles() * (drivetrain_effects.ticks_per_rev(self.params) / (2.0 * np.pi))
        board = np.asarray(self.params.ticks_per_rev, dtype=float)
        return counts * (2.0 * np.pi / board[:, None])

    def engage_gears(self, side: ArrayLike) -> None:
        """Backlash: close each gear's gap on `side` (N, 2) (+1 forward, -1 backward, 0 the middle), the
        encoders reading as before (the wheels move instead): where a robot that had been driven sits."""
        if self.gear_gap is not None:
            gap = np.sign(np.asarray(side, dtype=float)) * self._fx.play  # type: ignore[union-attr]
            self.q[:, 3:5] += self.gear_gap - gap
            self.gear_gap = gap
            self.rotor_speed = self.v.copy()  # the motor sides turn with their wheels

    def hold_speeds(self) -> None:
        """The wheel_speed drive's loops as if they had held the wheels at their present speeds: each integral
        at the volts that keep a wheel turning at its speed against its friction
        (drivetrain_effects.holding_volts)."""
        if self._speed is not None and self._fx is not None:
            self._speed.hold(drivetrain_effects.holding_volts(self.v, self._fx))

    def encoder_angles(self) -> np.ndarray:
        """(N, 2) what the encoders count, in wheel radians: the motor's angle / N (the wheel's, but for
        the backlash's gap)."""
        return self.q[:, 3:5] if self.gear_gap is None else self.q[:, 3:5] + self.gear_gap

    @property
    def n_ir(self) -> int:
        """The IR pairs of every robot's ring (ir_bearings; one ring for the whole batch)."""
        return len(self._ir_groups[0][1].ir_bearings)

    def read_sensors(self, rng: np.random.Generator | None = None,
                     pose: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(adc_on, adc_off), each (N, 8): the IR ring now, at the emitter power in force.

        pose: the robots' pose now (default self.pose).  Robots with an
        ir_latency read the pose of that long ago, linear between the poses
        of the earlier calls (ir_sensor.PoseHistory, as SimRobot.sense does).
        """
        pose = self.pose if pose is None else pose
        latency = max(p.ir_latency for _idx, p in self._ir_groups)
        if latency > 0:
            if self._ir_history is None:
                self._ir_history = ir_sensor.PoseHistory(latency)
            self._ir_history.add(self.t, pose)
        on = np.empty((self.n, self.n_ir), dtype=np.int64)
        off = np.empty((self.n, self.n_ir), dtype=np.int64)
        for idx, p in self._ir_groups:
            at, t = pose, self.t
            if p.ir_latency > 0:
                assert self._ir_history is not None
                t = self.t - p.ir_latency
                at = self._ir_history.at(t)
            if idx is None:
                off[:], on[:] = ir_sensor.read_sensors(self.world, at, self.emitter_now, t, p, rng)
            else:
                off[idx], on[idx] = ir_sensor.read_sensors(self.world, at[idx], self.emitter_now, _sub(t, idx), p,
                                                           rng)
        return on, off

    # ------------------------------------------------------------------ physics
    def substep(self, i_ref: ArrayLike, dt: PerRobot) -> None:
        """All N robots by dt seconds (a float, or (N,) each robot's own) with current references i_ref, (2,)
        or (N, 2) A: rolling where the wheels hold and no wall is hit, else the contact step.  Every robot's
        step, N = 1 or many: one robot with the nominal physics takes it in Python floats (_substep_one)."""
        if self._floats:
            self._substep_one(i_ref, dt)
            return
        if self._delay is not None:
            i_ref = self._delayed(i_ref, dt)
        if self._speed is not None:  # set-points to the loop, its volts to the bridge
            i_ref = self._speed.command(i_ref, self.t, self._loop_angles(), self.v, self.vbat)
        q0, v0 = self.q, self.v
        if self.bench:
            self.q, self.v, self.current, self.vbat = drivetrain_effects.bench_step(
                q0, v0, i_ref, dt, self._fx)  # type: ignore[arg-type]
            self.t = self.t + dt
            return
        if self.gear_gap is not None:
            q1, v1, ok, i_ref, gear = self._gear_step(q0, v0, i_ref, dt)
        elif self._fx is None:
            q1, v1, tau, self.current = drivetrain.drive_step_batch(q0, v0, i_ref, dt, self._p, self._p_motors)
            ok = contact.traction_ok_batch(v0, v1, tau, dt, self._p) & ~self.slipping
        else:
            q1, v1, tau, self.current, self.vbat = drivetrain_effects.drive_step(q0, v0, i_ref, dt, self._fx, self._d)
            ok = drivetrain_effects.traction_ok(v0, v1, tau, dt, self._fx) & ~self.slipping
        idx, gaps, normals, order = self._walls_in_reach(q0, q1, ok, dt)
        if idx.size:
            # the rolling step is kept unless it takes the rim into a wall (linearised gap: the distance
            # to a segment is convex in C, so this never misses a contact)
            d = _sub(self._d, idx)
            dx = q1[idx, 0] - q0[idx, 0] - d * (np.cos(q1[idx, 2]) - np.cos(q0[idx, 2]))
            dy = q1[idx, 1] - q0[idx, 1] - d * (np.sin(q1[idx, 2]) - np.sin(q0[idx, 2]))
            with np.errstate(invalid="ignore"):
                hits = (gaps + normals[..., 0] * dx[:, None] + normals[..., 1] * dy[:, None] < 0.0).any(1)
            ok[idx[hits]] = False
        if not ok.all():
            self._slip_step(q0, v0, q1, v1, ~ok, i_ref, dt, idx, gaps, normals, order)
        self._warm &= ~ok  # a rolling step ends the contact forces' history
        if self.gear_gap is not None:
            rolled, wm1, gap1 = gear
            if not ok.all():
                bad = np.flatnonzero(~ok)
                v1[bad], wm1[bad], gap1[bad] = backlash.after_contact(
                    rolled[bad] - q1[bad, 3:5], v1[bad], wm1[bad], gap1[bad],
                    self._fx.sub(bad))  # type: ignore[union-attr]
            self.gear_gap, self.rotor_speed = gap1, wm1
        self.q, self.v = q1, v1
        self.t = self.t + dt  # a new value: the actuator delay's history keeps the old one

    def _substep_one(self, i_ref: ArrayLike, dt: PerRobot) -> None:
        """substep for one robot with the nominal physics, in Python floats: for one robot numpy's cost per
        call outweighs the arithmetic; the figures are the vectorised step's to rounding
        (tests/test_batch.py::test_one_robot_steps_in_floats_as_in_a_batch).  drivetrain.drive_step, kept
        unless the wheels slip (contact.traction_ok) or the rim would enter a wall, else _contact_one."""
        p: RobotParams = self._p  # type: ignore[assignment]
        h = dt if type(dt) is float else float(np.reshape(dt, -1)[0])
        i_lr = i_ref if type(i_ref) is tuple else tuple(np.reshape(np.asarray(i_ref, dtype=float), 2).tolist())
        if self._one_state is None:
            q0, v0 = self._q.tolist()[0], self._v.tolist()[0]
        else:
            q0, v0, _current = self._one_state
        slip = tuple(self.body[0].tolist()) if self.slipping[0] else None
        rolled = False
        if slip is None:
            q1, v1, tau, current = drivetrain.drive_step(q0, v0, i_lr, h, p)
            rolled = contact.traction_ok(v0, v1, tau, h, p)
        walls = self._walls_near_one(q0, q1 if rolled else None, v0, slip, h)
        if rolled and walls:
            # the rolling step is kept unless it takes the rim into a wall (linearised gap, as substep's)
            d = p.com_offset
            dx = q1[0] - q0[0] - d * (math.cos(q1[2]) - math.cos(q0[2]))
            dy = q1[1] - q0[1] - d * (math.sin(q1[2]) - math.sin(q0[2]))
            rolled = all(gap + nx * dx + ny * dy >= 0.0 for gap, nx, ny, _i in walls)
        if rolled:
            self._one_state = (q1, v1, current)
            self._one_forces = None  # a rolling step ends the contact forces' history
        else:
            self._contact_one(q0, v0, slip, i_lr, h, walls)
        self.t = self.t + dt

    def _contact_one(self, q0: Sequence[float], v0: Sequence[float], slip: tuple[float, ...] | None,
                     i_lr: tuple[float, ...], h: float, walls: list[tuple[float, float, float, int]]) -> None:
        """_substep_one's contact step (contact.slip_step), started from the last one's contact forces."""
        p: RobotParams = self._p  # type: ignore[assignment]
        tl, il, sl = motors.wheel_torque_slope(i_lr[0], v0[0], p)
        tr, ir, sr = motors.wheel_torque_slope(i_lr[1], v0[1], p)
        warm = None
        if self._one_forces is not None:
            wheel_f, wall_f = self._one_forces
            warm = (wheel_f, [wall_f.get(w[3], [0.0, 0.0]) for w in walls])
        q1, v1, body, pushed, (wheel_f, wall_list) = contact.slip_step(
            q0, v0, slip, (tl, tr), (sl, sr), h, p, walls, warm)  # type: ignore[arg-type]
        self._one_state = (q1, v1, (il, ir))
        self._one_forces = (wheel_f, {w[3]: f for w, f in zip(walls, wall_list)})
        self.slipping[0] = body is not None
        if body is not None:
            self.body[0] = body
        if pushed and not self.in_contact[0]:
            self.collisions[0] += 1
            self.in_contact[0] = True

    def _walls_near_one(self, q0: Sequence[float], q1: Sequence[float] | None, v0: Sequence[float],
                        slip: tuple[float, ...] | None, h: float) -> list[tuple[float, float, float, int]]:
        """The walls the step from q0 (to q1 when rolling) may touch, (gap, nx, ny, index) each.

        Broad phase: no test while the smallest gap at the last test exceeds how far C may have
        moved since (C = G - d e moves at most |dG| + d |dphi|) plus how far this step takes it."""
        d: float = self._d  # type: ignore[assignment]
        chk, gap_at_check = self._one_checked_at, self._one_gap
        moved = math.hypot(q0[0] - chk[0], q0[1] - chk[1]) + d * abs(q0[2] - chk[2])
        if q1 is not None:
            travel = math.hypot(q1[0] - q0[0], q1[1] - q0[1]) + d * abs(q1[2] - q0[2])
        else:
            u, l, _om = slip if slip is not None else contact.body_velocity(v0, self._p)
            travel = h * (abs(u) + abs(l))
        within = travel + contact.REACH_MARGIN
        if moved + within < gap_at_check:
            if gap_at_check - moved > contact.CONTACT_HYSTERESIS and self.in_contact[0]:
                self.in_contact[0] = False
            return []
        cx, cy = q0[0] - d * math.cos(q0[2]), q0[1] - d * math.sin(q0[2])
        walls, gmin = contact.walls_in_reach(self.world, cx, cy, self._r, within)  # type: ignore[arg-type]
        self._one_checked_at, self._one_gap = (q0[0], q0[1], q0[2]), gmin
        if gmin > contact.CONTACT_HYSTERESIS:  # a little hysteresis: grazing is one contact, not many
            self.in_contact[0] = False
        return walls

    def _gear_step(self, q0: np.ndarray, v0: np.ndarray, i_ref: ArrayLike, dt: PerRobot
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
        """The rolling step with the gears' play (backlash.substep): (q1, v1, traction holds, the references a
        contact step takes, (wheel angles, motor-side speeds and gaps at the end of the rolling step))."""
        fx = self._fx
        assert fx is not None and self.rotor_speed is not None and self.gear_gap is not None
        q1, v1, wm1, gap1, tau, self.current, self.vbat, jump = backlash.substep(
            q0, v0, self.rotor_speed, self.gear_gap, i_ref, dt, fx, self._d)
        # tau: the gears' torques on the wheels, which turn with their own inertia; the impacts aside
        ok = drivetrain_effects.traction_ok(v0 + jump, v1, tau, dt, fx, fx.iw[:, None] - fx.i_r) & ~self.slipping
        # a contact step drives the wheels whose gear is engaged at the end (docs/effects.md)
        self._gear_engaged = backlash.engaged_at(gap1, fx)
        i_contact = np.where(self._gear_engaged, i_ref, 0.0)
        return q1, v1, ok, i_contact, (q1[:, 3:5].copy(), wm1, gap1)

    def _slip_step(self, q0: np.ndarray, v0: np.ndarray, q1: np.ndarray, v1: np.ndarray, bad: np.ndarray,
                   i_ref: ArrayLike, dt: PerRobot, idx: np.ndarray, gaps: np.ndarray, normals: np.ndarray,
                   order: np.ndarray) -> None:
        """contact.slip_step_batch for the robots `bad`, written into q1, v1."""
        s = np.flatnonzero(bad)
        dt = _sub(dt, s)
        i_s = np.asarray(i_ref, dtype=float)
        i_s = i_s[s] if i_s.ndim == 2 else np.broadcast_to(i_s, (len(s), 2))
        tau, slope, body, extra = self._slip_inputs(s, i_s, v0)
        width = gaps.shape[1] if idx.size else 0
        g = np.full((len(s), width), np.inf)
        nrm = np.zeros((len(s), width, 2))
        nrm[..., 0] = 1.0  # no wall: any unit normal, its gap is inf
        walls = np.zeros((len(s), width), dtype=np.int64)
        if width:
            pos = np.searchsorted(idx, s)
            found = (pos < len(idx)) & (idx[np.minimum(pos, len(idx) - 1)] == s)
            g[found] = gaps[pos[found]]
            nrm[found] = normals[pos[found]]
            walls[found] = order[pos[found]]
        # warm start from the last step's contact forces, where there was one
        warm = self._warm[s]
        wheel_f = np.where(warm[None, None], self._wheel_force[:, :, s], 0.0)
        wall_f = self._wall_force[:, s[:, None], walls].transpose(0, 2, 1)  # (2, W, K)
        wall_f = np.where((warm[:, None] & np.isfinite(g))[None].transpose(0, 2, 1), wall_f, 0.0)
        if extra or len(s) >= self.vector_contacts_from:  # the effects: batch only
            qn, vn, bn, rolled, pushed, wheel_f, wall_f = contact.slip_step_batch(
                q0[s], v0[s], body, tau, slope, dt, self._p, g, nrm, None if self._shared else s, wheel_f, wall_f, **extra)
        else:
            qn, vn, bn, rolled, pushed, wheel_f, wall_f = self._slip_steps_one_by_one(
                s, q0, v0, body, tau, slope, dt, g, nrm, walls, wheel_f, wall_f)
        q1[s], v1[s], self.body[s] = qn, vn, bn
        self._wheel_force[:, :, s] = wheel_f
        self._wall_force[:, s] = 0.0
        if width:
            self._wall_force[:, s[:, None], walls] = np.where(np.isfinite(g)[None], wall_f.transpose(0, 2, 1), 0.0)
        self._warm[s] = True
        self.slipping[s] = ~rolled
        started = s[pushed & ~self.in_contact[s]]
        self.collisions[started] += 1
        self.in_contact[s[pushed]] = True

    def _slip_steps_one_by_one(self, s: np.ndarray, q0: np.ndarray, v0: np.ndarray, body: np.ndarray,
                               tau: np.ndarray, slope: np.ndarray, dt: PerRobot, g: np.ndarray, nrm: np.ndarray,
                               walls: np.ndarray, wheel_f: np.ndarray, wall_f: np.ndarray) -> tuple[np.ndarray, ...]:
        """contact.slip_step (the scalar twin of slip_step_batch) for each robot of s, in the batch's layout:
        a few robots in contact cost less this way than a vectorised solve whose sweeps are all
        overhead.  dt: a float, or (K,) one per robot of s."""
        k, width = len(s), g.shape[1]
        qn, vn, bn = np.empty((k, 5)), np.empty((k, 2)), np.empty((k, 3))
        rolled, pushed = np.zeros(k, dtype=bool), np.zeros(k, dtype=bool)
        wheel_out, wall_out = np.zeros((2, 3, k)), np.zeros((2, width, k))
        for n, j in enumerate(s):
            near = [w for w in range(width) if np.isfinite(g[n, w])]
            in_reach = [(float(g[n, w]), float(nrm[n, w, 0]), float(nrm[n, w, 1]), int(walls[n, w])) for w in near]
            warm = (wheel_f[:, :, n].tolist(), [wall_f[:, w, n].tolist() for w in near]) if self._warm[j] else None
            q_j, v_j, b_j, pushed[n], (f_wheels, f_walls) = contact.slip_step(
                q0[j].tolist(), v0[j].tolist(), tuple(body[n].tolist()) if self.slipping[j] else None,
                tau[n].tolist(), slope[n].tolist(), float(dt) if np.ndim(dt) == 0 else float(dt[n]),
                self._robot_params(int(j)), in_reach, warm)
            qn[n], vn[n] = q_j, v_j
            rolled[n] = b_j is None
            bn[n] = body[n] if b_j is None else b_j
            wheel_out[:, :, n] = f_wheels
            for w, f in zip(near, f_walls):
                wall_out[:, w, n] = f
        return qn, vn, bn, rolled, pushed, wheel_out, wall_out

    def _robot_params(self, j: int) -> RobotParams:
        if isinstance(self._p, RobotParams):  # every robot shares it
            return self._p
        cached = self._robots_cache.get(j)
        if cached is None:
            cached = self._robots_cache[j] = self._p.robot(j, self.base)
        return cached

    def _slip_inputs(self, s: np.ndarray, i_s: np.ndarray, v0: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """For the contact step of robots s: wheel torques and their slopes at v0, body velocities (the
        rolling robots' from their wheels), and the effects' extra arguments of contact.slip_step_batch."""
        body = self.body[s]
        rolling = ~self.slipping[s]
        vs = v0[s]
        if self._fx is not None:
            fx = self._fx.sub(s)
            tau, cur, slope, self.vbat[s] = drivetrain_effects.wheel_torque_slope(i_s, vs, fx)
            body = np.where(rolling[:, None], drivetrain_effects.body_velocity(vs, fx), body)
            self.current[s] = cur
            forces = drivetrain_effects.body_forces(body[:, 0], body[:, 1], body[:, 2], fx)
            t_c = fx.dry(vs)
            t_c = t_c if self.gear_gap is None else np.where(self._gear_engaged[s], t_c, 0.0)
            return tau, slope, body, {"radii": fx.radius, "body_force": forces, "axle_friction": t_c,
                                      "yaw_damping": drivetrain_effects.yaw_damping(body[:, 2], fx)}
        tau, _cur, slope = motors.wheel_torque_slope_batch(i_s, vs, cast(Params, _SubParams(self._p_motors, s)))
        if rolling.any():
            r, b = _sub(self._wheel_radius, s), _sub(self._half_axle, s)
            body[:, 0] = np.where(rolling, 0.5 * r * (vs[:, 0] + vs[:, 1]), body[:, 0])
            body[:, 1] = np.where(rolling, 0.0, body[:, 1])
            body[:, 2] = np.where(rolling, 0.5 * r * (vs[:, 1] - vs[:, 0]) / b, body[:, 2])
        return tau, slope, body, {}

    def _delayed(self, i_ref: ArrayLike, dt: PerRobot) -> np.ndarray:
        """The current references the drivers see over this substep, actuator_delay after they were issued
        (a command is issued when it differs from the last; drivetrain_effects.delayed_reference)."""
        i = np.broadcast_to(np.asarray(i_ref, dtype=float), (self.n, 2))
        if not self._hist_i or not np.array_equal(i, self._hist_i[-1]):
            self._hist_t.append(self.t)
            self._hist_i.append(i.copy())
        oldest = self.t - float(self._delay.max())  # type: ignore[union-attr]
        while len(self._hist_t) > 1 and np.all(self._hist_t[1] <= oldest):
            del self._hist_t[0], self._hist_i[0]
        return drivetrain_effects.delayed_reference(self._hist_t, self._hist_i, self.t, dt, self._delay)  # type: ignore[arg-type]

    def _walls_in_reach(self, q0: np.ndarray, q1: np.ndarray, ok: np.ndarray, dt: PerRobot
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(robots tested, their gaps (K, W), normals (K, W, 2), wall indices (K, W)) of the robots that may
        reach a wall in this step (C moves at most |dG| + d |dphi|): _walls_near_one for each."""
        none = np.empty(0, dtype=np.int64)
        if not self._walls:
            return none, np.empty((0, 0)), np.empty((0, 0, 2)), np.empty((0, 0), dtype=np.int64)
        chk, d = self._chk, self._d
        moved = np.hypot(q0[:, 0] - chk[:, 0], q0[:, 1] - chk[:, 1]) + d * np.abs(q0[:, 2] - chk[:, 2])
        travel = np.hypot(q1[:, 0] - q0[:, 0], q1[:, 1] - q0[:, 1]) + d * np.abs(q1[:, 2] - q0[:, 2])
        if self.slipping.any():
            sl = self.body
            travel = np.where(self.slipping, dt * (np.abs(sl[:, 0]) + np.abs(sl[:, 1])), travel)
        within = travel + contact.REACH_MARGIN
        far = moved + within < self._gap
        self.in_contact &= ~(far & (self._gap - moved > contact.CONTACT_HYSTERESIS))
        idx = np.flatnonzero(~far)
        if idx.size == 0:
            return none, np.empty((0, 0)), np.empty((0, 0, 2)), np.empty((0, 0), dtype=np.int64)
        qi = q0[idx]
        di = _sub(d, idx)
        centre = np.stack([qi[:, 0] - di * np.cos(qi[:, 2]), qi[:, 1] - di * np.sin(qi[:, 2])], 1)
        gaps, normals, order, gmin = contact.walls_in_reach_batch(self.world, centre, _sub(self._r, idx),
                                                                  within[idx])
        chk[idx] = qi[:, :3]
        self._gap[idx] = gmin
        self.in_contact[idx[gmin > contact.CONTACT_HYSTERESIS]] = False
        return idx, gaps, normals, order

    # ------------------------------------------------------------------ runs
    def run_inputs(self, cmd: ArrayLike, substeps: int | None = None, sensors: bool = True,
                   seed: int | np.random.Generator | None = None, period: ArrayLike | None = None,
                   emitter: Sequence[float] | np.ndarray | None = None) -> BatchResult:
        """Apply T rows of current references, one per control period; returns the readings.

        cmd: (T, 2) A, the same references for every robot, or (T, N, 2).
        substeps: physics substeps per period (default the simulator's, 8).
        sensors: read the IR ring at every control instant (False: enc and
        pose only, faster).  seed: sensor noise (None: noise-free; an int or
        a numpy Generator).  period: seconds per row, a float, (T,) array
        (default cycle_s), or (T, N): each robot lives its own durations (a
        recorded robot's late rows), its clock `t` then its own (N,).
        emitter: (T,) % emitter power of each row's on-reading (default: as
        the constructor's emitter_pct and initial_emitter_pct say).  The state
        carries on: call again to continue.
        """
        cmd = np.asarray(cmd, dtype=float)
        n = self.n
        if not ((cmd.ndim == 2 and cmd.shape[1] == 2) or (cmd.ndim == 3 and cmd.shape[1:] == (n, 2))):
            raise ValueError(f"cmd must have shape (T, 2) or (T, {n}, 2), got {cmd.shape}")
        n_rows = cmd.shape[0]
        substeps = self.substeps if substeps is None else int(substeps)
        if substeps < 1:
            raise ValueError("substeps must be >= 1")
        periods = self._periods(period, n_rows)
        rng = seed if isinstance(seed, np.random.Generator) else (
            np.random.default_rng(seed) if seed is not None else None)
        t_out = np.empty((n_rows,) + np.shape(self.t))
        enc = np.empty((n_rows, n, 2), dtype=np.int64)
        theta = np.empty((n_rows, n, 2))
        pose = np.empty((n_rows, n, 3))
        vbat = np.empty((n_rows, n))
        ir_on = np.empty((n_rows, n, self.n_ir), dtype=np.int64) if sensors else None
        ir_amb = np.empty((n_rows, n, self.n_ir), dtype=np.int64) if sensors else None
        collisions0 = self.collisions.copy()
        for j in range(n_rows):
            t_out[j] = self.t
            enc[j] = self.encoder_ticks()
            theta[j] = self.encoder_angles()
            pose[j] = here = self.pose
            vbat[j] = self.vbat
            if emitter is not None:
                self.emitter_now = float(emitter[j])
            if sensors:
                ir_on[j], ir_amb[j] = self.read_sensors(rng, here)  # type: ignore[index]
            i_ref = cmd[j]
            self.emitter_now = self.emitter_pct  # the actuation of row j sets the emitters
            dt = float(periods[j]) / substeps if periods.ndim == 1 else periods[j] / substeps
            for _ in range(substeps):
                self.substep(i_ref, dt)
        return BatchResult(t_out, enc, pose, ir_on, ir_amb, self.collisions - collisions0, substeps, theta=theta,
                           vbat=vbat)

    def _periods(self, period: ArrayLike | None, n_rows: int) -> np.ndarray:
        """(T,) seconds per row shared by every robot, or (T, N) each robot's own (then the robots' clocks
        become one per robot: the actuator delay and the IR latency look back along each robot's own)."""
        given = np.asarray(self.cycle_s if period is None else period, dtype=float)
        if given.ndim == 2:
            if given.shape != (n_rows, self.n):
                raise ValueError(f"period must have shape ({n_rows},) or ({n_rows}, {self.n}), got {given.shape}")
            if np.ndim(self.t) == 0:
                self.t = np.full(self.n, float(self.t))
            periods = given
        else:
            periods = np.broadcast_to(given, (n_rows,))
        if n_rows and not (periods > 0).all():
            raise ValueError("every period must be > 0")
        return periods


# --------------------------------------------------------------------------- #
# Identification: N parameter sets replaying one recording
# --------------------------------------------------------------------------- #
def step_parts(p: RobotParams) -> tuple[bool, ...]:
    """Which optional parts of BatchSim's step (effects.STEP_PARTS) robot p sets going: the drive with
    effects, a gear's play, an actuator delay; each when an effect of the library that needs it is present.
    A batch runs every robot through each part one of them needs (a gear's play is the dearest), so robots
    batched by their step parts run faster (diagnosis.windows.run_windows).  A robot's figures do not depend
    on its batch: each robot's contact solve stops where its own impulses settle."""
    return tuple(any(getattr(p, f) != 0.0 for f in effects.fields_needing(part)) for part in effects.STEP_PARTS)


def robot_params(params: ParamSets, base: RobotParams | None
                 ) -> tuple[RobotParams | list[RobotParams] | ParamBatch, list[RobotParams]]:
    """(what BatchSim takes, the N RobotParams) from a RobotParams, a sequence of them or a ParamBatch."""
    if isinstance(params, RobotParams):
        return params, [params]
    if isinstance(params, ParamBatch):
        return params, [params.robot(i, base) for i in range(params.n)]
    robots = list(params)
    return robots, robots


__all__ = ["BatchSim", "BatchResult", "step_parts", "robot_params", "IR_FIELDS", "CYCLE_S", "SUBSTEPS"]
