"""Embedded budgets, proven under the MicroPython unix port.

- Zero heap allocations per control cycle in steady state: cycles run under
  micropython.heap_lock(), with host COMMAND frames arriving, in every
  combination of rule set, IR averaging and odometry method.
- The firmware, loaded from .mpy as a board holds it, runs in a small heap.
  The unix port is 64-bit (objects and GC blocks twice an RP2040's), so the
  budget asserted here is 64 KB; `twinbot bench firmware` reports the
  smallest heap it runs in.
"""
from __future__ import annotations

from pathlib import Path

from tools.bench_firmware import compile_for_heap, heap_run
from host_sim.micropython_tools import run_micropython

MP_DIR = Path(__file__).resolve().parent / "mp"
HEAP_BUDGET_KB_UNIX64 = 64


def test_control_cycle_allocates_nothing():
    r = run_micropython(MP_DIR / "firmware_cycle_check.py", heapsize="512k")
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("cycle: ok 1440 cycles")


def test_firmware_from_mpy_runs_in_a_small_heap(tmp_path):
    compile_for_heap(tmp_path)
    result = heap_run(tmp_path, HEAP_BUDGET_KB_UNIX64)
    assert result is not None, f"the firmware does not run in a {HEAP_BUDGET_KB_UNIX64} KB heap"
    assert result["cycles"] == 220 and result["faults"] == 0
    too_small = heap_run(tmp_path, 16)
    assert too_small is None  # the measurement can fail: the budget means something
