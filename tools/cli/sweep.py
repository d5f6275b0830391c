"""`twinbot sweep`: many exploration runs (rule sets x worlds x seeds x perturbations) in parallel.

Every combination is a fixed-step SIL run, so the same seed gives the same row on any
machine.  Each seed draws the sensor noise, a start near the world's and, with --perturb,
robot parameters within +-REL of nominal.  The runs go to a local Dask cluster, or with
--scheduler to an existing one (its workers need twinbot installed).  --out gets runs.csv
(a row per run), summary.csv (a row per rule set x world) and coverage.png (docs/sweep.md).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tools.arguments import CliError, float_range, int_range, output_folder, sim_seconds, writing

EXAMPLES = """\
examples:
  twinbot sweep --rules first,refined --world paper_room,maze --seeds 50 --duration 120 --out sweep
  twinbot sweep --seeds 4 --duration 30 --out /tmp/s --workers 2
  twinbot sweep --seeds 50 --perturb wheel_radius=0.02,coulomb_friction=0.2 --out sweep
  twinbot sweep --seeds 50 --fixed-start --out sweep    # only the sensor noise differs between seeds
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
    output_folder(text)  # tried before the runs, which may take hours
    return path


def perturbations(text: str) -> list[tuple[str, float]]:
    """--perturb NAME=REL,...: RobotParams fields, each drawn within +-REL (a fraction) of nominal."""
    from host_sim.loops.sweep import check_perturb

    out: dict[str, float] = {}
    for item in text.split(","):
        name, sep, value = item.strip().partition("=")
        name = name.strip()
        if not sep or not name:
            raise argparse.ArgumentTypeError(f"{item.strip()!r}: expected NAME=REL, e.g. wheel_radius=0.02")
        try:
            rel = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{item.strip()}': REL {value.strip()!r} is not a number") from None
        if name in out:
            raise argparse.ArgumentTypeError(f"'{name}' is given twice")
        try:
            check_perturb(name, rel)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        out[name] = rel
    return list(out.items())


def scheduler_address(text: str) -> str:
    if not text.startswith(("tcp://", "tls://", "inproc://", "ucx://")) or ":" not in text.split("://", 1)[1]:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a Dask scheduler address such as tcp://HOST:8786")
    return text


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    from host_sim.loops import sweep
    from host_sim.controller.hardware_io import RULE_SETS
    from host_sim.physics.world import BUILTIN_NAMES

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
    p.add_argument("--start-radius", type=float_range(0, 1, unit="m"), default=sweep.START_RADIUS_M, metavar="M",
                   help=f"each seed starts within this distance of the world's start, 0..1 m "
                        f"(default {sweep.START_RADIUS_M:g}; 0: at it)")
    p.add_argument("--start-heading", type=float_range(0, 180, unit="degrees"), default=sweep.START_HEADING_DEG,
                   metavar="DEG", help=f"... and within +-DEG of its heading, 0..180 (default {sweep.START_HEADING_DEG:g})")
    p.add_argument("--fixed-start", action="store_true",
                   help="every run at the world's start pose (same as --start-radius 0 --start-heading 0)")
    p.add_argument("--perturb", type=perturbations, default=[], metavar="NAME=REL,...",
                   help="robot parameters (RobotParams fields, host_sim/physics/params.py) each run draws uniformly within "
                        "+-REL of nominal from its seed, e.g. wheel_radius=0.02,coulomb_friction=0.2")
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

    from host_sim.loops import sweep

    radius, heading = (0.0, 0.0) if args.fixed_start else (args.start_radius, args.start_heading)
    todo = sweep.cases(args.rules, args.world, args.seeds, args.duration, args.substeps, start_radius=radius,
                       start_heading_deg=heading, perturb=args.perturb)
    where = args.scheduler or f"{args.workers or 'one per core'} local worker(s)"
    varied = f"start within {radius:g} m, +-{heading:g} deg" + "".join(f", {n} +-{100 * r:g} %" for n, r in args.perturb)
    print(f"{len(todo)} runs of {args.duration:g} sim s on {where}; per seed: {varied}", file=sys.stderr)
    bar = tqdm(total=len(todo), desc="sweep", unit="run", file=sys.stderr, disable=not sys.stderr.isatty())
    done = []

    def finished(n: int) -> None:
        done.append(n)
        bar.update(n)

    try:
        results = sweep.run_cases(todo, args.scheduler, args.workers, progress=finished)
    except OSError as exc:  # scheduler unreachable (Dask raises OSError on connect timeout)
        raise CliError(f"--scheduler {args.scheduler}: {exc}") from None
    except KeyboardInterrupt:  # one line, not the cluster's tracebacks (tests/test_sweep.py::test_ctrl_c_is_one_line)
        bar.close()
        print(f"twinbot sweep: interrupted: {sum(done)} of {len(todo)} runs done, nothing written to {args.out}",
              file=sys.stderr)
        return 130
    finally:
        bar.close()
    with writing("--out", args.out):
        table, summary, plot = _write_outputs(args, results)
    for s in summary:
        print(f"{s['rules']:>8} {s['world']:<11} {s['runs']} runs: coverage {100 * float(s['coverage_mean']):.1f} % "
              f"(sd {100 * float(s['coverage_std']):.1f}), 90 % reached {100 * float(s['reached_90_rate']):.0f} %, "
              f"exit {100 * float(s['exit_rate']):.0f} %, stuck {100 * float(s['stuck_rate']):.0f} %, "
              f"collisions {s['collisions_mean']}/run")
    print(f"table: {table}\nsummary: {args.out / 'summary.csv'}\nplot: {plot}")
    return 0


def _write_outputs(args: argparse.Namespace, results: list) -> tuple:  # type: ignore[type-arg]
    """runs.csv, summary.csv and coverage.png in --out: (the table's path, the summary's rows, the plot's path)."""
    from host_sim.loops import sweep

    rows = [r.row for r in results]
    args.out.mkdir(exist_ok=True)
    table = sweep.write_table(args.out / "runs.csv", rows, sweep.columns(args.perturb))
    summary = sweep.summarise(rows)
    sweep.write_table(args.out / "summary.csv", summary, sweep.SUMMARY_COLUMNS)
    return table, summary, sweep.save_coverage_plot(args.out / "coverage.png", results)
