"""`twinbot plot`: figures drawn from the models, for people who would rather look.

    twinbot plot recording REC.csv   a recording: trajectory, wheel commands, encoder speeds, IR
    twinbot plot sensor              the IR sensor model as the paper's Figs. 7, 8, 10, 11, 12
    twinbot plot worlds              the built-in worlds

The figures themselves are host_sim/figures/sensor_model.py's (docs/ir-sensor.md, docs/worlds.md).
"""
from __future__ import annotations

import argparse
from typing import Any

from host_sim.figures import sensor_model
from host_sim.figures.sensor_model import DEFAULT_OUT
from tools.arguments import help_and_error, image_file, input_file, output_folder, writing


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=__doc__.split("\n\n", 1)[1],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    figures = p.add_subparsers(dest="figure", metavar="FIGURE")
    register_recording(figures, "recording", "a recording: trajectory, wheel commands, encoder speeds, IR")
    register_sensor(figures, "sensor", "the IR sensor model (Figs. 7, 8, 10, 11, 12)")
    register_worlds(figures, "worlds", "the built-in worlds")

    def no_figure(args: argparse.Namespace) -> int:
        return help_and_error(p, "FIGURE", ["recording", "sensor", "worlds"])

    p.set_defaults(func=no_figure)


def register_sensor(subparsers: Any, name: str, summary: str) -> None:
    """`twinbot plot sensor`: the paper's Figs. 7, 8, 10, 11 and 12 from the sensor model."""
    parser = subparsers.add_parser(name, help=summary, description=sensor_model.__doc__,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(DEFAULT_OUT), metavar="DIR", type=output_folder,
                        help=f"directory for the PNG files (default {DEFAULT_OUT})")
    parser.add_argument("--params", metavar="FILE", type=input_file,
                        help="robot parameter file (JSON); default: the built-in set")
    parser.set_defaults(func=run_sensor)


def register_worlds(subparsers: Any, name: str, summary: str) -> None:
    """`twinbot plot worlds`: the built-in worlds in one picture."""
    parser = subparsers.add_parser(name, help=summary, description="Draw the built-in worlds (worlds.png).")
    parser.add_argument("--out", default=str(DEFAULT_OUT), metavar="DIR", type=output_folder,
                        help=f"directory for the PNG file (default {DEFAULT_OUT})")
    parser.set_defaults(func=run_worlds)


def run_sensor(args: argparse.Namespace) -> int:
    params = _params(args.params)
    with writing("--out", args.out):
        paths = sensor_model.plot_sensor_figures(args.out, params)
    for path in paths:
        print(path)
    return 0


def run_worlds(args: argparse.Namespace) -> int:
    with writing("--out", args.out):
        path = sensor_model.plot_worlds(args.out)
    print(path)
    return 0


def _params(path: str | None) -> Any:
    from host_sim.physics.params import DEFAULT, ParamsError, load_params
    from tools.arguments import CliError

    try:
        return load_params(path) if path else DEFAULT
    except ParamsError as exc:
        raise CliError(str(exc)) from None


def register_recording(figures: Any, name: str, summary: str) -> None:
    """`twinbot plot recording REC.csv`: one recording at a glance."""
    from tools.cli.replay import add_source_arguments

    p = figures.add_parser(name, help=summary,
                           description="A recording at a glance: the trajectory when it has a tracker pose (over "
                                       "its world; else the firmware's odometry), the wheel commands, the encoder speeds, the battery, and the "
                                       "IR readings with the emitters on and off, over time.")
    p.add_argument("recording", metavar="REC.csv", type=input_file, help="a recording (CSV + JSON sidecar)")
    add_source_arguments(p)
    p.add_argument("--png", metavar="FILE", type=image_file, help="the figure (default: REC.png beside REC.csv)")
    p.set_defaults(func=run_recording)


def run_recording(args: argparse.Namespace) -> int:
    from pathlib import Path

    from host_sim.figures.runs import save_recording
    from tools.arguments import CliError
    from tools.cli.replay import load_inputs, print_notes

    png = args.png or str(Path(args.recording).with_suffix(".png"))
    try:
        image_file(png)
    except argparse.ArgumentTypeError as exc:
        raise CliError(f"--png {exc}") from None
    rec, params, world = load_inputs(args)
    with writing("--png", png):
        path = save_recording(png, rec, params, world)
    print(path)
    print_notes(rec)
    return 0
