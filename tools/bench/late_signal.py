"""`twinbot bench ghost`: the late-signal twin's pose error against the raw late pose.

Behind a late link of 0-300 ms, the ghost's predicted pose and the last
frame's pose against the simulator's true one; DESCRIPTION (the --help text)
says how.  Figures: docs/benchmarks.md; the twin: docs/late-signal-twin.md.
"""
from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path
from typing import Any

from tools.arguments import float_range, image_file, int_range, output_file, writing
from tools.bench.report import machine_line, print_targets

DESCRIPTION = """\
The robot is the simulator with the firmware in SIL (HOST mode), driven
through the identification manoeuvre by a scripted host; each TELEMETRY
frame reaches the host MEAN +- JITTER ms late (uniform, seeded, in order).
At every control instant (40 ms) the ghost's predicted pose
(host_sim/loops/late_signal_twin.py) and the raw late pose (the last frame's odometry) are
compared with the simulator's true pose.  Prints one table (mean and 95th
percentile position error, mm; the ghost's latency estimate against the
frames' true latency) and, with --plot, draws them.
"""

DELAYS_MS = (0, 50, 100, 200, 300)


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--duration", type=float_range(5, 3600, unit="s"), default=46.0,
                   help="simulated seconds per delay (default 46: one whole manoeuvre)")
    p.add_argument("--jitter", type=float_range(0, 1000, unit="ms"), default=50.0,
                   help="jitter half-width, ms (default 50; never more than the mean)")
    p.add_argument("--seed", type=int_range(0, 2**31), default=0, help="seed of the link's delays")
    p.add_argument("--plot", metavar="FILE", type=image_file, default=None, help="write the error plot here (PNG)")
    p.add_argument("--json", metavar="FILE", type=output_file, default=None, help="keep every figure in this JSON file")
    p.set_defaults(func=run)


def measure(duration: float, jitter_ms: float, seed: int) -> list[dict[str, Any]]:
    import numpy as np

    from host_sim.loops.late_signal_trial import run_late

    rows = []
    for d in DELAYS_MS:
        jitter = min(d, jitter_ms) / 1000.0
        r = run_late(d / 1000.0, jitter, seed=seed, duration=duration)
        g, w = 1000 * np.array(r.ghost_err), 1000 * np.array(r.raw_err)
        rows.append({"delay_ms": d, "jitter_ms": 1000 * jitter, "instants": len(g),
                     "ghost_mean_mm": float(g.mean()), "ghost_p95_mm": float(np.percentile(g, 95)),
                     "raw_mean_mm": float(w.mean()), "raw_p95_mm": float(np.percentile(w, 95)),
                     "latency_est_ms": 1000 * float(np.mean(r.latency_est)),
                     "latency_true_ms": 1000 * float(np.mean(r.latency_true))})
    return rows


def table(rows: list[dict[str, Any]]) -> str:
    head = ("| delay ms | jitter ms | ghost mean mm | ghost p95 mm | raw late mean mm | raw late p95 mm "
            "| latency est. ms | latency true ms |")
    lines = [head, "|" + "---|" * 8]
    for r in rows:
        lines.append(f"| {r['delay_ms']} | ±{r['jitter_ms']:.0f} | {r['ghost_mean_mm']:.1f} | {r['ghost_p95_mm']:.1f} "
                     f"| {r['raw_mean_mm']:.1f} | {r['raw_p95_mm']:.1f} | {r['latency_est_ms']:.1f} "
                     f"| {r['latency_true_ms']:.1f} |")
    return "\n".join(lines)


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = [r["delay_ms"] for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(d, [r["raw_mean_mm"] for r in rows], "o-", color="tab:red", label="raw late pose, mean")
    ax.plot(d, [r["raw_p95_mm"] for r in rows], "o--", color="tab:red", alpha=0.5, label="raw late pose, p95")
    ax.plot(d, [r["ghost_mean_mm"] for r in rows], "s-", color="tab:blue", label="ghost, mean")
    ax.plot(d, [r["ghost_p95_mm"] for r in rows], "s--", color="tab:blue", alpha=0.5, label="ghost, p95")
    ax.set_xlabel("link delay (mean), ms")
    ax.set_ylabel("position error against the true pose, mm")
    ax.set_title("Late-signal twin: ghost vs raw late pose")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    rows = measure(args.duration, args.jitter, args.seed)
    print("twinbot bench ghost")
    print(f"command:     twinbot bench ghost --duration {args.duration:g} --jitter {args.jitter:g} --seed {args.seed}")
    print(f"machine:     {machine_line()}")
    print(f"python:      CPython {platform.python_version()}")
    print()
    print(table(rows))
    worse = [r["delay_ms"] for r in rows if r["delay_ms"] > 0 and r["ghost_mean_mm"] >= r["raw_mean_mm"]]
    print_targets([{"met": not worse, "text": "ghost error below the raw late pose's at every delay > 0"
                                              + (f" (not at {', '.join(map(str, worse))} ms)" if worse else "")}])
    if args.plot is not None:
        with writing("--plot", args.plot):
            plot(rows, Path(args.plot))
        print(f"plot: {args.plot}")
    if args.json is not None:
        with writing("--json", args.json):
            Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0 if not worse else 1

