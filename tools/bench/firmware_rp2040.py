"""`twinbot bench firmware --rp2040`: the firmware on MicroPython's rp2 build, in an emulated RP2040.

A blank emulated Pico (host_sim/board/rp2040_board.py) is flashed with `twinbot flash`'s own steps and
must answer HELLO; then, through mpremote, the golden vectors, the control cycle's time in emulated
time at 125 MHz, its allocations and the heap; last, a firmware that hangs must be reset by
machine.WDT and come back with HELLO.  Where the emulator's timing is not the chip's: docs/rp2040.md.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from host_sim.board.micropython_runner import REPO_ROOT, RigError
from tools.arguments import CliError

PERIOD_US = 40_000  # the control period (firmware/config.py)
TARGET_CYCLE_US = 10_000  # a quarter of the period, worst case
TARGET_FREE_KB = 100
VECTORS_PER_KIND = 10  # golden cases per kind sent to the board (the link, not the chip, limits it)
GOLDEN = REPO_ROOT / "tests" / "data" / "firmware_golden.jsonl"
STAGED_SCRIPTS = ("tools/bench/mp/mp_firmware.py", "tests/mp/firmware_vectors_check.py")


def _progress(text: str) -> None:
    print(f"  ... {text}", file=sys.stderr, flush=True)


def golden_subset(path: Path, per_kind: int) -> int:
    """The first per_kind cases of each kind of the golden file, with a header that counts them."""
    lines = GOLDEN.read_text(encoding="ascii").splitlines()
    header = json.loads(lines[0])
    kept: list[str] = []
    counts = {kind: 0 for kind in header["counts"]}
    for line in lines[1:]:
        kind = json.loads(line)[0]
        if counts[kind] < per_kind:
            counts[kind] += 1
            kept.append(line)
    header.update(counts=counts, total=len(kept))
    path.write_text("\n".join([json.dumps(header), *kept]) + "\n", encoding="ascii")
    return len(kept)


def stage_sources(stage: Path) -> None:
    """What the board imports over mpremote's mount, compiled with mpy-cross as `twinbot flash` does (the
    emulated chip would take minutes to compile the sources): the firmware, the test HAL, two scripts."""
    from firmware.manifest import BOARD_FILES
    from host_sim.board.micropython_runner import mpy_cross_compile

    for rel in (*BOARD_FILES, "firmware/hal_testbench.py", *STAGED_SCRIPTS):
        dst = stage / (rel[:-3] + ".mpy" if rel in BOARD_FILES or "firmware/" in rel else Path(rel).stem + ".mpy")
        dst.parent.mkdir(parents=True, exist_ok=True)
        r = mpy_cross_compile(REPO_ROOT / rel, dst)
        if r.returncode != 0:
            raise RigError(f"mpy-cross failed on {rel}: {r.stderr.strip()}")


def board_exec(port: str, stage: Path, code: str, timeout: float) -> str:
    """Run code on the board with STAGE mounted as its current folder; its printout (RigError on failure)."""
    cmd = [sys.executable, "-m", "mpremote", "connect", port, "resume", "mount", str(stage), "exec", code]
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        raise RigError(f"the emulated board did not finish within {timeout:.0f} s: {code[:60]}...") from None
    if r.returncode != 0 or "Traceback" in r.stdout:
        raise RigError(f"on the emulated board: {(r.stdout + r.stderr).strip()[-600:]}")
    return r.stdout


def last_json(text: str) -> dict:  # type: ignore[type-arg]
    return json.loads([line for line in text.splitlines() if line.startswith("{")][-1])  # type: ignore[no-any-return]


CYCLE_CODE = """import gc, json, micropython
import mp_firmware as B
hal, robot = B.make_robot()
n = {n}
d = [0] * n
gc.collect()
B.time_cycles(robot, hal, n, d)
d.sort()
out = {{'cycles': n, 'median_us': d[n // 2], 'p90_us': d[n * 9 // 10], 'max_us': d[-1]}}
m = min(n, {checked})
out['alloc_bytes_per_cycle'] = B.alloc_per_cycle(robot, hal, m, d)
out['heap_locked_cycles_ok'] = B.cycles_run_heap_locked(robot, hal, m, d)
out['checked_cycles'] = m
out['faults'] = robot.faults
gc.collect()
out['heap_free'] = gc.mem_free()
out['heap_in_use'] = gc.mem_alloc()
print(json.dumps(out))
"""


def cycle_figures(port: str, stage: Path, cycles: int, checked: int) -> dict:  # type: ignore[type-arg]
    """Control cycles on the test HAL (firmware/hal_testbench.py) timed with the board's own ticks_us."""
    return last_json(board_exec(port, stage, CYCLE_CODE.format(n=cycles, checked=checked), 3600))


def vectors(port: str, stage: Path, locked: bool) -> str:
    code = ("import firmware_vectors_check as V\n"
            + ("import micropython\nV._lock = (micropython.heap_lock, micropython.heap_unlock)\n" if locked else "")
            + "try:\n    c, t = V.check_file('golden.jsonl')\n    print('ok', t)\n"
              "except V.Mismatch as e:\n    print('FAIL', e)\n")
    out = board_exec(port, stage, code, 1800).strip().splitlines()
    return out[-1] if out else "no answer"


def fresh_stage(tmp: Path) -> Path:
    stage = tmp / "stage"
    stage.mkdir()
    stage_sources(stage)
    return stage


def register_options(p: argparse.ArgumentParser) -> None:
    from tools.arguments import input_file

    p.add_argument("--rp2040", action="store_true",
                   help="measure on MicroPython's rp2 build in an emulated RP2040 instead (docs/rp2040.md)")
    p.add_argument("--image", metavar="FILE", type=input_file,
                   help="with --rp2040: the MicroPython rp2 .uf2 (default: $TWINBOT_RP2040_IMAGE)")
    p.add_argument("--bootrom", metavar="FILE", type=input_file,
                   help="with --rp2040: the RP2040's 16 KB bootrom (default: $TWINBOT_RP2040_BOOTROM)")


def run_rp2040(args: argparse.Namespace) -> int:
    from host_sim.board.rp2040_board import image_files

    try:
        image, bootrom = image_files(args.image, args.bootrom)
    except RigError as exc:
        raise CliError(str(exc)) from None
    t_start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="twinbot-rp2040-") as tmp:
        try:
            figures = measure(image, bootrom, Path(tmp), args.cycles)
        except RigError as exc:
            raise CliError(str(exc)) from None
    report(figures, image, args.cycles, time.monotonic() - t_start)
    if args.json:
        from tools.arguments import writing

        with writing("--json", args.json):
            Path(args.json).write_text(json.dumps(figures, indent=2, default=str))
    return 0


def flash_and_hello(board) -> dict:  # type: ignore[no-untyped-def, type-arg]
    """`twinbot flash` on the blank board, as a user runs it: it copies, resets and waits for HELLO."""
    t0 = time.monotonic()
    cmd = [sys.executable, "-m", "tools.cli.main", "flash", "--port", board.path, "--timeout", "300"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=1200, cwd=REPO_ROOT, check=False)
    said = (r.stdout + r.stderr).strip().splitlines()
    return {"hello": r.returncode == 0 and "answered HELLO" in r.stdout, "wall_s": time.monotonic() - t0,
            "said": said[-1] if said else ""}


HANG = b"\r\x03\x03\r\nimport machine\r\nw = machine.WDT(timeout=1000)\r\nwhile True: pass\r\n\r\n"


def watchdog_recovery(board) -> dict:  # type: ignore[no-untyped-def, type-arg]
    """A firmware that hangs with machine.WDT armed: the chip must restart and main.py's firmware send HELLO."""
    from host_sim.board.serial_link import SerialLink
    from protocol import messages as M

    link = SerialLink.open(board.path)  # open before the reset: the firmware's first HELLO is not missed
    try:
        link.port.write(HANG)
        t0 = time.monotonic()
        deadline = t0 + 600
        while time.monotonic() < deadline and b"(watchdog)" not in board.log():
            time.sleep(0.2)
        reset = b"(watchdog)" in board.log()
        hello = link.wait_for(M.HELLO, 300) if reset else None
    finally:
        link.close()
    return {"watchdog_reset": reset, "hello_after": hello is not None, "wall_s": time.monotonic() - t0}


def measure(image: Path, bootrom: Path, tmp: Path, cycles: int) -> dict:  # type: ignore[type-arg]
    from host_sim.board.rp2040_board import Rp2040Board

    board = Rp2040Board(image, bootrom, tmp / "bridge.log")
    try:
        if not board.wait_port_up(timeout=300):
            raise RigError(f"the emulated board's USB serial port did not come up: {board.log()[-300:]!r}")
        figures: dict = {"image": str(image)}  # type: ignore[type-arg]
        _progress("flash a blank board with twinbot flash's steps, then HELLO")
        figures["flash"] = flash_and_hello(board)
        stage = fresh_stage(tmp)
        n = golden_subset(stage / "golden.jsonl", VECTORS_PER_KIND)
        _progress(f"golden vectors: {n} cases, then again under heap_lock")
        figures["vectors"] = {"cases": n, "free": vectors(board.path, stage, False),
                              "locked": vectors(board.path, stage, True)}
        _progress(f"{cycles} control cycles in emulated time")
        figures["cycle"] = cycle_figures(board.path, stage, cycles, min(cycles, 500))
        _progress("a hung firmware under machine.WDT")
        figures["watchdog"] = watchdog_recovery(board)
        figures["boots"] = board.log().decode("utf-8", "replace").count("rp2040: boot ")
        return figures
    finally:
        board.close()


def report(f: dict, image: Path, cycles: int, wall_s: float) -> None:  # type: ignore[type-arg]
    from tools.bench.report import machine_line

    fl, cy, vec, wd = f["flash"], f["cycle"], f["vectors"], f["watchdog"]
    print("twinbot bench firmware --rp2040")
    print(f"machine:     {machine_line()}")
    print(f"image:       {image.name} (MicroPython rp2, RPI_PICO) in rp2040js, 125 MHz, one core")
    print()
    print(f"twinbot flash on a blank board: {'HELLO' if fl['hello'] else 'NO HELLO'} after {fl['wall_s']:.0f} s "
          f"of wall time ({fl['said']})")
    print(f"golden vectors ({vec['cases']} cases, {VECTORS_PER_KIND} of each kind): {vec['free']}; "
          f"under heap_lock: {vec['locked']}")
    print(f"control cycle (test HAL), emulated time over {cy['cycles']} cycles: median {cy['median_us']} us, "
          f"p90 {cy['p90_us']} us, max {cy['max_us']} us; period {PERIOD_US} us")
    print(f"  allocated per cycle: {cy['alloc_bytes_per_cycle']:.2f} B; {cy['checked_cycles']} cycles under "
          f"heap_lock(): {'ok' if cy['heap_locked_cycles_ok'] else 'ALLOCATED'}")
    print(f"  heap with the firmware loaded and running: {cy['heap_in_use'] / 1024:.1f} KB in use, "
          f"{cy['heap_free'] / 1024:.1f} KB free")
    print(f"watchdog: hung firmware reset by machine.WDT: {'yes' if wd['watchdog_reset'] else 'NO'}; "
          f"HELLO after it: {'yes' if wd['hello_after'] else 'NO'}")
    print()
    hello_ok = fl["hello"] and wd["hello_after"]
    vec_ok = vec["free"].startswith("ok") and vec["locked"].startswith("ok")
    print("targets:")
    print(f"  [{'MET' if cy['max_us'] <= TARGET_CYCLE_US else 'MISSED'}]  worst cycle <= {TARGET_CYCLE_US} us "
          f"at 125 MHz: {cy['max_us']} us over {cy['cycles']} cycles")
    print(f"  [{'MET' if cy['heap_free'] >= TARGET_FREE_KB * 1024 else 'MISSED'}]  >= {TARGET_FREE_KB} KB heap free: "
          f"{cy['heap_free'] / 1024:.1f} KB")
    alloc_ok = cy["alloc_bytes_per_cycle"] == 0 and cy["heap_locked_cycles_ok"]
    print(f"  [{'MET' if alloc_ok else 'MISSED'}]  0 B allocated per cycle")
    print(f"  [{'MET' if vec_ok else 'MISSED'}]  golden vectors identical")
    print(f"  [{'MET' if hello_ok else 'MISSED'}]  HELLO after flashing and after a watchdog reset")
    print(f"\nelapsed: {wall_s:.1f} s")
