"""Proof of the late-signal twin: the robot is the simulator, the link is late (docs/late-signal-twin.md).

The simulator with the firmware in SIL is driven by a scripted host through the
identification manoeuvre; every TELEMETRY frame reaches the host `mean_s +
U(-jitter_s, +jitter_s)` late (simulated time, seeded, in order).  At every control instant
the ghost's prediction and the raw late pose are compared with the true pose, in the
odometry's frame.  The plant shares no code with the ghost (tests/test_ghost.py).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from host_sim.loops.excitation import Manoeuvre, odometry_of, reflected_of
from host_sim.loops.late_signal_twin import Ghost
from host_sim.controller.hardware_io import Actuate, Sense
from host_sim.physics.params import RobotParams
from host_sim.controller.sil import SilController
from protocol import messages as M
from protocol.framing import FrameEncoder


@dataclass
class LateRun:
    mean_s: float
    jitter_s: float
    ghost_err: list[float] = field(default_factory=list)  # m, each control instant
    raw_err: list[float] = field(default_factory=list)
    latency_est: list[float] = field(default_factory=list)  # s, each frame
    latency_true: list[float] = field(default_factory=list)


class LateHost:
    """The scripted host behind a late link: a controller for Simulation wrapping the SIL firmware."""

    def __init__(self, params: RobotParams, mean_s: float, jitter_s: float, seed: int, floor_s: float) -> None:
        self.sil = SilController(params=params)
        self.manoeuvre = Manoeuvre(radius=0.4)
        self.rng = np.random.default_rng(seed)
        self.mean_s, self.jitter_s = mean_s, jitter_s
        self.ghost = Ghost(2 * params.half_axle, 2 * params.wheel_radius, params.ticks_per_rev, floor_s=floor_s)
        self._in_flight: deque[tuple[float, dict[str, object]]] = deque()
        self._last_arrival = -math.inf
        self._seen: dict[str, object] | None = None
        self._enc = FrameEncoder()
        self.truth = lambda: (0.0, 0.0, 0.0)  # set by run_late: the simulator's true pose
        self.start = (0.0, 0.0, 0.0)
        self.run = LateRun(mean_s, jitter_s)

    def _post(self, now: float) -> None:
        """Put the firmware's new frames on the wire; deliver the ones due by `now`."""
        for frame in self.sil.telemetry():
            tick_s = int(frame["tick_ms"]) / 1000.0  # type: ignore[call-overload]
            delay = max(0.0, self.mean_s + self.rng.uniform(-self.jitter_s, self.jitter_s))
            arrival = max(tick_s + delay, self._last_arrival)
            self._last_arrival = arrival
            self._in_flight.append((arrival, frame))
        while self._in_flight and self._in_flight[0][0] <= now + 1e-9:
            arrival, frame = self._in_flight.popleft()
            self.ghost.on_telemetry(frame, arrival)
            self.run.latency_est.append(self.ghost.latency_s or 0.0)
            self.run.latency_true.append(arrival - int(frame["tick_ms"]) / 1000.0)  # type: ignore[call-overload]
            self._seen = frame

    def _score(self, now: float) -> None:
        ghost, raw = self.ghost.predict(now), self.ghost.raw_pose()
        if ghost is None or raw is None:
            return
        true = in_start_frame(self.truth(), self.start)
        self.run.ghost_err.append(math.hypot(ghost[0] - true[0], ghost[1] - true[1]))
        self.run.raw_err.append(math.hypot(raw[0] - true[0], raw[1] - true[1]))

    def cycle(self, s: Sense) -> Actuate:
        now = s.tick_ms / 1000.0  # host clock = simulated time; the robot's tick is its own clock
        self._post(now)
        self._score(now)
        left, right = self.manoeuvre.command(now, reflected_of(self._seen), odometry_of(self._seen))
        payload = M.pack_payload(M.COMMAND, {"mode": M.MODE_HOST, "left": left, "right": right})
        self.sil.send(self._enc.encode(M.COMMAND, payload))
        self.ghost.on_command(now, left, right)
        return self.sil.cycle(s)

    def telemetry(self, wait: float = 0.0) -> list[dict[str, object]]:
        return []

    def close(self) -> None:
        self.sil.close()


def in_start_frame(pose: tuple[float, float, float], start: tuple[float, float, float]) -> tuple[float, float, float]:
    """A world pose relative to the start pose (the odometry's frame)."""
    dx, dy = pose[0] - start[0], pose[1] - start[1]
    c, s = math.cos(start[2]), math.sin(start[2])
    return c * dx + s * dy, -s * dx + c * dy, pose[2] - start[2]


def run_late(mean_s: float, jitter_s: float, *, seed: int = 0, duration: float = 20.0,
             world_name: str = "arena", floor_s: float | None = None) -> LateRun:
    """One run behind a late link; floor_s: the link's fastest delivery the host is told (default: the true one)."""
    from host_sim.loops.simulation import Simulation
    from host_sim.physics.world import builtin_world

    params = RobotParams()
    world = builtin_world(world_name, params.body_radius)
    floor = max(0.0, mean_s - jitter_s) if floor_s is None else floor_s
    host = LateHost(params, mean_s, jitter_s, seed, floor)
    sim = Simulation(world, params, host, seed=seed)
    host.start = sim.robot.pose
    host.truth = lambda: sim.robot.pose
    sim.run_fixed(duration)
    return host.run
