"""The paper's repeatability experiment (section 4, Fig. 15), measured (docs/paper-reproduction.md).

Runs from identical conditions are identical bit for bit with a fixed step and can take
different routes with the step from the clock.  `ForkScenario` is such a decision: the
first rule set driving almost square at the paper room's top wall.  `fork_heading` finds by
bisection the start heading where the route forks; `split_experiment` counts the pairs from
there whose routes, at the same simulated times, come farther apart than a threshold.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from host_sim.controller.hardware_io import RULE_SETS
from host_sim.physics.params import DEFAULT, RobotParams
from host_sim.controller.sil import SilController
from host_sim.loops.simulation import RunResult, Simulation
from host_sim.physics.world import World, builtin_world


@dataclass(frozen=True)
class ForkScenario:
    world: str = "paper_room"
    x: float = 1.30  # m, the start of the axle centre: 0.4 m below the top wall, 0.7 m from the exit wall
    y: float = 1.10
    headings: tuple[float, float] = (math.pi / 2 - 0.05, math.pi / 2 + 0.05)  # rad: one goes right, one left
    rules: str = "first"
    seed: int = 0  # the sensor noise's seed, the same in every run
    duration: float = 30.0  # simulated s
    threshold: float = 0.3  # m: routes farther apart than this at some time have split


def route_gap(a: RunResult, b: RunResult) -> float:
    """Largest distance (m) between two routes at the same simulated times (their common span).

    The positions are interpolated in time, so runs whose control instants
    follow the clock compare at equal times, not at equal indices.
    """
    end = min(a.t[-1], b.t[-1]) if len(a.t) and len(b.t) else 0.0
    grid = np.arange(0.0, end, 0.02)
    if not len(grid):
        return 0.0
    dx = np.interp(grid, a.t, a.pose[:, 0]) - np.interp(grid, b.t, b.pose[:, 0])
    dy = np.interp(grid, a.t, a.pose[:, 1]) - np.interp(grid, b.t, b.pose[:, 1])
    return float(np.hypot(dx, dy).max())


def _simulation(sc: ForkScenario, heading: float, world: World, params: RobotParams) -> Simulation:
    # the paper's controller alone: the stall guard (firmware 0.3.0) would back a robot that pushes the wall out
    controller = SilController(RULE_SETS[sc.rules], stall_guard=False)
    return Simulation(world, params, controller, seed=sc.seed, pose=(sc.x, sc.y, heading))


def fixed_run(sc: ForkScenario, heading: float, world: World | None = None,
              params: RobotParams = DEFAULT) -> RunResult:
    world = world or builtin_world(sc.world, params.body_radius)
    return _simulation(sc, heading, world, params).run_fixed(sc.duration)


def realtime_run(sc: ForkScenario, heading: float, speed: float, world: World | None = None,
                 params: RobotParams = DEFAULT) -> RunResult:
    world = world or builtin_world(sc.world, params.body_radius)
    return _simulation(sc, heading, world, params).run_realtime(sc.duration, speed=speed)


def first_turn(run: RunResult, threshold: float) -> int:
    """The side the robot first moves off to: +1 left, -1 right of its start heading, 0 neither.

    The first time its sideways distance from the start line exceeds
    `threshold` (m) decides.
    """
    x0, y0, h = run.pose[0]
    side = -(run.pose[:, 0] - x0) * math.sin(h) + (run.pose[:, 1] - y0) * math.cos(h)
    off = np.nonzero(np.abs(side) > threshold)[0]
    return int(np.sign(side[off[0]])) if len(off) else 0


def fork_heading(sc: ForkScenario, iterations: int = 18, params: RobotParams = DEFAULT) -> float:
    """The start heading where the robot's first turn changes side, to (headings span) / 2^iterations.

    Bisection on fixed-step runs: the two ends of the bracket turn to
    different sides; each step keeps the half whose ends still do.
    ValueError if the scenario's two headings turn to the same side.
    """
    world = builtin_world(sc.world, params.body_radius)
    lo, hi = sc.headings
    side_lo = first_turn(fixed_run(sc, lo, world, params), sc.threshold)
    if side_lo == first_turn(fixed_run(sc, hi, world, params), sc.threshold):
        raise ValueError(f"the headings {lo:.4f} and {hi:.4f} rad turn to the same side: no fork between them")
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if first_turn(fixed_run(sc, mid, world, params), sc.threshold) == side_lo:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@dataclass
class PairSet:
    mode: str  # "realtime" or "fixed"
    gaps: list[float] = field(default_factory=list)  # route_gap of each pair, m
    turns: list[tuple[int, int]] = field(default_factory=list)  # first_turn of each run of each pair
    identical: list[bool] = field(default_factory=list)  # the pair's poses and commands equal bit for bit
    example: tuple[RunResult, RunResult] | None = None  # opposite turns if any, else a split, else the first

    def splits(self, threshold: float) -> int:
        return sum(g > threshold for g in self.gaps)

    def opposite_turns(self) -> int:
        """Pairs whose two runs first turned to different sides (or one of them never turned)."""
        return sum(a != b for a, b in self.turns)


@dataclass
class SplitReport:
    scenario: ForkScenario
    heading: float
    speed: float
    realtime: PairSet
    fixed: PairSet

    def rate(self, pairs: PairSet) -> float:
        return pairs.splits(self.scenario.threshold) / len(pairs.gaps) if pairs.gaps else math.nan


def _pairs(mode: str, n: int, run: Callable[[], RunResult], threshold: float,
           progress: Callable[[str, int], None] | None) -> PairSet:
    out = PairSet(mode)
    best = -1  # the example: a pair that turned to opposite sides (2), else one that split (1), else the first
    for k in range(n):
        a, b = run(), run()
        gap = route_gap(a, b)
        turns = (first_turn(a, threshold), first_turn(b, threshold))
        out.gaps.append(gap)
        out.turns.append(turns)
        out.identical.append(a.pose.shape == b.pose.shape and bool(np.array_equal(a.pose, b.pose))
                             and bool(np.array_equal(a.cmd, b.cmd)))
        score = 2 if turns[0] != turns[1] else int(gap > threshold)
        if score > best:
            best, out.example = score, (a, b)
        if progress:
            progress(mode, k + 1)
    return out


def split_experiment(sc: ForkScenario = ForkScenario(), pairs: int = 20, speed: float = 25.0,
                     heading: float | None = None, params: RobotParams = DEFAULT,
                     progress: Callable[[str, int], None] | None = None) -> SplitReport:
    """`pairs` real-time pairs (at `speed` x real time) and `pairs` fixed-step pairs from the fork.

    heading: the start heading (default: fork_heading(sc)).  progress(mode,
    pairs done) is called after each pair.
    """
    if pairs < 1:
        raise ValueError("pairs must be >= 1")
    world = builtin_world(sc.world, params.body_radius)
    h = fork_heading(sc, params=params) if heading is None else heading
    rt = _pairs("realtime", pairs, lambda: realtime_run(sc, h, speed, world, params), sc.threshold, progress)
    fx = _pairs("fixed", pairs, lambda: fixed_run(sc, h, world, params), sc.threshold, progress)
    return SplitReport(sc, h, speed, rt, fx)
