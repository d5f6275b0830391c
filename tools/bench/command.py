"""`twinbot bench`: the benchmarks, each a module of tools/bench with its own options.

A benchmark registers itself with `register(subparsers, name, summary)`, so
adding one is one line in BENCHMARKS; each gets --markdown FILE here
(tools/bench/report.py).  Modules keep heavy imports (numpy, pymavlink)
inside their functions.  The figures: docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import importlib
import textwrap
from typing import Any

from tools.arguments import help_and_error
from tools.bench.report import add_markdown_option

# (name, module, what it measures).
BENCHMARKS = (
    ("protocol", "tools.bench.protocol",
     "serial protocol: encode/decode frames/s and MB/s on CPython (against pymavlink) and "
     "MicroPython, framing overhead, allocation per received byte"),
    ("firmware", "tools.bench.firmware",
     "firmware: control-cycle time and allocations under MicroPython, heap of the loaded firmware, "
     "one fuzzy inference on CPython against peer fuzzy libraries"),
    ("sim", "tools.bench.sim",
     "host simulator: real-time factor of one robot replaying a recording and with the firmware in SIL, "
     "batch robot-steps/s at N = 1000, and IR-SIM on the same room"),
    ("gui", "tools.bench.gui",
     "twinbot gui: frame time with the simulated, user and real (virtual board) robots, rays and coverage on"),
    ("diagnose", "tools.bench.diagnose",
     "diagnosis proven blind: a suite of MuJoCo recordings with concealed effects, diagnosed, scored against "
     "the answer keys (names, sides, parameters, held-out fit, false alarms, out-of-library, seconds), with "
     "PySINDy beside it"),
    ("margins", "tools.bench.margins",
     "the diagnosis's locate rules on a blind suite: how far below its threshold each stays on the "
     "effect-free controls, and how many of the cases it is there to find it reaches"),
    ("ghost", "tools.bench.late_signal",
     "late-signal twin: the ghost's pose error against the raw late pose behind a 0-300 ms late link, "
     "and its latency estimate"),
)


def _description() -> str:
    lines = [
        "Benchmarks that produce the project's figures.  Each prints the machine, the exact",
        "command, one table and the targets with whether each is met; --json FILE keeps",
        "every figure, --markdown FILE writes the printout as its own section of FILE",
        "(docs/benchmarks.md).  Timings are medians over repeated runs.",
        "",
        "benchmarks (what each measures):",
    ]
    for name, _module, summary in BENCHMARKS:
        lines += textwrap.wrap(summary, 78, initial_indent=f"  {name:<10} ", subsequent_indent=" " * 13)
    lines += ["", "Run 'twinbot bench BENCHMARK --help' for the details of one."]
    return "\n".join(lines)


def register(subparsers: Any, name: str, summary: str) -> None:
    parser = subparsers.add_parser(
        name, help=summary, description=_description(), formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK")
    order = [b[0] for b in BENCHMARKS]
    order.insert(order.index("firmware") + 1, "firmware-rp2040")  # `bench firmware --rp2040`'s own section
    for bench_name, module_name, bench_summary in BENCHMARKS:
        importlib.import_module(module_name).register(sub, bench_name, bench_summary)
        add_markdown_option(sub.choices[bench_name], bench_name, bench_summary, order)

    def no_benchmark(args: argparse.Namespace) -> int:
        return help_and_error(parser, "BENCHMARK", [b[0] for b in BENCHMARKS])

    parser.set_defaults(func=no_benchmark)

