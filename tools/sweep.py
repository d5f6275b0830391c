"""`twinbot sweep`: many exploration runs (rule sets x worlds x seeds) in parallel, one table.

Every combination is a fixed-step SIL run (exactly repeatable: the same
seed gives the same row on any machine).  By default the runs go to a Dask
LocalCluster of one worker process per local core; --scheduler sends them
to an existing Dask distributed cluster instead (its workers need twinbot
installed: `pip install -e .` in a checkout of the same version).

Writes in --out: runs.csv (a row per run: rules, world, seed, duration_s,
coverage_end (fraction of the free area), t90_s (time to 90 % coverage,
empty if never), exit_found, exit_time_s, collisions, stuck (the robot did
not find the exit and its centre stayed within 5 cm of where it was 20 s
before the end; runs shorter than 20 s use the whole run),
moved_last_window_m), summary.csv (a row per rule set x world: means,
rates, medians) and coverage.png (coverage against time, mean and 10-90 %
band over the seeds, a panel per world).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tools.arguments import int_range, sim_seconds
from tools.cli import CliError

EXAMPLES = """\
examples:
  twinbot sweep --rules first,refined --world paper_room,maze --seeds 50 --duration 120 --out sweep
  twinbot sweep --seeds 4 --duration 30 --out /tmp/s --workers 2
  twinbot sweep --seeds 50 --out sweep --scheduler tcp://10.0.0.5:8786
"""


def _names(allowed: tuple[str, ...], what: str):  # type: ignore[no-untyped-def]
    def parse(text: str) -> list[str]:
        names = [n.strip() for n in text.split(",")]
        bad = [n for n in names if n not in allowed]
        if bad or not names:
            raise argparse.ArgumentTypeError(f"{what} {bad[0] if bad else text!r}: expected a comma-separated "
                                             f"list of {', '.join(allowed)}")
        return list(dict.fromkeys(names))

    parse.__name__ = what
    return parse


def out_folder(text: str) -> Path:
    """An output folder: created if missing, but its parent must exist; not a file."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: is a file, not a folder")
    if not path.exists() and not path.parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: its parent folder {path.parent} does not exist")
    return path


def scheduler_address(text: str) -> str:
    if not text.startswith(("tcp://", "tls://", "inproc://", "ucx://")) or ":" not in text.split("://", 1)[1]:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a Dask scheduler address such as tcp://HOST:8786")
    return text


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    from host_sim.interface import RULE_SETS
    from host_sim.world import BUILTIN_NAMES

    p = sub.add_parser(name, help=summary, description=__doc__.split("\n\n", 1)[1], epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rules", type=_names(tuple(RULE_SETS), "rule set"), default=["first", "refined"],
                   help="comma-separated rule sets (default first,refined)")
    p.add_argument("--world", type=_names(BUILTIN_NAMES, "world"), default=["paper_room", "maze"],
                   help=f"comma-separated built-in worlds, of {', '.join(BUILTIN_NAMES)} (default paper_room,maze)")
    p.add_argument("--seeds", type=int_range(1, 100_000), default=50,
                   help="seeds 0..N-1 of the sensor noise per rule set x world, 1..100000 (default 50)")
    p.add_argument("--duration", type=sim_seconds(1.0), default=120.0,
                   help="simulated seconds per run, 1 to 86400 (default 120)")
    p.add_argument("--substeps", type=int_range(1, 1000), default=8,
                   help="physics substeps per 40 ms control period, 1..1000 (default 8)")
    p.add_argument("--out", type=out_folder, required=True, metavar="DIR",
                   help="folder for runs.csv, summary.csv and coverage.png (created if missing)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", type=scheduler_address, metavar="tcp://HOST:8786",
                       help="run on this existing Dask distributed scheduler instead of local cores")
    where.add_argument("--workers", type=int_range(1, 1024),
                       help="local worker processes (default: one per core)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from host_sim import sweep

    todo = sweep.cases(args.rules, args.world, args.seeds, args.duration, args.substeps)
    where = args.scheduler or f"{args.workers or 'one per core'} local worker(s)"
    print(f"{len(todo)} runs of {args.duration:g} sim s on {where}", file=sys.stderr)
    bar = tqdm(total=len(todo), desc="sweep", unit="run", file=sys.stderr, disable=not sys.stderr.isatty())
    try:
        results = sweep.run_cases(todo, args.scheduler, args.workers, progress=bar.update)
    except OSError as exc:  # scheduler unreachable (Dask raises OSError on connect timeout)
        raise CliError(f"--scheduler {args.scheduler}: {exc}") from None
    finally:
        bar.close()
    rows = [r.row for r in results]
    args.out.mkdir(exist_ok=True)
    table = sweep.write_table(args.out / "runs.csv", rows)
    summary = sweep.summarise(rows)
    sweep.write_table(args.out / "summary.csv", summary, sweep.SUMMARY_COLUMNS)
    plot = sweep.save_coverage_plot(args.out / "coverage.png", results)
    for s in summary:
        print(f"{s['rules']:>8} {s['world']:<11} {s['runs']} runs: coverage {100 * float(s['coverage_mean']):.1f} % "
              f"(sd {100 * float(s['coverage_std']):.1f}), 90 % reached {100 * float(s['reached_90_rate']):.0f} %, "
              f"exit {100 * float(s['exit_rate']):.0f} %, stuck {100 * float(s['stuck_rate']):.0f} %, "
              f"collisions {s['collisions_mean']}/run")
    print(f"table: {table}\nsummary: {args.out / 'summary.csv'}\nplot: {plot}")
    return 0
