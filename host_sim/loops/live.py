"""A Simulation stepped from outside, a frame at a time: the loops of `twinbot gui`.

`Simulation.run_fixed` and `Simulation.run_realtime` own their loop; an
interactive front end owns its own (events, drawing) and asks the
simulation to catch up once per frame.  `LiveStepper` gives it the same
two ways of stepping, with the same semantics:

- `fixed(seconds)`: whole control periods, each = read the sensors and run
  the controller, then `substeps` substeps of cycle / substeps.  Seconds
  that do not make a whole period are owed to the next call, so the
  trajectory depends only on how many periods ran, never on how the frames
  cut them: it is run_fixed's trajectory bit for bit.
- `clock(big_dt)`: one pass of the paper's real-time loop (run_realtime):
  if the simulated time has reached the next 40 ms control instant, the
  controller runs now (the grid keeps its phase; instants a long pass
  jumped over are counted in `missed`), then big_dt is integrated in
  n = ceil(big_dt / (cycle / substeps)) equal substeps.

`before_control` (optional) is called just before each control instant:
the place to queue a host command so that it reaches the firmware in the
cycle it belongs to, whatever the speed factor.
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
