"""`twinbot plot`: figures drawn from the models, for people who would rather look.

    twinbot plot sensor    the IR sensor model as the paper's Figs. 7, 8, 10, 11, 12
    twinbot plot worlds    the built-in worlds

The figures themselves are host_sim/sensor_figures.py's.
"""
from __future__ import annotations

import argparse
from typing import Any

from host_sim import sensor_figures
from host_sim.sensor_figures import DEFAULT_OUT


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=__doc__.split("\n\n", 1)[1],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    figures = p.add_subparsers(dest="figure", metavar="FIGURE")
    register_sensor(figures, "sensor", "the IR sensor model (Figs. 7, 8, 10, 11, 12)")
    register_worlds(figures, "worlds", "the built-in worlds")

    def no_figure(args: argparse.Namespace) -> int:
        p.print_help()
        return 2

    p.set_defaults(func=no_figure)


def register_sensor(subparsers: Any, name: str, summary: str) -> None:
    """`twinbot plot sensor`: the paper's Figs. 7, 8, 10, 11 and 12 from the sensor model."""
    parser = subparsers.add_parser(name, help=summary, description=sensor_figures.__doc__,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(DEFAULT_OUT), metavar="DIR",
                        help=f"directory for the PNG files (default {DEFAULT_OUT})")
    parser.add_argument("--params", metavar="FILE", help="robot parameter file (JSON); default: the built-in set")
    parser.set_defaults(func=run_sensor)


def register_worlds(subparsers: Any, name: str, summary: str) -> None:
    """`twinbot plot worlds`: the built-in worlds in one picture."""
    parser = subparsers.add_parser(name, help=summary, description="Draw the built-in worlds (worlds.png).")
    parser.add_argument("--out", default=str(DEFAULT_OUT), metavar="DIR",
                        help=f"directory for the PNG file (default {DEFAULT_OUT})")
    parser.set_defaults(func=run_worlds)


def run_sensor(args: argparse.Namespace) -> int:
    for path in sensor_figures.plot_sensor_figures(args.out, _params(args.params)):
        print(path)
    return 0


def run_worlds(args: argparse.Namespace) -> int:
    print(sensor_figures.plot_worlds(args.out))
    return 0


def _params(path: str | None) -> Any:
    from host_sim.params import DEFAULT, load_params

    return load_params(path) if path else DEFAULT
