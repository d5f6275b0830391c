"""A Simulation stepped from outside, a frame at a time: the loops of `twinbot gui` (docs/gui.md).

An interactive front end owns its loop and asks the simulation to catch up once per frame.
`LiveStepper.fixed(seconds)` runs whole control periods and owes the rest to the next call,
so its trajectory is run_fixed's bit for bit however the frames cut it; `clock(big_dt)` is
one pass of run_realtime's loop.  `before_control` runs just before each control instant:
the place to queue a host command for the cycle it belongs to.
"""
from __future__ import annotations

import math
from typing import Callable

from host_sim.loops.simulation import ControlGrid, Simulation


class LiveStepper:
    def __init__(self, sim: Simulation, before_control: Callable[[], None] | None = None) -> None:
        self.sim = sim
        self.before_control = before_control
        self.owed = 0.0  # fixed step: simulated seconds asked for but not yet a whole period
        self.grid = ControlGrid(sim.robot.t, sim.cycle_s)  # real time: the 40 ms control instants
        self.missed = 0  # real time: control instants skipped by passes longer than a period
        self.passes = 0

    def _control(self) -> None:
        if self.before_control is not None:
            self.before_control()
        self.sim.control()

    def fixed(self, seconds: float) -> int:
        """Advance by whole control periods worth `seconds` (plus what was owed); returns the periods run."""
        sim = self.sim
        cycle = sim.cycle_s
        self.owed += seconds
        periods = int(self.owed // cycle)
        self.owed -= periods * cycle
        dt = cycle / sim.substeps
        robot = sim.robot
        for _ in range(periods):
            self._control()
            for _ in range(sim.substeps):
                robot.advance(dt)
            sim.steps += sim.substeps
        if periods:
            self.grid.restart(robot.t)  # a switch to real time continues the grid from here
        return periods

    def step_period(self) -> None:
        """Exactly one control period, fixed step (single-step of a paused run)."""
        self.owed = 0.0
        self.fixed(self.sim.cycle_s)

    def clock(self, big_dt: float) -> None:
        """One pass of the real-time loop with Dt = big_dt simulated seconds."""
        sim = self.sim
        robot, cycle = sim.robot, sim.cycle_s
        behind = self.grid.due(robot.t)
        if behind is not None:
            self._control()
            self.missed += behind
        if big_dt <= 0:
            return
        n = max(1, math.ceil(big_dt / (cycle / sim.substeps)))
        for _ in range(n):
            robot.advance(big_dt / n)
        sim.steps += n
        self.passes += 1
        self.owed = 0.0
