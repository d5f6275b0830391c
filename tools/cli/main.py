"""`twinbot`: the command a user types.

Each subcommand lives in its own module and registers itself through a
`register(subparsers)` function; this file only wires them together, so a
new subcommand is one module and one line here.
"""
from __future__ import annotations

import argparse
import errno
import sys

from tools.arguments import CliError

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
    ("import", "turn a robot's own log (its columns and units) into a recording"),
    ("replay", "replay a recording open loop through the twin; how far the twin ends from it"),
    ("plot", "figures: a recording, the IR sensor model (the paper's Figs. 7-12), the built-in worlds"),
    ("sweep", "many runs (rule sets x worlds x seeds) in parallel, locally or on a Dask cluster: a table, plots"),
    ("bench", "benchmarks that produce the README's figures"),
)

_MODULES = {
    "demo": "tools.cli.demo",
    "sim": "tools.cli.sim",
    "serial": "tools.cli.serial_harness",
    "board": "tools.cli.board",
    "flash": "tools.cli.flash",
    "diagnose": "tools.cli.diagnose",
    "fuzzy": "tools.cli.fuzzy",
    "gui": "tools.cli.gui",
    "import": "tools.cli.import_log",
    "replay": "tools.cli.replay",
    "plot": "tools.cli.plot",
    "sweep": "tools.cli.sweep",
    "bench": "tools.bench.command",
}


# The host's own "this input is wrong" errors: each message names the file,
# entry or value.  One that escapes a subcommand is still one line, exit 2.
EXPECTED_ERRORS = frozenset({
    "host_sim.physics.world.WorldError", "host_sim.physics.params.ParamsError", "host_sim.recordings.recording.RecordingError",
    "host_sim.recordings.replay.ReplayError", "host_sim.board.frame_log.FrameLogError", "host_sim.board.serial_link.LinkError",
})


# A write the work ends with fails with these whatever wrote it: a full disk or a read-only one.
# Each command's own writes say which option failed; these catch any other write in one line too.
FULL_OR_READ_ONLY = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})


def _expected(exc: BaseException) -> bool:
    return any(f"{c.__module__}.{c.__qualname__}" in EXPECTED_ERRORS for c in type(exc).__mro__)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The full parser, or (only=NAME) one that knows that subcommand alone."""
    import importlib

    from tools.arguments import OneLineParser
    from tools.version import package_version

    parser = OneLineParser(
        prog="twinbot",
        description="Firmware twin of a differential-drive robot with eight IR proximity sensors.",
        epilog="Run 'twinbot COMMAND --help' for the options of one command.",
    )
    parser.add_argument("--version", action="version", version=f"twinbot {package_version()}")
    # dest is not "command": a subcommand's own --command option would overwrite it.
    sub = parser.add_subparsers(dest="subcommand", metavar="COMMAND")

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
        from tools.arguments import help_and_error

        return help_and_error(parser, "COMMAND", [name for name, _ in SUBCOMMANDS])
    try:
        return int(args.func(args) or 0)
    except CliError as exc:
        print(f"twinbot {args.subcommand}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        if exc.errno not in FULL_OR_READ_ONLY:
            raise
        where = f" {exc.filename}" if exc.filename else ""
        print(f"twinbot {args.subcommand}: error: could not write{where}: {exc.strerror}", file=sys.stderr)
        return 2
    except Exception as exc:
        if not _expected(exc):
            raise
        print(f"twinbot {args.subcommand}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    # Run the imported module, not this __main__ copy, so that CliError raised
    # by subcommands is the class caught above.
    from tools.cli.main import main as _main

    sys.exit(_main())
