"""`twinbot import LOG.csv --map MAP.json --robot ROBOT.json --out REC.csv`: a robot's own log as a recording.

The conversion is host_sim/recordings/log_import.py's; the MAP format and examples: docs/recordings.md, "Import".
"""
from __future__ import annotations

import argparse

from tools.arguments import CliError, input_file, recording_file

DESCRIPTION = """\
Turn a log in its own columns and units into a recording that twinbot replay,
plot and diagnose read.  MAP.json names the log's columns and their units: the
time, the command (kind current, voltage, duty or wheel_speed), the wheels
(encoder counts, or wheel speeds integrated into counts) and, if the log has
them, the battery, a tracker's pose, the IR sensors, the emitter power and the
firmware's view.  ROBOT.json is a robot parameter file, as --params takes.
A bad MAP or LOG is one line naming the file, the line or entry and the problem
(exit status 2), and nothing is written.  The format: docs/recordings.md.
"""

EXAMPLES = """\
example:
  twinbot import run.csv --map pololu_map.json --robot pololu.json --out rec.csv && twinbot diagnose rec.csv
"""


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=DESCRIPTION, epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log", metavar="LOG.csv", type=input_file, help="the robot's log: a CSV file with a header")
    p.add_argument("--map", required=True, metavar="MAP.json", type=input_file,
                   help="which of the log's columns hold what, in which unit")
    p.add_argument("--robot", required=True, metavar="ROBOT.json", type=input_file,
                   help="the robot's parameters (a parameter file as --params takes)")
    p.add_argument("--out", required=True, metavar="REC.csv", type=recording_file,
                   help="the recording to write (and its sidecar REC.csv.json)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from host_sim.recordings.log_import import LogImportError, import_log
    from host_sim.recordings.recording import RecordingError

    try:
        imported = import_log(args.log, args.map, args.robot, args.out)
    except (LogImportError, RecordingError) as exc:
        raise CliError(str(exc)) from None
    n, n_ir = len(imported.t), imported.ir_on.shape[1]
    have = [f"{n_ir} IR sensors" if n_ir else "no IR",
            "a battery" if imported.vbat is not None else "no battery",
            "a tracker" if imported.pose is not None else "no tracker",
            "the firmware's view" if imported.firmware is not None else "no firmware view"]
    print(f"wrote {args.out}: {n} rows, {imported.t[-1] - imported.t[0]:.2f} s, a {imported.drive['kind']} drive "
          f"(commands in {imported.drive['unit']}); {', '.join(have)}")
    return 0
