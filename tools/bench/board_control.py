"""The virtual board as a control for `twinbot bench diagnose --board-controls`.

The firmware runs on the virtual board, whose hardware is the nominal twin, and is recorded through the
real serial path by `twinbot serial --excite`, idle and with busy processes oversubscribing the cores.
Each recording must be diagnosed a match: docs/proving-ground.md, "The virtual board as a control".
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

BUSY_PER_CORE = 3  # the oversubscribed control: three busy processes per core, as a shared CI box


def busy_levels() -> tuple[int, ...]:
    """Idle, and three busy processes per core of this machine."""
    return 0, BUSY_PER_CORE * (os.cpu_count() or 1)


def _record(out_dir: Path, busy: int, duration: float) -> tuple[Path, float]:
    """Record `twinbot serial --excite` against a fresh virtual board with `busy` spinning processes; the
    recording's path and the wall seconds it took."""
    from host_sim.board.board_twin import BoardTwin
    from host_sim.board.virtual_board import VirtualBoard, factory_image
    from host_sim.physics.params import DEFAULT
    from host_sim.physics.world import builtin_world

    twin = BoardTwin(builtin_world("paper_room"), DEFAULT)
    twin.start()
    flash = out_dir / f"flash_busy{busy}"
    flash.mkdir(parents=True, exist_ok=True)
    factory_image(flash)
    board = VirtualBoard(str(flash), twin.port, out_dir / f"board_busy{busy}.log")
    loads = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(busy)]
    run = out_dir / f"board_busy{busy}.csv"
    start = time.monotonic()
    try:
        done = subprocess.run([sys.executable, "-m", "tools.cli.main", "serial", board.path, "--excite",
                               "--record", str(run), "--duration", f"{duration:g}", "--quiet"],
                              capture_output=True, text=True, timeout=duration * 4 + 120)
    finally:
        for proc in loads:
            proc.kill()
            proc.wait()
        board.close()
        twin.stop()
    if done.returncode != 0:
        raise RuntimeError(f"twinbot serial failed (busy {busy}): {done.stderr.strip()[-300:]}")
    return run, time.monotonic() - start


def run_board_controls(out_dir: Path, duration: float) -> list[dict[str, Any]]:
    """One row per busy level: the verdict, its summary, and how late the board's rows came."""
    from host_sim.diagnosis import diagnose
    from host_sim.physics.params import DEFAULT
    from host_sim.recordings.recording import load_recording

    rows = []
    for busy in busy_levels():
        path, wall = _record(out_dir, busy, duration)
        rec = load_recording(path)
        periods = np.diff(rec.t)
        d = diagnose(rec, DEFAULT, None)
        rows.append({"busy": busy, "cores": os.cpu_count(), "recording": str(path), "wall_s": wall,
                     "verdict": d.verdict, "summary": d.summary(),
                     "late_share": float(np.mean(np.abs(periods - 0.04) > 5e-4)),
                     "period_median_ms": float(np.median(periods) * 1e3),
                     "period_max_ms": float(np.max(periods) * 1e3)})
    return rows


def format_rows(rows: list[dict[str, Any]]) -> list[str]:
    lines = ["The virtual board as a control (firmware over the serial link, `twinbot serial --excite`):",
             f"  {'busy':>4} {'cores':>5} {'late rows':>9} {'median ms':>9} {'max ms':>7}  verdict"]
    for r in rows:
        lines.append(f"  {r['busy']:>4} {r['cores']:>5} {r['late_share']:>9.0%} {r['period_median_ms']:>9.1f} "
                     f"{r['period_max_ms']:>7.0f}  {r['verdict']}")
    return lines
