"""`twinbot bench firmware`: the firmware's embedded budgets, measured.

The control cycle's time and allocations and the loaded firmware's heap
under MicroPython (64-bit unix and 32-bit webassembly ports), and one fuzzy
inference beside peer libraries on CPython; DESCRIPTION (the --help text)
says how.  Figures: docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from firmware.manifest import BOARD_FILES
from host_sim.board.micropython_runner import REPO_ROOT, mpy_cross_compile, run_micropython, run_micropython_wasm
from tools.bench.report import machine_line

DESCRIPTION = """\
Under the MicroPython unix port (tools/bench/mp/mp_firmware.py):
  - one full control cycle (IR acquisition with ambient subtraction, fuzzy
    inference, two wheel PIs, odometry, a TELEMETRY frame): median, p90, max;
    the parts timed one by one;
  - heap allocated per cycle in steady state (GC off, mem_alloc before and
    after), and whether the cycles run under micropython.heap_lock();
  - heap: every firmware module loaded from .mpy (as flashed) plus a running
    Robot: the heap in use, and the smallest -X heapsize it runs in.
Under the 32-bit MicroPython webassembly port (Node), where objects are the
RP2040's size: the same heap in use, and the smallest heap the load and the
cycles fit in without ever growing it.  That port collects garbage only
between top-level execs, so the load goes one module per exec and the
figure is an upper bound: a board collects inside an import too.
On CPython: one fuzzy inference of the firmware engine beside peer fuzzy
libraries (tools/bench/fuzzy.py), and the cycle time for information.

The unix port is 64-bit: its objects and GC blocks are twice the size of
an RP2040's, so its heap figures are upper bounds for the robot; the
32-bit port's are the ones the <= 32 KB target is held to.

With --rp2040 (docs/rp2040.md), on MicroPython's rp2 build (--image, a .uf2
the user provides) in an emulated RP2040 instead: `twinbot flash` on a
blank board and its HELLO; the first 10 golden vectors of each kind, free
and under heap_lock; --cycles control cycles on the test HAL timed by the
board's own ticks_us (emulated time at 125 MHz), allocation and heap_lock
over up to 500 of them, the heap free; a hung firmware reset by
machine.WDT and its HELLO after.
"""

MP_SCRIPT = REPO_ROOT / "tools" / "bench" / "mp" / "mp_firmware.py"
HEAP_SCRIPT = REPO_ROOT / "tools" / "bench" / "mp" / "mp_heap_firmware.py"
HEAP_CYCLES = 200
TARGET_CYCLE_US = 250
TARGET_HEAP_KB = 32
TARGET_SPEEDUP = 30


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    from tools.arguments import int_range, output_file

    p.add_argument("--cycles", type=int_range(1, 10_000_000), default=5000,
                   help="cycles timed under MicroPython (default 5000; with --rp2040 each costs about "
                        "0.1 s of wall time)")
    p.add_argument("--repeats", type=int_range(1, 10_000_000), default=2000,
                   help="timed calls per fuzzy engine (default 2000)")
    p.add_argument("--json", metavar="FILE", type=output_file, help="write every figure here")
    from tools.bench.firmware_rp2040 import register_options

    register_options(p)
    # --rp2040's figures are a section of their own on the benchmarks page.
    p.set_defaults(func=run, markdown_section=lambda args: "firmware-rp2040" if args.rp2040 else name)


def _progress(text: str) -> None:
    print(f"  ... {text}", file=sys.stderr, flush=True)


def micropython_timing(cycles: int) -> dict[str, object]:
    r = run_micropython(MP_SCRIPT, "time", str(cycles), heapsize="1m", timeout=600)
    if r.returncode != 0:
        raise RuntimeError(f"MicroPython timing run failed: {r.stderr.strip() or r.stdout.strip()}")
    return json.loads(r.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def compile_for_heap(stage: Path) -> None:
    """Everything the heap run imports, as .mpy, the way a board holds it."""
    for rel in BOARD_FILES + ("firmware/hal_testbench.py",):
        dst = stage / (rel[:-3] + ".mpy")
        dst.parent.mkdir(parents=True, exist_ok=True)
        r = mpy_cross_compile(REPO_ROOT / rel, dst)
        if r.returncode != 0:
            raise RuntimeError(f"mpy-cross failed on {rel}: {r.stderr}")
    r = mpy_cross_compile(HEAP_SCRIPT, stage / "mp_heap_firmware.mpy")
    if r.returncode != 0:
        raise RuntimeError(r.stderr)
    (stage / "run_heap.py").write_text(f"import mp_heap_firmware\nmp_heap_firmware.main({HEAP_CYCLES})\n")


def heap_run(stage: Path, heap_kb: int) -> dict[str, object] | None:
    r = run_micropython(stage / "run_heap.py", heapsize=f"{heap_kb}k", path=[stage], timeout=120)
    if r.returncode != 0:
        return None
    return json.loads(r.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def micropython_heap() -> tuple[dict[str, object], dict[str, object]]:
    """(64-bit unix port, 32-bit webassembly port) heap figures of the firmware from .mpy."""
    with tempfile.TemporaryDirectory(prefix="twinbot-heap-") as tmp:
        stage = Path(tmp)
        compile_for_heap(stage)
        roomy = heap_run(stage, 1024)
        if roomy is None:
            raise RuntimeError("the heap run failed even with a 1 MB heap")
        lo, hi = 8, 1024  # smallest heap (KB, 2 KB steps) in which load + 200 cycles succeed
        while hi - lo > 2:
            mid = (lo + hi) // 2 // 2 * 2
            if heap_run(stage, mid) is None:
                lo = mid
            else:
                hi = mid
        unix = {"in_use_bytes": roomy["heap_in_use"], "harness_bytes": roomy["harness_bytes"],
                "smallest_heap_kb": hi}
        return unix, micropython_wasm_heap(stage)


def wasm_heap_steps() -> list[str]:
    """tools/mp_heap_firmware.main as top-level execs, the load one module at a time
    (BOARD_FILES order, the modules its load() imports, as a fresh interpreter finds them)."""
    import subprocess

    probe = ("import sys; sys.path.insert(0, 'tools/bench/mp'); import mp_heap_firmware as H; H.load(); "
             "print(' '.join(sys.modules))")
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=REPO_ROOT, check=True)
    loaded = set(r.stdout.split())
    modules = [rel[:-3].replace("/", ".").removesuffix(".__init__") for rel in BOARD_FILES]
    steps = ["import mp_heap_firmware as H", "base = gc.mem_alloc()"]
    steps += [f"__import__({m!r})" for m in modules if m in loaded]
    steps += ["before = gc.mem_alloc()", "hal = H.board()", "harness = gc.mem_alloc() - before",
              "robot = H.make_robot(hal)", f"H.run_cycles(robot, hal, {HEAP_CYCLES})",
              "print(H.figures(base, harness, robot))"]
    return steps


def wasm_heap_run(stage: Path, heap_kb: int) -> dict[str, object]:
    """The heap run on the 32-bit port, started with a heap_kb heap; adds `grew`: whether
    the port had to enlarge its heap (it does instead of failing)."""
    (stage / "wasm_heap.py").write_text("import gc\n")
    r = run_micropython_wasm(stage / "wasm_heap.py", heapsize=f"{heap_kb}k", path=[stage],
                             steps=wasm_heap_steps(), heap_report=True, timeout=120)
    lines = r.stdout.strip().splitlines()
    if r.returncode != 0 or len(lines) < 2 or not lines[-1].startswith("wasm-heap: total "):
        raise RuntimeError(f"the 32-bit heap run failed: {r.stderr.strip() or r.stdout.strip()}")
    result: dict[str, object] = json.loads(lines[-2])
    total = int(lines[-1].split()[2])
    result["heap_total_bytes"] = total
    result["grew"] = total > heap_kb * 1024
    return result


def micropython_wasm_heap(stage: Path) -> dict[str, object]:
    """32-bit: the firmware's heap in use, and the smallest heap (2 KB steps) it never outgrows."""
    roomy = wasm_heap_run(stage, 1024)
    lo, hi = 8, 1024
    while hi - lo > 2:
        mid = (lo + hi) // 2 // 2 * 2
        if wasm_heap_run(stage, mid)["grew"]:
            lo = mid
        else:
            hi = mid
    return {"in_use_bytes": roomy["heap_in_use"], "harness_bytes": roomy["harness_bytes"],
            "smallest_heap_kb": hi, "cycles": roomy["cycles"], "faults": roomy["faults"]}


def cpython_cycle_us(cycles: int) -> float:
    from protocol import wire as W
    from protocol.framing import FrameEncoder
    from firmware.robot import Robot
    from firmware.hal_testbench import TestHal

    hal = TestHal()
    robot = Robot(hal)
    hal.give(FrameEncoder().encode(W.COMMAND, bytes((W.MODE_AUTONOMOUS, 0, 0, 0, 0))))
    times = []
    for k in range(cycles):
        hal.reflection[k & 7] = (k * 331) % 3000
        t0 = time.perf_counter()
        robot.cycle()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e6


def run(args: argparse.Namespace) -> int:
    if args.rp2040:
        from tools.bench.firmware_rp2040 import run_rp2040

        return run_rp2040(args)
    t_start = time.monotonic()
    command = f"twinbot bench firmware --cycles {args.cycles} --repeats {args.repeats}"
    _progress(f"MicroPython: {args.cycles} control cycles")
    mp = micropython_timing(args.cycles)
    _progress("MicroPython: heap of the firmware loaded from .mpy, 64-bit unix and 32-bit webassembly ports")
    heap, heap32 = micropython_heap()
    _progress("CPython: control cycle")
    cp_cycle = cpython_cycle_us(min(args.cycles, 5000))
    _progress("CPython: one fuzzy inference, firmware engine and peer libraries")
    try:
        from tools.bench.fuzzy import bench_inference

        fuzzy = bench_inference(args.repeats)
    except ImportError as exc:
        fuzzy = {"error": str(exc)}

    print("twinbot bench firmware")
    print(f"command:     {command}")
    _print_cycle(mp, heap, heap32, cp_cycle)
    print()
    speedup = None
    if "error" in fuzzy:
        print(f"fuzzy peers: not measured ({fuzzy['error']})")
    else:
        print(fuzzy.get("table", ""))
        speedup = fuzzy.get("speedup_vs_fastest_peer")
    print()
    _print_targets(mp, heap, heap32, speedup)
    print(f"\nelapsed: {time.monotonic() - t_start:.1f} s")
    if args.json:
        from tools.arguments import writing

        with writing("--json", args.json):
            Path(args.json).write_text(json.dumps({
                "command": command, "micropython": mp, "heap": heap, "heap_32bit": heap32,
                "cpython_cycle_us": cp_cycle, "fuzzy": {k: v for k, v in fuzzy.items() if k != "table"},
            }, indent=2, default=str))
    return 0


def _print_cycle(mp: dict[str, Any], heap: dict[str, Any], heap32: dict[str, Any], cp_cycle: float) -> None:
    """The machine, then the control cycle's time, parts, allocation and heap."""
    parts = mp["parts_us"]
    assert isinstance(parts, dict)
    print(f"machine:     {machine_line()}")
    print(f"python:      CPython {platform.python_version()}")
    print(f"micropython: MicroPython {mp['micropython']} unix port (64-bit)")
    print()
    print("MicroPython unix port, one control cycle (IR + fuzzy + 2 PI + odometry + TELEMETRY):")
    print(f"  median {mp['cycle_us_median']} us   p90 {mp['cycle_us_p90']} us   max {mp['cycle_us_max']} us"
          f"   over {mp['cycles']} cycles")
    print("  parts, us per call: " + ", ".join(f"{k} {v:.1f}" for k, v in parts.items()))
    print(f"  heap allocated per cycle: {mp['alloc_bytes_per_cycle']:.2f} B; "
          f"cycles under heap_lock(): {'ok' if mp['heap_locked_cycles_ok'] else 'ALLOCATED'}")
    print(f"  heap, all firmware modules from .mpy + a running Robot: {int(heap['in_use_bytes']) / 1024:.1f} KB "
          f"in use; smallest -X heapsize that runs it (with the test board): {heap['smallest_heap_kb']} KB")
    print("MicroPython webassembly port (32-bit, objects the RP2040's size), same firmware and run:")
    print(f"  heap in use {int(heap32['in_use_bytes']) / 1024:.1f} KB (the test board another "
          f"{int(heap32['harness_bytes']) / 1024:.1f} KB); load + cycles fit a heap of "
          f"{heap32['smallest_heap_kb']} KB with no collection inside an import (an upper bound)")
    print(f"CPython {platform.python_version()}: one control cycle, median {cp_cycle:.1f} us")


def _print_targets(mp: dict[str, Any], heap: dict[str, Any], heap32: dict[str, Any], speedup: float | None) -> None:
    cycle_ok = mp["cycle_us_median"] <= TARGET_CYCLE_US
    alloc_ok = mp["alloc_bytes_per_cycle"] == 0 and mp["heap_locked_cycles_ok"]
    heap_ok = int(heap32["in_use_bytes"]) <= TARGET_HEAP_KB * 1024
    print("targets:")
    print(f"  [{'MET' if cycle_ok else 'MISSED'}]  cycle <= {TARGET_CYCLE_US} us on the unix port: "
          f"median {mp['cycle_us_median']} us")
    print(f"  [{'MET' if alloc_ok else 'MISSED'}]  0 allocations per cycle: {mp['alloc_bytes_per_cycle']:.2f} B/cycle")
    print(f"  [{'MET' if heap_ok else 'MISSED'}]  heap <= {TARGET_HEAP_KB} KB with all firmware modules loaded, on 32 "
          f"bits: {int(heap32['in_use_bytes']) / 1024:.1f} KB in use on the webassembly port "
          f"(64-bit unix port: {int(heap['in_use_bytes']) / 1024:.1f} KB)")
    if speedup is not None:
        print(f"  [{'MET' if speedup >= TARGET_SPEEDUP else 'MISSED'}]  one inference >= {TARGET_SPEEDUP}x faster than "
              f"the fastest peer on CPython: {speedup:.0f}x")
