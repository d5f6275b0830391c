"""The simulation loop of the paper's section 4: fixed step and real time (docs/paper-reproduction.md).

Every 40 ms control period the controller gets the robot's readings and sets its currents;
between control instants the physics advances.  `run_fixed` splits each period into n
equal substeps: nothing depends on the clock, so runs repeat bit for bit.  `run_realtime`
(the paper's variable step) integrates the wall time since its last pass, times `speed`, in
n substeps and runs the controller at the first pass at or after each 40 ms instant, so
runs from identical conditions can part (host_sim/loops/repeatability.py).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from host_sim.controller.hardware_io import CYCLE_S, Actuate, Sense, firmware_command
from host_sim.loops.coverage import Coverage
from host_sim.robot.sim_robot import SimRobot
from host_sim.physics.params import RobotParams
from host_sim.recordings.recording import RecordingWriter
from host_sim.physics.world import World




@dataclass
class RunResult:
    t: np.ndarray  # (n,) s, at each control instant
    pose: np.ndarray  # (n, 3) x, y, phi
    cmd: np.ndarray  # (n, 2) current references, A
    coverage: np.ndarray  # (n,) covered fraction
    collisions: int
    wall_seconds: float
    sim_seconds: float
    mode: str
    controller: str
    steps: int  # physics substeps taken
    exit_time: float | None = None  # when the robot's centre first left the world's area (found the exit)
    extra: dict[str, object] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        return self.sim_seconds / self.wall_seconds if self.wall_seconds > 0 else math.inf

    def time_to(self, level: float) -> float | None:
        hit = np.nonzero(self.coverage >= level)[0]
        return float(self.t[hit[0]]) if len(hit) else None


GRID_SLACK = 1e-9  # of a period: substeps that add up to an instant may fall short of it by rounding


class ControlGrid:
    """The real-time loop's 40 ms control instants, origin + k * cycle, kept as a whole count k.

    The instants are computed from the count, never summed: a sum drifts (98 periods of 0.04 s
    make 3.9200000000000026), and a pass that lands on an instant would then find it a hair
    ahead, or count one period too few as jumped over.  The simulated time is itself a sum of
    substeps, so a time within GRID_SLACK of a period short of an instant has reached it.
    """

    def __init__(self, origin: float, cycle: float) -> None:
        self.cycle = cycle
        self.restart(origin)

    def restart(self, origin: float) -> None:
        """The next instant is `origin` and the grid continues from it."""
        self.origin, self.next = origin, 0

    def due(self, t: float) -> int | None:
        """None while the next instant is ahead of t; else the instants jumped over, and the grid
        moves on to the first instant after t."""
        reached = math.floor((t - self.origin) / self.cycle + GRID_SLACK)
        if reached < self.next:
            return None
        behind = reached - self.next
        self.next = reached + 1
        return behind


class Simulation:
    def __init__(self, world: World, params: RobotParams, controller: object, *, seed: int | None = 0,
                 noise: bool = True, substeps: int = 8, cycle_s: float = CYCLE_S,
                 pose: tuple[float, float, float] | None = None, recorder: RecordingWriter | None = None,
                 coverage_resolution: float = 0.05) -> None:
        if substeps < 1:
            raise ValueError("substeps must be >= 1")
        self.world = world
        self.params = params
        self.controller = controller
        self.robot = SimRobot(world, params, pose, seed, noise)
        self.substeps = substeps
        self.cycle_s = cycle_s
        self.recorder = recorder
        self._rows = _RecordingRows(recorder, controller, params) if recorder is not None else None
        self.coverage = Coverage(world, params.body_radius, coverage_resolution)
        self._t: list[float] = []
        self._pose: list[tuple[float, float, float]] = []
        self._cmd: list[tuple[float, float]] = []
        self.steps = 0
        self.exit_time: float | None = None
        w, h = world.size

        def outside(x: float, y: float) -> bool:
            return x < 0.0 or y < 0.0 or x > w or y > h

        self._outside = outside

    def record_to(self, recorder: RecordingWriter | None) -> None:
        """Start writing every control cycle to `recorder` from now on; None stops (the caller closes it)."""
        if self._rows is not None:
            self._rows.finish()
        self.recorder = recorder
        self._rows = _RecordingRows(recorder, self.controller, self.params) if recorder is not None else None

    # One control instant: readings -> controller -> currents; log it.
    def control(self) -> None:
        robot = self.robot
        pose = robot.pose
        s: Sense = robot.sense()
        a: Actuate = self.controller.cycle(s)  # type: ignore[attr-defined]
        robot.actuate(a)
        cmd = (a.i_left_ma / 1000.0, a.i_right_ma / 1000.0)
        self._t.append(robot.t)
        self._pose.append(pose)
        self._cmd.append(cmd)
        self.coverage.add(pose[0], pose[1])
        if self.exit_time is None and self._outside(pose[0], pose[1]):
            self.exit_time = robot.t
        if self._rows is not None:
            self._rows.cycle(robot.t, pose, s, a, robot.emitter_used)

    def run_fixed(self, duration: float, speed: float = math.inf,
                  progress: Callable[[float], None] | None = None, stop_at_exit: bool = False,
                  stop: Callable[[], bool] | None = None) -> RunResult:
        """Fixed step: n substeps of cycle/n per control period; exactly repeatable.

        stop_at_exit: end the run when the robot leaves the world's area (it found the exit).
        stop: checked before each period; with an infinite duration, the run ends only when it says so
        (a twin in lockstep with an emulated board, host_sim/board/board_twin.py).
        """
        n_cycles = int(round(duration / self.cycle_s)) if math.isfinite(duration) else -1
        dt = self.cycle_s / self.substeps
        robot = self.robot
        start = time.perf_counter()
        k = -1
        while k + 1 != n_cycles and not (stop and stop()):
            k += 1
            self.control()
            if stop_at_exit and self.exit_time is not None:
                break
            for _ in range(self.substeps):
                robot.advance(dt)
            self.steps += self.substeps
            if speed != math.inf:
                ahead = (k + 1) * self.cycle_s / speed - (time.perf_counter() - start)
                if ahead > 0:
                    time.sleep(ahead)
            if progress and k % 25 == 0:
                progress(robot.t)
        return self._result("fixed", time.perf_counter() - start)

    def run_realtime(self, duration: float, speed: float = 1.0, min_step: float = 0.002,
                     progress: Callable[[float], None] | None = None,
                     stop: Callable[[], bool] | None = None, stop_at_exit: bool = False) -> RunResult:
        """The paper's loop: the step comes from the clock, control runs at the pass where a period ended.

        Each pass: Dt = (wall seconds since the last pass) * speed, waiting
        first until it is at least `min_step` simulated seconds; Dt is
        integrated in n substeps of Dt / n, each at most cycle / substeps;
        then, if the simulated time has reached the next control instant,
        the sensors are read and the controller runs now.  Runs until
        `duration` simulated seconds, or until stop() says so.
        RunResult.extra: "passes", "max_pass" (largest Dt, s),
        "missed_periods" (control instants a long pass jumped over).
        """
        if not speed > 0 or math.isinf(speed):
            raise ValueError("real-time mode needs a finite speed factor > 0")
        if not min_step > 0:
            raise ValueError("min_step must be > 0 simulated seconds")
        robot, cycle = self.robot, self.cycle_s
        h_max = cycle / self.substeps
        min_wall = min_step / speed
        grid = ControlGrid(robot.t, cycle)  # the 40 ms grid keeps its phase
        passes, missed, max_pass = 0, 0, 0.0
        start = last = time.perf_counter()
        while robot.t < duration and not (stop and stop()):
            behind = grid.due(robot.t)
            if behind is not None:  # the clock says a period has elapsed: sense and control here
                self.control()
                missed += behind  # whole periods this pass jumped over
                if stop_at_exit and self.exit_time is not None:
                    break
            now = time.perf_counter()
            if now - last < min_wall:
                time.sleep(min_wall - (now - last))
                now = time.perf_counter()
            big_dt = min((now - last) * speed, duration - robot.t)
            last = now
            n = max(1, math.ceil(big_dt / h_max))
            for _ in range(n):
                robot.advance(big_dt / n)
            self.steps += n
            passes += 1
            max_pass = max(max_pass, big_dt)
            if progress:
                progress(robot.t)
        result = self._result("realtime", time.perf_counter() - start)
        result.extra.update(passes=passes, max_pass=max_pass, missed_periods=missed)
        return result

    def _result(self, mode: str, wall: float) -> RunResult:
        if self._rows is not None:
            self._rows.finish()
        return RunResult(
            t=np.array(self._t), pose=np.array(self._pose).reshape(-1, 3), cmd=np.array(self._cmd).reshape(-1, 2),
            coverage=np.array(self.coverage.fractions), collisions=self.robot.collisions, wall_seconds=wall,
            sim_seconds=self.robot.t, mode=mode, controller=getattr(self.controller, "name", "?"), steps=self.steps,
            exit_time=self.exit_time,
        )


TRUTH_KEPT = 64  # cycles whose TELEMETRY may still be on its way (PIL: a few at most)


class _RecordingRows:
    """Rows of a recording, one per control cycle, written as the robot would write them.

    With the firmware in the loop (SIL, PIL) a row is the firmware's TELEMETRY
    for that cycle, exactly what `twinbot serial --record` writes from a real
    robot, plus the simulator's truth (time and pose) as the tracker columns;
    TELEMETRY is matched to its cycle by the tick, since over PIL's serial
    port it may arrive a cycle late.  A controller without firmware (a
    replay) gives its readings and outputs directly.  The commands are
    written as they reach the robot's drive, in its unit (firmware_command).
    """

    def __init__(self, writer: RecordingWriter, controller: object, params: RobotParams) -> None:
        self.writer = writer
        self.command = firmware_command(params)
        self.telemetry: Callable[..., list[dict[str, object]]] | None = getattr(controller, "telemetry", None)
        # tick -> (time, pose, emitter power in force): the simulator's truth for the row of that cycle
        self.truth: dict[int, tuple[float, tuple[float, float, float], int]] = {}

    def cycle(self, t: float, pose: tuple[float, float, float], s: Sense, a: Actuate, emitter_pct: int) -> None:
        if self.telemetry is None:
            cmd = (self.command(a.i_left_ma), self.command(a.i_right_ma))
            self.writer.row(t, cmd, (s.enc_l, s.enc_r), s.adc_on, s.adc_off, s.vbat_mv / 1000.0, pose,
                            emitter_pct=emitter_pct)
            return
        self.truth[s.tick_ms] = (t, pose, emitter_pct)
        if len(self.truth) > TRUTH_KEPT:  # a cycle the firmware never reported (it faulted): forget it
            del self.truth[next(iter(self.truth))]
        self._write(self.telemetry())

    def finish(self) -> None:
        if self.telemetry is not None and self.truth:
            self._write(self.telemetry(wait=0.5))  # PIL: the last frames may still be on the wire

    def _write(self, frames: list[dict[str, object]]) -> None:
        for f in frames:
            truth = self.truth.pop(int(f["tick_ms"]), None)  # type: ignore[call-overload]
            if truth is not None:  # else a frame from before this run
                refs = int(f["i_ref_l_ma"]), int(f["i_ref_r_ma"])  # type: ignore[call-overload]
                cmd = (self.command(refs[0]), self.command(refs[1]))
                self.writer.telemetry(f, t=truth[0], pose=truth[1], emitter_pct=truth[2], cmd=cmd)
