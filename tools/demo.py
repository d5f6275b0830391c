"""`twinbot demo`: the paper's experiment, start to finish.

1. Both rule sets of section 5 explore the paper's room (Fig. 15), with the
   firmware in the loop (SIL), fixed step: trajectory pictures, coverage
   over time, collisions.
2. The repeatability experiment of section 4: two real-time runs from
   identical conditions (variable step from the wall clock) and two
   fixed-step runs; the real-time pair drifts apart, the fixed pair is
   identical bit for bit.

Pictures go to --out (default demo/).  `twinbot demo --loopback` shows the
serial protocol on its own instead.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from tools.cli import CliError


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=__doc__.split("\n\n", 1)[1],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="demo", help="folder for the pictures (default demo/)")
    p.add_argument("--duration", type=float, default=180.0, help="simulated seconds per exploration (default 180)")
    p.add_argument("--world", default="paper_room", help="world to explore (default paper_room)")
    p.add_argument("--repeat-duration", type=float, default=40.0,
                   help="simulated seconds of each repeatability run (default 40)")
    p.add_argument("--repeat-speed", type=float, default=15.0,
                   help="real-time runs go at this many times real time (default 15)")
    p.add_argument("--loopback", action="store_true", help="show the serial protocol on loop:// instead")
    p.add_argument("--record", default="recordings/demo-frames.jsonl", help=argparse.SUPPRESS)
    p.add_argument("--port", default="loop://", help=argparse.SUPPRESS)
    p.set_defaults(func=run)


def identical(a, b) -> bool:  # type: ignore[no-untyped-def]
    return a.pose.shape == b.pose.shape and bool(np.array_equal(a.pose, b.pose))


def run(args: argparse.Namespace) -> int:
    if args.loopback:
        from tools import loopback_demo

        return loopback_demo.run(args)
    from host_sim.sil import SilController
    from host_sim.params import DEFAULT
    from host_sim.simulation import Simulation
    from host_sim.world import WorldError, world_by_name_or_path
    from host_sim.figures import save_coverage, save_runs
    from tools.sim import Progress, summary

    try:
        world = world_by_name_or_path(args.world, DEFAULT.body_radius)
    except WorldError as exc:
        raise CliError(str(exc)) from None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    print(f"1. exploration of {world.name}, up to {args.duration:.0f} s per rule set or until the robot finds "
          "the exit; firmware in the loop (SIL), fixed step")
    runs = {}
    for rules, rule_set in (("first", 0), ("refined", 1)):
        progress = Progress(args.duration, f"{rules} rule set")
        try:
            runs[rules] = Simulation(world, DEFAULT, SilController(rule_set), seed=1).run_fixed(
                args.duration, progress=progress, stop_at_exit=True)
        finally:
            progress.close()
        print("   " + summary(runs[rules], f"{rules:>7}: "))
    pic = save_runs(out / "exploration.png", world, list(runs.values()),
                    [_title("first", runs["first"]), _title("refined", runs["refined"])],
                    DEFAULT.body_radius, f"{world.name}: the paper's exploration task")
    cov = save_coverage(out / "coverage.png", list(runs.values()), ["first rule set", "refined rule set"])
    print(f"   pictures: {pic}, {cov}")

    print(f"2. repeatability (paper Fig. 15): {args.repeat_duration:.0f} s runs, refined rules, same start, same seed")
    pair = []
    for k in range(2):
        progress = Progress(args.repeat_duration, f"real-time run {k + 1}")
        try:
            pair.append(Simulation(world, DEFAULT, SilController(1), seed=2).run_realtime(
                args.repeat_duration, speed=args.repeat_speed, progress=progress))
        finally:
            progress.close()
    fixed = [Simulation(world, DEFAULT, SilController(1), seed=2).run_fixed(args.repeat_duration) for _ in range(2)]
    gap = _final_gap(pair[0], pair[1])
    print(f"   real time ({args.repeat_speed:g}x, variable step): "
          f"{'identical' if identical(*pair) else 'different'}; final positions {gap * 100:.1f} cm apart "
          f"(largest gap on the way {_max_gap(pair[0], pair[1]) * 100:.1f} cm)")
    print(f"   fixed step: {'identical, bit for bit' if identical(*fixed) else 'DIFFERENT (a bug)'}")
    pic = save_runs(out / "repeatability.png", world, pair + fixed,
                    ["real time, run A", "real time, run B", "fixed step, run A", "fixed step, run B"],
                    DEFAULT.body_radius, "Same start, same seed: variable steps drift apart, fixed steps do not")
    print(f"   picture: {pic}")
    return 0 if identical(*fixed) else 1


def _title(rules: str, run) -> str:  # type: ignore[no-untyped-def]
    found = f"exit found at {run.exit_time:.0f} s" if run.exit_time is not None else "no exit"
    return f"{rules} rule set: {found}, {100 * run.coverage[-1]:.0f} % covered, {run.collisions} collisions"


def _max_gap(a, b) -> float:  # type: ignore[no-untyped-def]
    n = min(len(a.pose), len(b.pose))
    return float(np.hypot(*(a.pose[:n, :2] - b.pose[:n, :2]).T).max()) if n else math.nan


def _final_gap(a, b) -> float:  # type: ignore[no-untyped-def]
    n = min(len(a.pose), len(b.pose))
    if not n:
        return math.nan
    return float(math.hypot(*(a.pose[n - 1, :2] - b.pose[n - 1, :2])))
