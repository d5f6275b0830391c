"""host_sim/loops/live.py: a Simulation stepped a frame at a time keeps run_fixed's and run_realtime's semantics."""
from __future__ import annotations

import numpy as np
import pytest

from host_sim.loops.live import LiveStepper
from host_sim.physics.params import DEFAULT
from host_sim.controller.sil import SilController
from host_sim.loops.simulation import Simulation
from host_sim.physics.world import builtin_world

WORLD = builtin_world("paper_room")


def test_fixed_steps_cut_into_uneven_frames_give_run_fixed_bit_for_bit() -> None:
    ref = Simulation(WORLD, DEFAULT, SilController(1), seed=3).run_fixed(4.0)
    sim = Simulation(WORLD, DEFAULT, SilController(1), seed=3)
    live = LiveStepper(sim)
    rng = np.random.default_rng(0)
    periods = 0
    while periods < 100:
        periods += live.fixed(float(rng.uniform(0.0, 0.13)))
    while periods > 100:  # the last frame may overshoot: compare the first 100 periods
        periods -= 1
    pose = np.array(sim._pose[:100])
    assert np.array_equal(pose, ref.pose[:100])
    assert np.array_equal(np.array(sim._cmd[:100]), ref.cmd[:100])


def test_clock_passes_integrate_dt_and_control_on_the_40ms_grid() -> None:
    sim = Simulation(WORLD, DEFAULT, SilController(1), seed=3)
    calls: list[float] = []
    live = LiveStepper(sim, before_control=lambda: calls.append(sim.robot.t))
    passes = [0.017] * 30 + [0.133] + [0.017] * 10
    for dt in passes:
        live.clock(dt)
    assert sim.robot.t == pytest.approx(0.017 * 40 + 0.133)
    # Control at the first pass at or after each 40 ms instant of the grid; the 133 ms pass jumped
    # over three instants, which are skipped, not made up.
    expected, t, grid = [], 0.0, 0
    for dt in passes:
        if t >= grid * 0.040 - 1e-12:
            expected.append(t)
            grid = int(t / 0.040 + 1e-9) + 1
        t += dt
    assert calls == pytest.approx(expected, abs=1e-12) and sim._t == calls
    assert live.missed == 3 and live.passes == len(passes)


@pytest.mark.parametrize("periods", [1, 2, 3])
def test_passes_that_land_on_the_instants_control_at_each_one_they_reach(periods: int) -> None:
    """Passes of whole periods end on the grid's instants: each is reached, none is a hair ahead.

    (With the instants summed, 0.04 + 0.04 + ..., which drifts above k x 0.04, or with no slack
    for the substeps' own rounding, one period a pass controlled 239 times in 240.)"""
    sim = Simulation(WORLD, DEFAULT, SilController(1), seed=3)
    calls: list[float] = []
    live = LiveStepper(sim, before_control=lambda: calls.append(sim.robot.t))
    passes = 240 // periods
    for _ in range(passes):
        live.clock(periods * 0.040)
    assert len(calls) == passes
    assert live.missed == (passes - 1) * (periods - 1)  # the instants between controls, all counted
    assert np.allclose(np.diff(calls), periods * 0.040, rtol=0, atol=1e-9)
