"""The RP2040's small integers are 31-bit: the firmware proven on a 32-bit MicroPython (docs/firmware.md).

The 64-bit unix port keeps any value up to 2**62 a small int, so it cannot show an
intermediate past 2**30, which on the RP2040 is a big int: a heap allocation every cycle.
The webassembly port (host_sim/board/micropython_runner.py run_micropython_wasm) has 31-bit
small ints; under micropython.heap_lock() a big int raises MemoryError there, so the checks
below fail on any value beyond +-2**30 on the paths they run.  Same golden vectors, same bits.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from host_sim.board.micropython_runner import run_micropython, run_micropython_wasm, wasm_path

HERE = Path(__file__).resolve().parent
MP = HERE / "mp"
GOLDEN = HERE / "data" / "firmware_golden.jsonl"
CHECKER = MP / "firmware_vectors_check.py"


def test_the_check_bites_on_32_bits_only(wasm_micropython) -> None:
    """2**30 - 1 is a small int and 2**30 a heap allocation on the 32-bit port; the 64-bit unix port
    allocates for neither (which is why it cannot prove the firmware's ranges)."""
    r = run_micropython_wasm(MP / "bigint_probe.py")
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.strip() == "maxsize 2147483647 alloc at 2**30-1: 0 alloc at 2**30: 1"
    r = run_micropython(MP / "bigint_probe.py")
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.strip() == "maxsize 9223372036854775807 alloc at 2**30-1: 0 alloc at 2**30: 0"


def test_golden_vectors_bit_for_bit_and_allocation_free_on_32_bits(wasm_micropython) -> None:
    """All 12,500 firmware golden vectors (max_speed 0..1000, power 0..100, every averaging method
    and window, kp and ki up to 100,000, current_limit up to 3000, multi-turn odometry steps, encoder
    counts at the wrap) give the same outputs on the 32-bit port, with every call into the firmware
    inside heap_lock().  Every parameter at its minimum and maximum, the geometry included, is driven
    by test_control_cycles_allocate_nothing_on_32_bits."""
    header = json.loads(GOLDEN.read_text(encoding="ascii").split("\n", 1)[0])
    r = run_micropython_wasm(CHECKER, wasm_path(GOLDEN), "--locked", files=[GOLDEN])
    assert r.returncode == 0, r.stdout + r.stderr
    m = re.fullmatch(r"firmware vectors: (\d+) cases ok \(.*\), heap locked\n", r.stdout)
    assert m and int(m.group(1)) == header["total"], r.stdout


def test_locked_vectors_catch_a_big_int(wasm_micropython, tmp_path) -> None:
    """An encoder count past the HAL's range (2**31) makes the wheel loop compute with big ints: the
    locked check names the allocation on the 32-bit port, while the 64-bit unix port, locked too,
    passes the same case (its small ints reach 2**62)."""
    from firmware.wheels import WheelLoop

    lines = GOLDEN.read_text(encoding="ascii").splitlines()
    header = json.loads(lines[0])
    header["counts"] = {k: (1 if k == "wh" else 0) for k in header["counts"]}
    loop = WheelLoop(20000, 400, 2000, 3000)
    steps = []
    for k, ticks in enumerate((2 ** 31, 2 ** 31 + 300, 2 ** 31 + 650)):
        dt = 0 if k == 0 else 40
        loop.measure(ticks, dt)
        loop.control(200, dt)
        steps.append([ticks, dt, 200, loop.speed, loop.current, loop.acc, 1 if loop.clamped else 0])
    bad = tmp_path / "bigint.jsonl"
    bad.write_text(json.dumps(header) + "\n" + json.dumps(["wh", 20000, 400, 2000, 3000, steps]) + "\n")
    r = run_micropython_wasm(CHECKER, wasm_path(bad), "--locked", files=[bad])
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stdout.startswith("firmware vectors: FAIL line 2 (wh case 0): allocation in wheel measure"), r.stdout
    r = run_micropython(CHECKER, str(bad), "--locked")
    assert r.returncode == 0 and "1 cases ok" in r.stdout, r.stdout + r.stderr


def test_protocol_allocates_nothing_on_32_bits(wasm_micropython) -> None:
    """tests/mp/alloc_check.py (frames, garbage, corrupted frames, overflows; send and receive under
    heap_lock) on the 32-bit port."""
    r = run_micropython_wasm(MP / "alloc_check.py", heapsize="64k")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "no MemoryError" in r.stdout and r.stdout.rstrip().endswith("alloc: ok"), r.stdout


def test_control_cycles_allocate_nothing_on_32_bits(wasm_micropython) -> None:
    """tests/mp/firmware_cycle_check.py (locked cycles over every mode, parameter and hostile
    frame it sends) on the 32-bit port."""
    r = run_micropython_wasm(MP / "firmware_cycle_check.py")
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("cycle: ok "), r.stdout
