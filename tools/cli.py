"""`twinbot`: the command a user types.

Each subcommand lives in its own module and registers itself through a
`register(subparsers)` function; this file only wires them together, so a
new subcommand is one module and one line here.
"""
from __future__ import annotations

import argparse
import sys

# (module under tools/, one-line summary for the overview).  Imported lazily
# so that `twinbot serial` does not pay for numpy or pymavlink.
SUBCOMMANDS = (
    ("demo", "run the main demonstration: both rule sets exploring the paper's room"),
    ("sim", "simulate the robot with its firmware in the loop (SIL or PIL), headless"),
    ("serial", "serial protocol test harness: show, send and record frames on a port"),
    ("board", "run the firmware on a virtual board behind a pseudo-terminal"),
    ("flash", "compile the firmware with mpy-cross, copy it to a board with mpremote, check HELLO"),
    ("diagnose", "where a recording and the twin disagree, in physical terms"),
    ("fuzzy", "the fuzzy controller: rule table, FCL, figure, evaluation"),
    ("gui", "the paper's application in a window: draw a room, watch three robots, drive one"),
    ("plot", "figures: the IR sensor model (the paper's Figs. 7-12), the built-in worlds"),
    ("bench", "benchmarks that produce the README's figures"),
)

_MODULES = {
    "demo": "tools.demo",
    "sim": "tools.sim",
    "serial": "tools.serial_harness",
    "board": "tools.board",
    "flash": "tools.flash",
    "diagnose": "tools.diagnose",
    "fuzzy": "tools.fuzzy_rules",
    "gui": "tools.gui",
    "plot": "tools.plot",
    "bench": "tools.bench",
}


class CliError(Exception):
    """An error a user can act on: printed as one line, exit status 2."""


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The full parser, or (only=NAME) one that knows that subcommand alone."""
    parser = argparse.ArgumentParser(
        prog="twinbot",
        description="Firmware twin of a differential-drive robot with eight IR proximity sensors.",
        epilog="Run 'twinbot COMMAND --help' for the options of one command.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    import importlib

    for name, summary in SUBCOMMANDS:
        if only is not None and name != only:
            continue
        module = importlib.import_module(_MODULES[name])
        module.register(sub, name, summary)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # Import only the chosen subcommand's module: `twinbot serial` starts fast.
    chosen = argv[0] if argv and argv[0] in _MODULES else None
    parser = build_parser(chosen)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except CliError as exc:
        print(f"twinbot {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    # Run the imported module, not this __main__ copy, so that CliError raised
    # by subcommands is the class caught above.
    from tools.cli import main as _main

    sys.exit(_main())
