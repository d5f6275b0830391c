"""The plant robot's own wheel-speed loop: a PI on each wheel's encoder speed whose output volts drive the H-bridge.

A robot that takes wheel-speed set-points runs it on its board: every period it counts the encoder edges
since the last run, and holds kp e + ki integral(e) (clipped to the battery, the integral too) until the next.
docs/proving-ground.md, "Drives".
"""
from __future__ import annotations

import math


class WheelSpeedLoop:
    """Both wheels' loops: `volts(t, ticks, set_points, v_bat)` once a plant step, the volts held between runs."""

    def __init__(self, kp: float, ki: float, period: float, ticks_per_rev: float) -> None:
        self.kp, self.ki, self.period = kp, ki, period
        self.rad_per_tick = 2 * math.pi / ticks_per_rev  # what the board believes a count is
        self.integral = [0.0, 0.0]
        self.out = [0.0, 0.0]
        self.last: tuple[float, tuple[int, int]] | None = None  # (t, counts) at the last run

    def volts(self, t: float, ticks: tuple[int, int], set_points: tuple[float, float],
              v_bat: float) -> tuple[float, float]:
        if self.last is None:
            self.last = (t, ticks)  # the first run: no period behind it, no speed measured yet
        elif t >= self.last[0] + self.period - 1e-9:
            elapsed = t - self.last[0]
            for k in range(2):
                speed = (ticks[k] - self.last[1][k]) * self.rad_per_tick / elapsed
                err = set_points[k] - speed
                self.integral[k] = min(max(self.integral[k] + self.ki * err * elapsed, -v_bat), v_bat)
                self.out[k] = min(max(self.kp * err + self.integral[k], -v_bat), v_bat)
            self.last = (t, ticks)
        return self.out[0], self.out[1]
