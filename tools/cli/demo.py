"""`twinbot demo`: the paper's experiment, start to finish (docs/paper-reproduction.md).

Both rule sets explore the paper's room with the firmware in the loop (trajectories,
coverage over time, collisions); then the repeatability experiment of section 4: pairs of
runs from identical conditions at a decision point split with the step from the wall clock,
and never with a fixed step.  Pictures go to --out (default demo/); --loopback shows the
serial protocol on its own instead.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tools.arguments import int_range, output_folder, positive_float, sim_seconds, writing
from tools.arguments import CliError
from tools.cli.sim import plural


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=__doc__.split("\n\n", 1)[1],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="demo", type=output_folder, help="folder for the pictures (default demo/)")
    p.add_argument("--duration", type=sim_seconds(), default=180.0,
                   help="simulated seconds per exploration (default 180)")
    p.add_argument("--world", default="paper_room", help="world to explore (default paper_room)")
    p.add_argument("--repeat-duration", type=sim_seconds(), default=30.0,
                   help="simulated seconds of each repeatability run (default 30)")
    p.add_argument("--repeat-speed", type=positive_float, default=25.0,
                   help="real-time runs go at this many times real time (default 25)")
    p.add_argument("--pairs", type=int_range(1, 1000), default=20, help="pairs of runs of each kind (default 20)")
    p.add_argument("--loopback", action="store_true", help="show the serial protocol on loop:// instead")
    p.add_argument("--record", default="recordings/demo-frames.jsonl", type=output_folder_file,
                   help=argparse.SUPPRESS)
    p.add_argument("--port", default="loop://", help=argparse.SUPPRESS)
    p.set_defaults(func=run)


def output_folder_file(text: str) -> str:
    """The loopback demo's frame log: a file whose folder may still have to be made."""
    output_folder(str(Path(text).parent))
    if Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a folder; give a file name")
    return text


def run(args: argparse.Namespace) -> int:
    if args.loopback:
        from tools.cli import loopback_demo

        return loopback_demo.run(args)
    from host_sim.controller.sil import SilController
    from host_sim.physics.params import DEFAULT
    from host_sim.loops.simulation import Simulation
    from host_sim.physics.world import WorldError, world_by_name_or_path
    from host_sim.figures.runs import save_coverage, save_runs
    from tools.cli.sim import Progress, summary

    try:
        world = world_by_name_or_path(args.world, DEFAULT.body_radius)
    except WorldError as exc:
        raise CliError(str(exc)) from None
    out = Path(args.out)
    with writing("--out", out):
        out.mkdir(parents=True, exist_ok=True)

    print(f"1. exploration of {world.name}, up to {args.duration:.0f} s per rule set or until the robot finds "
          "the exit; firmware in the loop (SIL), fixed step")
    runs = {}
    # the paper's explorers alone (the stall guard off), then the first one as the firmware runs it
    for rules, rule_set, guard in (("first", 0, False), ("refined", 1, False), ("guarded", 0, True)):
        progress = Progress(args.duration, f"{rules} rule set" if rules != "guarded" else "first + stall guard")
        controller = SilController(rule_set, stall_guard=guard)
        try:
            runs[rules] = Simulation(world, DEFAULT, controller, seed=1).run_fixed(
                args.duration, progress=progress, stop_at_exit=True)
        finally:
            progress.close()
        line = summary(runs[rules], f"{rules:>7}: ")
        if guard:
            line += f"; the first rule set with the firmware's stall guard: {controller.robot.stall.escapes} escapes"
        print("   " + line)
    runs.pop("guarded")  # the pictures show the paper's two
    with writing("--out", out):
        pic = save_runs(out / "exploration.png", world, list(runs.values()),
                        [_title("first", runs["first"]), _title("refined", runs["refined"])],
                        DEFAULT.body_radius, f"{world.name}: the paper's exploration task")
        cov = save_coverage(out / "coverage.png", list(runs.values()), ["first rule set", "refined rule set"])
    print(f"   pictures: {pic}, {cov}")

    fixed_ok = _repeatability(args, out)
    return 0 if fixed_ok else 1


def _repeatability(args: argparse.Namespace, out: Path) -> bool:
    """Part 2: the split rate of real-time pairs against fixed-step pairs, and the picture."""
    import dataclasses

    from host_sim.physics.params import DEFAULT
    from host_sim.loops.repeatability import ForkScenario, fork_heading, route_gap, split_experiment
    from host_sim.physics.world import builtin_world
    from host_sim.figures.runs import save_pairs

    if args.pairs < 1 or not args.repeat_duration > 0 or not args.repeat_speed > 0:
        raise CliError("--pairs, --repeat-duration and --repeat-speed must be > 0")
    sc = dataclasses.replace(ForkScenario(), duration=args.repeat_duration)
    heading = fork_heading(sc)
    print(f"2. repeatability (paper Fig. 15): {sc.rules} rule set in {sc.world}, start ({sc.x:.2f}, {sc.y:.2f}) m "
          f"heading {heading:.6f} rad (where fixed-step runs fork between turning left and right at the wall), "
          f"noise seed {sc.seed}, {sc.duration:.0f} s runs; {args.pairs} pairs of each kind")
    bar = _PairProgress(args.pairs)
    try:
        rep = split_experiment(sc, args.pairs, args.repeat_speed, heading=heading, progress=bar)
    finally:
        bar.close()
    thr = sc.threshold
    rt, fx = rep.realtime, rep.fixed
    print(f"   real time ({args.repeat_speed:g}x, step from the clock): {rt.splits(thr)} of {args.pairs} pairs split "
          f"(routes > {thr:g} m apart at the same time; largest gap {max(rt.gaps):.2f} m), "
          f"in {rt.opposite_turns()} of them one run turned left at the wall and the other right")
    fixed_ok = all(fx.identical)
    print(f"   fixed step: {fx.splits(thr)} of {args.pairs} pairs split; "
          f"{'every pair identical, bit for bit' if fixed_ok else 'pairs DIFFER (a bug)'}")
    world = builtin_world(sc.world, DEFAULT.body_radius)
    a, b = rt.example  # type: ignore[misc]
    with writing("--out", out):
        pic = save_pairs(out / "repeatability.png", world, [rt.example, fx.example],  # type: ignore[list-item]
                         [f"step from the clock ({args.repeat_speed:g}x): routes up to {route_gap(a, b):.2f} m apart",
                          "fixed step: the two routes are identical"],
                         DEFAULT.body_radius,
                         f"Same start, same firmware, same noise seed: {rt.splits(thr)}/{args.pairs} real-time "
                         f"pairs split, {fx.splits(thr)}/{args.pairs} fixed-step pairs")
    print(f"   picture: {pic}")
    return fixed_ok


class _PairProgress:
    """One progress bar per kind of pair."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.bars: dict[str, object] = {}

    def __call__(self, mode: str, done: int) -> None:
        from tqdm import tqdm

        if mode not in self.bars:
            self.close()
            self.bars[mode] = tqdm(total=self.total, desc=f"{mode} pairs", unit="pair", file=sys.stderr,
                                   disable=not sys.stderr.isatty())
        self.bars[mode].update(1)  # type: ignore[attr-defined]

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()  # type: ignore[attr-defined]
        self.bars = {}


def _title(rules: str, run) -> str:  # type: ignore[no-untyped-def]
    found = f"exit found at {run.exit_time:.0f} s" if run.exit_time is not None else "no exit"
    return (f"{rules} rule set: {found}, {100 * run.coverage[-1]:.0f} % covered, "
            f"{plural(run.collisions, 'collision')}")
