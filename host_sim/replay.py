"""Replay a recording's inputs open loop, from any recorded state.

This is what identification needs: take row k of a recording (a real
robot's or the simulator's), put the model in the state recorded there,
feed it the recorded current references cycle after cycle, and compare
what the model's encoders, sensors and pose do with what was recorded.

The state at row k comes from the recording alone: the pose of C from the
tracker columns (needed), the wheel angles from the encoder counts (the
middle of the recorded tick), and the
wheel speeds from the encoder counts around row k (central differences, or
the rows after it at the start).  At row 0 of a simulator recording the
robot is at rest, so a replay from there repeats the run exactly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from host_sim import dynamics, ir_sensor, motors
from host_sim.interface import Actuate, Sense
from host_sim.sim_robot import SimRobot
from host_sim.params import RobotParams
from host_sim.recording import Recording
from host_sim.world import World


class ReplayError(ValueError):
    pass


class ReplayController:
    """A recording's current references, one row per cycle (open loop)."""

    name = "replay"

    def __init__(self, cmd_amps: list[tuple[float, float]], emitter_pct: int = 60) -> None:
        self.cmd = cmd_amps
        self.k = 0
        self.emitter_pct = emitter_pct

    def cycle(self, s: Sense) -> Actuate:
        if self.k < len(self.cmd):
            left, right = self.cmd[self.k]
        else:
            left = right = 0.0
        self.k += 1
        return Actuate(round(left * 1000), round(right * 1000), self.emitter_pct)

    def close(self) -> None:
        pass


@dataclass
class ReplayResult:
    t: np.ndarray  # (n,) s
    enc: np.ndarray  # (n, 2) simulated encoder ticks
    pose: np.ndarray  # (n, 3) simulated pose of C
    ir_on: np.ndarray  # (n, 8)
    ir_amb: np.ndarray  # (n, 8)
    start: int  # the recording row it started from


def state_at(rec: Recording, k: int, p: RobotParams) -> tuple[tuple[float, ...], tuple[float, float]]:
    """(q, v) of the model at row k, from the recording alone."""
    if rec.pose is None:
        raise ReplayError("replay from a recorded state needs the tracker pose (x, y, phi columns), "
                          "and this recording has none")
    n = len(rec)
    if not 0 <= k < n:
        raise ReplayError(f"row {k} is outside the recording (0..{n - 1})")
    x, y, phi = (float(v) for v in rec.pose[k])
    if k == 0 and rec.meta.get("source") == "simulator":
        theta = [0.0, 0.0]  # the simulator starts every run at rest, the wheels at angle 0
        v = (0.0, 0.0)
    else:
        lo, hi = (k - 1, k + 1) if 0 < k < n - 1 else ((k, k + 1) if k == 0 else (k - 1, k))
        dt = float(rec.t[hi] - rec.t[lo]) if n > 1 else 0.0
        per_tick = 2 * math.pi / p.ticks_per_rev
        v = tuple(float(rec.enc[hi, i] - rec.enc[lo, i]) * per_tick / dt if dt > 0 else 0.0
                  for i in range(2))  # type: ignore[assignment]
        # the middle of the recorded tick: the best guess, and never the tick below
        theta = [motors.encoder_angle(int(rec.enc[k, i]), p) for i in range(2)]
    q = dynamics.q_from_axle_pose(x, y, phi, p, theta[0], theta[1])
    return q, (float(v[0]), float(v[1]))


def replay(rec: Recording, p: RobotParams, world: World, start: int = 0, stop: int | None = None,
           substeps: int = 8, seed: int | None = None, nominal_timing: bool | None = None,
           exact_sensors: bool = False) -> ReplayResult:
    """Feed rows start..stop-1's current references to the model from the state at `start`.

    Steps last one sample period (nominal_timing, the default for fixed-step
    simulator recordings) or the time between recorded rows (robots).
    seed: the sensor noise seed (None: noise-free sensors).

    The inputs are open loop, so the IR ring is read for all rows at once
    after the physics (vectorised, several times faster).  exact_sensors=True
    reads it row by row as the simulation did instead, drawing the noise in
    the same order: a simulator recording then replays bit for bit.
    """
    if nominal_timing is None:
        nominal_timing = rec.meta.get("source") == "simulator" and rec.meta.get("mode") == "fixed"
    stop = len(rec) if stop is None else stop
    if not start < stop <= len(rec):
        raise ReplayError(f"rows {start}..{stop} do not fit the recording (0..{len(rec)})")
    period = rec.sample_period
    emitter = int(rec.meta.get("emitter_pct", 60))  # type: ignore[call-overload]
    robot = SimRobot(world, p, seed=seed, noise=seed is not None)
    robot.q, robot.v = state_at(rec, start, p)
    robot.t = float(rec.t[start])
    # A simulated run starts with the emitters off (no actuation yet).
    robot.emitter_pct = 0 if (start == 0 and rec.meta.get("source") == "simulator") else emitter
    controller = ReplayController([tuple(c) for c in rec.cmd[start:stop]], emitter)  # type: ignore[misc]
    n = stop - start
    enc = np.zeros((n, 2), dtype=np.int64)
    pose = np.zeros((n, 3))
    ir_on = np.zeros((n, 8), dtype=np.int64)
    ir_amb = np.zeros((n, 8), dtype=np.int64)
    t = np.zeros(n)
    power = np.zeros(n)
    for j in range(n):
        t[j] = robot.t
        pose[j] = robot.pose
        if exact_sensors:
            s = robot.sense()
            ir_on[j] = s.adc_on
            ir_amb[j] = s.adc_off
        else:
            enc_l, enc_r = robot.encoder_ticks()
            s = Sense(0, [], [], enc_l, enc_r, 0)
            power[j] = robot.emitter_pct
        enc[j] = (s.enc_l, s.enc_r)
        robot.actuate(controller.cycle(s))
        if nominal_timing or start + j + 1 >= len(rec):
            h = period / substeps
        else:
            h = (float(rec.t[start + j + 1]) - robot.t) / substeps
        for _ in range(substeps):
            robot.advance(h)
    if not exact_sensors:
        ir_amb, ir_on = ir_sensor.read_sensors_batch(world, pose, power, t, p, robot.rng)
    return ReplayResult(t, enc, pose, ir_on, ir_amb, start)
