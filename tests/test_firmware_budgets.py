"""Embedded budgets, proven under the real MicroPython (docs/firmware.md, Budgets).

- No heap allocation per control cycle in steady state: cycles run under heap_lock(), with
  host COMMAND frames arriving, in every combination of rule set, IR averaging and odometry.
- The firmware loaded from .mpy with a Robot running: on the 32-bit webassembly port the heap
  it keeps is within the 32 KB target; on the 64-bit unix port (objects twice the size) the
  whole run, test board included, fits a 64 KB heap.  `twinbot bench firmware` reports them.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from tools.bench.firmware import TARGET_HEAP_KB, compile_for_heap, heap_run, wasm_heap_run
from host_sim.board.micropython_runner import run_micropython

MP_DIR = Path(__file__).resolve().parent / "mp"
HEAP_BUDGET_KB_UNIX64 = 64


@pytest.fixture(scope="module")
def stage(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("heap")
    compile_for_heap(out)
    return out


def test_control_cycle_allocates_nothing():
    r = run_micropython(MP_DIR / "firmware_cycle_check.py", heapsize="512k")
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("cycle: ok ")


def test_firmware_from_mpy_runs_in_a_small_heap(stage):
    result = heap_run(stage, HEAP_BUDGET_KB_UNIX64)
    assert result is not None, f"the firmware does not run in a {HEAP_BUDGET_KB_UNIX64} KB heap"
    assert result["cycles"] == 220 and result["faults"] == 0
    too_small = heap_run(stage, 16)
    assert too_small is None  # the measurement can fail: the budget means something


def test_firmware_heap_on_32_bits_within_target(stage, wasm_micropython):
    """32-bit MicroPython: every firmware module from .mpy plus a Robot after 220 cycles keeps at most
    32 KB of heap in use (the test board not counted), and the port really is 32-bit."""
    result = wasm_heap_run(stage, 1024)
    assert result["cycles"] == 220 and result["faults"] == 0
    assert 16 * 1024 < int(result["heap_in_use"]) <= TARGET_HEAP_KB * 1024, result  # type: ignore[call-overload]
    assert not result["grew"]
    # The port tells when a run outgrows its heap (it enlarges it instead of failing).
    assert wasm_heap_run(stage, 16)["grew"]
