"""The wheel_speed drive's own speed loop: a PI on each wheel's encoder speed, its output volts across the motor.

Robots that take wheel-speed set-points (an e-puck, a Thymio) run such a loop on their own board at a fixed
period; its output drives the H-bridge as a voltage command does (drivetrain_effects.py).  docs/motors.md "Drives".
"""
from __future__ import annotations

from typing import Any

import numpy as np


class SpeedLoop:
    """N robots' loops: each period it measures the wheel speed from the encoder counts over the last period,
    and holds kp e + ki integral(e) (clipped to the supply, the integral too: no wind-up) until the next."""

    def __init__(self, kp: np.ndarray, ki: np.ndarray, period: np.ndarray, on: np.ndarray) -> None:
        self.kp, self.ki, self.period = kp[:, None], ki[:, None], period
        self.on = on  # (N,) bool: robots whose drive is wheel_speed (the others' commands pass through)
        self.integral = np.zeros((len(on), 2))
        self.out = np.zeros((len(on), 2))
        self.next_t: np.ndarray | None = None  # (N,) when each loop runs next
        self.angle = np.zeros((len(on), 2))  # the encoders' angles at the last run
        self.last_t = np.zeros(len(on))  # and its time

    def hold(self, volts: np.ndarray) -> None:
        """Each loop as if it had been holding its wheels: its integral (and output) at volts (N, 2), within the
        supply (the caller's: drivetrain_effects.holding_volts); a twin started mid-run (a diagnosis window)
        does not wind up from 0
        (tests/test_simulation.py::test_sim_runs_a_wheel_speed_robot_and_its_recording_replays)."""
        held = np.where(self.on[:, None], volts, 0.0)
        self.integral, self.out = held.copy(), held.copy()

    def command(self, set_point: Any, t: Any, angle: np.ndarray, speed: np.ndarray, volts: np.ndarray
                ) -> np.ndarray:
        """(N, 2) the commands in force now: the loops' volts for wheel_speed robots, set_point for the others.
        t: now (s, scalar or (N,)); angle: the encoders' counts as wheel angles (N, 2); speed: the wheels' true
        speeds (the first run's measurement, with no period behind it); volts: the supply (N,)."""
        set_point = np.broadcast_to(np.asarray(set_point, dtype=float), angle.shape)
        t = np.broadcast_to(np.asarray(t, dtype=float), self.period.shape)
        if self.next_t is None:
            run, measured, elapsed = np.ones(len(t), dtype=bool), speed, self.period
            self.next_t = t.copy()
        else:
            run = t >= self.next_t - 1e-9 * self.period  # the substeps' sum of dt: rounding
            elapsed = np.where(run, t - self.last_t, 1.0)  # a substep longer than the period: every substep
            measured = (angle - self.angle) / elapsed[:, None]
        if run.any():
            err = set_point - measured
            cap = volts[:, None]
            integral = np.clip(self.integral + self.ki * err * elapsed[:, None], -cap, cap)
            out = np.clip(self.kp * err + integral, -cap, cap)
            self.integral = np.where(run[:, None], integral, self.integral)
            self.out = np.where(run[:, None], out, self.out)
            self.angle = np.where(run[:, None], angle, self.angle)
            self.last_t = np.where(run, t, self.last_t)
            self.next_t = np.where(run, np.maximum(self.next_t + self.period, t), self.next_t)
        return np.where(self.on[:, None], self.out, set_point)
