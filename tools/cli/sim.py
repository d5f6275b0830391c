"""`twinbot sim`: run the simulated robot, headless, with its firmware in the loop.

The firmware explores the world with the chosen rule set, either in this
process (SIL, default) or on a virtual board under MicroPython (--pil).
Prints the coverage of the free area, the time to 90 % coverage, the
collisions and the real-time factor; --png draws the trajectory, --record
writes a recording (CSV + JSON sidecar, docs/recordings.md).  A bridge robot
(--params) takes the PWM duty the firmware's HAL makes of its current references,
a wheel_speed robot's board that duty times its top speed (docs/motors.md "Drives").
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from tools.arguments import (image_file, int_range, non_negative_int, recording_file, sim_seconds, speed_factor,
                             warn, writing)
from tools.arguments import CliError

EXAMPLES = """\
examples:
  twinbot sim --world paper_room --rules refined --duration 120 --png run.png
  twinbot sim --world maze --rules first --duration 60 --realtime --speed 10
  twinbot sim --world my_room.json --pil --record run.csv
"""


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=__doc__.split("\n\n", 1)[1], epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_arguments(p)
    p.add_argument("--record", metavar="FILE", type=recording_file,
                   help="write a recording: FILE (CSV) and FILE.json")
    p.add_argument("--png", metavar="FILE", type=image_file,
                   help="draw the world and the trajectory (any format matplotlib writes: .png, .svg, .pdf ...)")
    p.set_defaults(func=run)


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--world", default="paper_room",
                   help="built-in world (paper_room, maze, arena) or a world JSON file (default paper_room)")
    p.add_argument("--rules", choices=("first", "refined"), default="refined", help="fuzzy rule set (default refined)")
    p.add_argument("--no-stall-guard", action="store_true",
                   help="the paper's explorer alone: the firmware's stall guard off (parameter stall_ms = 0; "
                        "on, it backs a robot that is held or pushing a wall out and turns it away)")
    p.add_argument("--duration", type=sim_seconds(), default=60.0,
                   help="simulated seconds, 0.04 (one control period) to 86400 (default 60)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--fixed", dest="mode", action="store_const", const="fixed",
                      help="fixed step: exactly repeatable (default)")
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="variable step from the wall clock, as the paper's real-time loop")
    p.set_defaults(mode="fixed")
    p.add_argument("--speed", default="max", type=speed_factor,
                   help="k x real time, or 'max' (fixed step only: as fast as possible; default max, "
                        "and 1 in --realtime)")
    p.add_argument("--substeps", type=int_range(1, 1000), default=8,
                   help="physics substeps per 40 ms control period, 1..1000 (default 8)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the sensor noise, >= 0 (default 0)")
    p.add_argument("--no-noise", action="store_true", help="noise-free sensors")
    p.add_argument("--params", metavar="FILE",
                   help="robot parameters JSON (any subset; see host_sim/physics/params.py); its drive may be "
                        "any: current, voltage, duty or wheel_speed (docs/motors.md \"Drives\")")
    p.add_argument("--stop-at-exit", action="store_true",
                   help="end the run when the robot leaves the world's area (found the exit), "
                        "instead of simulating it off the map until --duration")
    p.add_argument("--pil", action="store_true",
                   help="run the firmware on a virtual board under MicroPython (processor in the loop)")
    p.add_argument("--excite", action="store_true",
                   help="drive the firmware through the identification manoeuvre (HOST mode: creep, steps, chirp, "
                        "spins, arcs, reversals, bursts; IR-guarded) instead of exploring: a recording for "
                        "twinbot diagnose")


def parse_speed(speed: str | float, mode: str) -> float:
    """The pace: 'max' is as fast as possible in fixed step, real time (1) in --realtime."""
    if speed == "max":
        return 1.0 if mode == "realtime" else math.inf
    return float(speed)


def load_inputs(args: argparse.Namespace, drives: tuple[str, ...] | None = None):  # type: ignore[no-untyped-def]
    """(params, world) from --params and --world; CliError for a robot whose drive is not among `drives`
    (default: those the firmware can run, hardware_io.FIRMWARE_DRIVES)."""
    from host_sim.controller.hardware_io import FIRMWARE_DRIVES
    from host_sim.physics.params import DEFAULT, ParamsError, load_params
    from host_sim.physics.world import WorldError, world_by_name_or_path

    try:
        params = load_params(args.params) if args.params else DEFAULT
        world = world_by_name_or_path(args.world, params.body_radius)
    except (ParamsError, WorldError) as exc:
        raise CliError(str(exc)) from None
    allowed = drives or FIRMWARE_DRIVES
    if params.drive_kind not in allowed:  # docs/motors.md "Drives"
        raise CliError(f"{args.params}: drive '{params.drive_kind}': this command runs {' or '.join(allowed)} "
                       f"drives only; its recordings replay and diagnose with its drive (twinbot replay, "
                       f"twinbot diagnose)")
    return params, world


def make_controller(args: argparse.Namespace, params=None):  # type: ignore[no-untyped-def]
    """The firmware in the loop, configured with the robot's geometry (params) as flashing it would be."""
    from host_sim.controller.hardware_io import RULE_SETS, stall_guard_off
    from host_sim.board.pil import PilController
    from host_sim.controller.sil import SilController

    rule_set = RULE_SETS[args.rules]
    try:
        if args.pil:
            controller: object = PilController(rule_set, params=params)
        else:
            controller = SilController(rule_set, params=params)
    except RuntimeError as exc:
        raise CliError(f"PIL: {exc}") from None
    except ValueError as exc:
        raise CliError(f"--params: the firmware cannot hold this robot's geometry: {exc}") from None
    if getattr(args, "no_stall_guard", False):
        controller.send(stall_guard_off())  # type: ignore[attr-defined]
    if getattr(args, "excite", False):
        from host_sim.loops.excitation import ExcitedController

        return ExcitedController(controller)
    return controller


class Progress:
    """A progress bar over simulated time (tqdm on stderr; quiet when not a terminal)."""

    def __init__(self, total: float, label: str) -> None:
        from tqdm import tqdm

        self.bar = tqdm(total=round(total, 2), desc=label, unit="sim s", file=sys.stderr,
                        disable=not sys.stderr.isatty(), bar_format="{l_bar}{bar}| {n:.1f}/{total:.0f} sim s "
                                                                    "[{elapsed}<{remaining}]")
        self.done = 0.0

    def __call__(self, t: float) -> None:
        self.bar.update(round(t - self.done, 3))
        self.done = t

    def close(self) -> None:
        self.bar.close()


def simulate(args: argparse.Namespace, params, world, recorder=None, label: str = "simulating"):  # type: ignore[no-untyped-def]
    from host_sim.loops.simulation import Simulation

    speed = parse_speed(args.speed, args.mode)
    controller = make_controller(args, params)
    progress = Progress(args.duration, label)
    try:
        sim = Simulation(world, params, controller, seed=args.seed, noise=not args.no_noise,
                         substeps=args.substeps, recorder=recorder)
        if args.mode == "realtime":
            result = sim.run_realtime(args.duration, speed=speed, progress=progress, stop_at_exit=args.stop_at_exit)
        else:
            result = sim.run_fixed(args.duration, speed=speed, progress=progress, stop_at_exit=args.stop_at_exit)
    finally:
        progress.close()
        controller.close()
    if speed != math.inf and result.real_time_factor < KEPT_PACE * speed:
        warn("sim", f"asked for {speed:g}x real time, kept {result.real_time_factor:.3g}x: this machine "
                    "cannot keep that pace")
    return result


KEPT_PACE = 0.9  # below this fraction of the asked --speed, the run says it could not keep up


def plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def summary(result, label: str = "") -> str:  # type: ignore[no-untyped-def]
    t90 = result.time_to(0.9)
    return (f"{label}coverage {100 * result.coverage[-1]:.1f} % of the free area, "
            f"90 % {'at ' + format(t90, '.1f') + ' s' if t90 is not None else 'not reached'}, "
            f"{plural(result.collisions, 'collision')}, {exit_text(result)}"
            f"; {result.sim_seconds:.1f} sim s in {result.wall_seconds:.2f} s "
            f"({result.real_time_factor:.0f}x real time, {result.mode} step, {result.controller})")


def exit_text(result) -> str:  # type: ignore[no-untyped-def]
    if result.exit_time is None:
        return "no exit"
    text = f"exit found at {result.exit_time:.1f} s"
    off_map = result.sim_seconds - result.exit_time
    if off_map > 0.5:
        text += f" (then {off_map:,.0f} s simulated off the map; --stop-at-exit ends the run at the exit)"
    return text


def drive_meta(params) -> dict[str, object]:  # type: ignore[no-untyped-def]
    """The sidecar's drive block and units for a robot whose bridge takes the firmware's commands as its HAL
    writes them (docs/recordings.md "The drive block"); nothing for a current drive, the sidecar's default."""
    from host_sim.controller.hardware_io import firmware_drive_block
    from host_sim.recordings.recording import UNITS

    if params.drive_kind == "current":
        return {}
    block = firmware_drive_block(params)
    return {"drive": block, "units": {**UNITS, "cmd_l": block["unit"], "cmd_r": block["unit"]}}


def run(args: argparse.Namespace) -> int:
    params, world = load_inputs(args)
    recorder = None
    if args.record:
        from host_sim.recordings.recording import RecordingError, RecordingWriter

        try:
            recorder = RecordingWriter(args.record, source="simulator", sample_period=0.04,
                                       robot=params.to_json(), world=world.to_dict(),
                                       extra={"controller": "PIL" if args.pil else "SIL", "rules": args.rules,
                                              "excitation": "manoeuvre" if args.excite else "exploration",
                                              "seed": args.seed, "mode": args.mode, "substeps": args.substeps,
                                              "noise": not args.no_noise, "emitter_pct": 60, **drive_meta(params)})
        except RecordingError as exc:
            raise CliError(str(exc)) from None
    try:
        result = simulate(args, params, world, recorder)
    finally:
        if recorder:
            recorder.close()
    print(summary(result, f"{world.name}, {args.rules} rules: "))
    if args.record:
        print(f"recording: {args.record} (+ .json sidecar), {len(result.t)} rows")
    if args.png:
        from host_sim.figures.runs import save_runs

        with writing("--png", args.png):
            save_runs(args.png, world, [result], [f"{world.name}, {args.rules} rule set, {args.duration:.0f} s"],
                      params.body_radius)
        print(f"picture: {args.png}")
    return 0


__all__ = ["register", "add_run_arguments", "simulate", "summary", "load_inputs", "Path"]
