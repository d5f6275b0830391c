"""`twinbot bench gui`: frame time of `twinbot gui` with its robots, rays and coverage on.

Headless, in the paper's room, with and without a virtual board as the real
robot; DESCRIPTION (the --help text) says what a timed frame holds.
Figures: docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tools.arguments import float_range, int_range
from tools.arguments import CliError
from tools.bench.report import machine_line

DESCRIPTION = """\
Each workload opens the application headless (SDL_VIDEODRIVER=dummy),
first runs the two simulated robots PRERUN simulated seconds at full speed
(so that their trails are as long as the window draws them, 4000 points),
then 30 frames to warm up, then times FRAMES frames one by one, started
every 1/60 s as in the window (the wait is not counted): the events, the simulated robots' physics and firmware for 1/60 s of wall
time x the speed factor, the real robot's frames, and drawing everything
(room, coverage overlay, trails, 8 rays and bars per robot, set-points,
coverage plot, buttons, status bar) into the window.  The real robot is a
virtual board (`twinbot board`, MicroPython running the firmware, its own
twin as hardware, in real time, on this machine's cores too) set
exploring (AUTONOMOUS) before the timing starts.  The replay workload
has the replay panel open on a recording of the simulated robot
(90 s, recorded first) and plays it, so that each frame also draws
the recorded robot, the slider, the plots and their cursor.

The dummy driver has no display to show the frame on: a real display's
flip (a copy to the compositor) comes on top and is not measured here.
"""

TARGET_FPS = 60.0
PRERUN = 200.0  # simulated seconds before timing: 5000 control periods, trails at their longest
REPLAY_S = 90.0  # s, the replay workload's recording (DESCRIPTION says 90 s): as long as a diagnosis likes them
REPO = Path(__file__).resolve().parents[2]


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int_range(10, 1_000_000), default=600, help="timed frames per workload (default 600)")
    p.add_argument("--prerun", type=float_range(0, 86_400, unit="s"), default=PRERUN,
                   help=f"simulated seconds run before timing, to grow the trails (default {PRERUN:g})")
    p.add_argument("--no-board", action="store_true", help="skip the workloads with a real robot (virtual board)")
    p.set_defaults(func=run)


def start_board(*options: str) -> tuple[subprocess.Popen[str], str]:
    """A virtual board (`twinbot board OPTIONS`) as a child process; its pty's path."""
    proc = subprocess.Popen([sys.executable, "-m", "tools.cli.main", "board", *options], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line.startswith("twinbot board: /"):
        proc.terminate()
        raise CliError(f"the virtual board did not start (it said {line.strip()!r})")
    return proc, line.split(": ", 1)[1].strip()


def record_replay(folder: Path, seconds: float) -> Path:
    """A recording of the twin exploring the paper's room (fixed step), for the replay workload."""
    from host_sim.controller.sil import SilController
    from host_sim.loops.simulation import Simulation
    from host_sim.physics.params import DEFAULT
    from host_sim.physics.world import builtin_world
    from host_sim.recordings.recording import RecordingWriter

    world, path = builtin_world("paper_room"), folder / "replay.csv"
    with RecordingWriter(path, source="simulator", sample_period=0.04, robot=DEFAULT.to_json(), world=world.to_dict(),
                         extra={"mode": "fixed"}) as w:
        Simulation(world, DEFAULT, SilController(1), seed=0, recorder=w).run_fixed(seconds)
    return path


def workload(frames: int, speed: float, port: str | None, prerun: float, replay: Path | None = None
             ) -> dict[str, Any]:
    from host_sim.physics.world import builtin_world
    from host_sim.physics.params import DEFAULT
    from protocol import messages as M
    from tools.gui import loop
    from tools.gui.app import Settings

    settings = Settings(world=builtin_world("paper_room"), params=DEFAULT, speed=speed, port=port, replay=replay)
    window = loop.open_window(settings, headless=True)
    app = window.app
    try:
        if replay is not None:
            assert app.replay.open, app.message
            app.toggle_replay_play()  # the slider, the cursor and the recorded robot move every frame
        if app.real is not None:
            app.real.link.send(M.COMMAND, {"mode": M.MODE_AUTONOMOUS, "left": 0, "right": 0})
            time.sleep(0.5)
        assert app.show_coverage
        app.advance(prerun)
        times = loop.time_frames(window, frames)
        real_frames = app.real.frames if app.real is not None else 0
        t_sim = app.sim.sim.robot.t
    finally:
        app.close()
        loop.close()
    med = statistics.median(times)
    return {"speed": speed, "robots": 3 if port else 2, "frames": len(times), "median_ms": 1000 * med,
            "p90_ms": 1000 * statistics.quantiles(times, n=10)[-1], "max_ms": 1000 * max(times),
            "fps": 1 / med, "telemetry": real_frames, "sim_s": t_sim - prerun}


def run(args: argparse.Namespace) -> int:
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    rows: list[tuple[str, dict[str, Any]]] = []
    rows.append(("simulated + user robot, speed 1", workload(args.frames, 1.0, None, args.prerun)))
    with tempfile.TemporaryDirectory(prefix="twinbot-bench-gui-") as folder:
        recording = record_replay(Path(folder), REPLAY_S)
        rows.append(("simulated + user robot + replay panel, speed 1",
                     workload(args.frames, 1.0, None, args.prerun, recording)))
    if not args.no_board:
        proc, pty = start_board()
        try:
            rows.append(("three robots (real = virtual board), speed 1", workload(args.frames, 1.0, pty, args.prerun)))
            rows.append(("three robots (real = virtual board), speed 8", workload(args.frames, 8.0, pty, args.prerun)))
        finally:
            proc.terminate()
            proc.wait(10)
    print_report(args, rows)
    return 0


def print_report(args: argparse.Namespace, rows: list[tuple[str, dict[str, Any]]]) -> None:
    import pygame

    from tools.gui.app import SIZE

    print("twinbot bench gui")
    print(f"command:  twinbot bench gui --frames {args.frames} --prerun {args.prerun:g}"
          f"{' --no-board' if args.no_board else ''}")
    print(f"machine:  {machine_line()}")
    print(f"pygame-ce {pygame.version.ver} (SDL {'.'.join(map(str, pygame.get_sdl_version()))}), "
          f"video driver {os.environ.get('SDL_VIDEODRIVER')}, window {SIZE[0]} x {SIZE[1]}, paper_room, coverage overlay, "
          f"rays and trails on; trails {args.prerun:g} s long before timing; frames started at 60 Hz")
    print()
    head = f"{'workload':<46}| median ms | p90 ms | max ms | 1/median | sim s | TELEMETRY rx"
    print(head)
    print("-" * 46 + "+" + "+".join("-" * (len(c)) for c in head.split("|")[1:]))
    for name, r in rows:
        print(f"{name:<46}| {r['median_ms']:9.2f} | {r['p90_ms']:6.2f} | {r['max_ms']:6.2f} | {r['fps']:8.0f} "
              f"| {r['sim_s']:5.1f} | {r['telemetry']:>12}")
    print()
    print("targets:")
    three = [r for name, r in rows if r["robots"] == 3]
    if not three:
        print(f"  [NOT RUN] >= {TARGET_FPS:.0f} frames/s with the three robots (--no-board)")
        return
    worst = min(r["fps"] for r in three)
    p90 = max(r["p90_ms"] for r in three)
    mark = "[MET]   " if worst >= TARGET_FPS else "[MISSED]"
    print(f"  {mark} >= {TARGET_FPS:.0f} frames/s with the three robots, rays and coverage on: median frame "
          f"{1000 / worst:.2f} ms = {worst:.0f} frames/s at worst (p90 {p90:.2f} ms, "
          f"budget {1000 / TARGET_FPS:.2f} ms)")
