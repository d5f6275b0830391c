"""`twinbot plot`: figures drawn from the models, for people who would rather look.

    twinbot plot sensor    the IR sensor model as the paper's Figs. 7, 8, 10, 11, 12
    twinbot plot worlds    the built-in worlds
"""
from __future__ import annotations

import argparse

from tools import plot_sensor


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=__doc__.split("\n\n", 1)[1],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    figures = p.add_subparsers(dest="figure", metavar="FIGURE")
    plot_sensor.register(figures, "sensor", "the IR sensor model (Figs. 7, 8, 10, 11, 12)")
    plot_sensor.register_worlds(figures, "worlds", "the built-in worlds")

    def no_figure(args: argparse.Namespace) -> int:
        p.print_help()
        return 2

    p.set_defaults(func=no_figure)
