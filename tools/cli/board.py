"""`twinbot board`: the firmware on a virtual board, behind a pseudo-terminal.

MicroPython's unix port runs firmware/unix_board.py (its own flash, boot, REPL, resets) and
this relays its stdin/stdout to a pty that `twinbot serial`, mpremote or a terminal opens as
a Pico's /dev/ttyACM0.  Its hardware is the robot's twin in --world, in real time; drive it as
the real robot (`twinbot serial /dev/pts/N --command autonomous 0 0`).  --standin serves fixed
readings instead.  --late MS [--jitter MS] delays what the board sends, to try the late-signal
twin against a real host (docs/firmware.md, docs/late-signal-twin.md).  --rp2040: an rp2 image
(--image, --bootrom) on an emulated Pico, the twin on its pins in lockstep (docs/rp2040.md).
"""
from __future__ import annotations

import argparse
import os
import re
import select
import signal
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Callable

from host_sim.board.virtual_board import VirtualBoard, factory_image
from host_sim.controller.hardware_io import TICK_MASK
from protocol import messages as M
from protocol.framing import FrameDecoder, FrameEncoder
from host_sim.board.rp2040_board import UF2_MAGIC
from tools.arguments import float_range, input_file, int_range, output_file, output_folder, tcp_port
from tools.arguments import CliError
from tools.cli.sim import plural


# What the stand-in hardware reports: ambient light on every sensor, a wall
# about 10 cm in front of S1 (strong reflection) and seen obliquely by S2, S8.
STANDIN_AMBIENT = (180, 175, 170, 165, 160, 165, 170, 175)
STANDIN_REFLECTION = (900, 260, 0, 0, 0, 0, 0, 240)  # at 100 % emitter power
STANDIN_VBAT_MV = 7400


class StandInHardware:
    """Serves HW_SENSE at the control rate with fixed readings; logs HW_ACTUATE."""

    def __init__(self, cycle_ms: int = 40) -> None:
        self.cycle_s = cycle_ms / 1000
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.actuations = 0
        self.last_actuate: dict[str, object] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="stand-in hardware", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self.server.close()

    def sense_payload(self, tick_ms: int, emitter_pct: int) -> bytes:
        on = [min(4095, a + r * emitter_pct // 100) for a, r in zip(STANDIN_AMBIENT, STANDIN_REFLECTION)]
        return M.pack_payload(M.HW_SENSE, {
            "tick_ms": tick_ms & TICK_MASK, "adc_off": list(STANDIN_AMBIENT), "adc_on": on,
            "enc_l": 0, "enc_r": 0, "vbat_mv": STANDIN_VBAT_MV,
        })

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.server.accept()
            except OSError:
                return
            with conn:
                self._session(conn)

    def _session(self, conn: socket.socket) -> None:
        enc = FrameEncoder()
        dec = FrameDecoder()
        t0 = time.monotonic()
        k = 0
        power = 60
        conn.setblocking(False)
        while not self._stop.is_set():
            tick = int(k * self.cycle_s * 1000)
            try:
                conn.sendall(enc.encode(M.HW_SENSE, self.sense_payload(tick, power)))
            except OSError:
                return
            k += 1
            deadline = t0 + k * self.cycle_s
            while True:
                wait = deadline - time.monotonic()
                if wait <= 0:
                    break
                ready, _, _ = select.select([conn], [], [], wait)
                if not ready:
                    continue
                try:
                    data = conn.recv(4096)
                except OSError:
                    return
                if not data:
                    return  # the firmware stopped (REPL) or the board reset
                for t, _seq, payload in dec.decode_all(data):
                    if t == M.HW_ACTUATE:
                        self.last_actuate = M.unpack_payload(t, payload)
                        power = int(self.last_actuate["emitter_pct"])  # type: ignore[call-overload]
                        self.actuations += 1


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        name, help=summary, formatter_class=argparse.RawDescriptionHelpFormatter,
        description=__doc__.split("\n\n", 1)[1],
        epilog="examples:\n"
               "  twinbot board                      a board flashed with this checkout's firmware\n"
               "  twinbot board --flash-kb 256 --image board.img   a blank 256 KB board to flash\n"
               "  twinbot board --rp2040 --image RPI_PICO.uf2 --bootrom rp2040.rom   an emulated Pico\n"
               "then, in another terminal:\n"
               "  twinbot serial /dev/pts/N          live telemetry\n"
               "  twinbot flash --port /dev/pts/N    flash it\n"
               "  mpremote connect /dev/pts/N resume repl",
    )
    p.add_argument("--flash-dir", metavar="DIR", type=output_folder,
                   help="the board's flash as a folder, kept between runs (default: a temporary folder "
                        "holding this checkout's firmware, removed when the board stops)")
    p.add_argument("--image", metavar="FILE", type=image_path,
                   help="the board's flash as a littlefs image file (blank if new); with --rp2040, the "
                        "MicroPython rp2 .uf2 to run (default: $TWINBOT_RP2040_IMAGE)")
    p.add_argument("--rp2040", action="store_true",
                   help="an emulated Raspberry Pi Pico (rp2040js) running --image, the twin on its pins")
    p.add_argument("--bootrom", metavar="FILE", type=input_file,
                   help="with --rp2040: the RP2040's 16 KB bootrom (default: $TWINBOT_RP2040_BOOTROM)")
    p.add_argument("--flash-kb", type=int_range(64, 65536, unit="KB"), default=1024,
                   help="size of a new --image, KB, 64..65536 (default 1024)")
    p.add_argument("--blank", action="store_true", help="start with empty flash (nothing to run until flashed)")
    p.add_argument("--world", default="paper_room", help="the twin's world (default paper_room)")
    p.add_argument("--standin", action="store_true", help="fixed readings instead of the simulated twin")
    p.add_argument("--hw-port", type=tcp_port,
                   help="TCP port on 127.0.0.1 of another simulator serving the hardware link")
    p.add_argument("--late", type=float_range(0, 10_000, unit="ms"), default=0.0, metavar="MS",
                   help="the board's output (its TELEMETRY) reaches the pty MS ms late, in order (default 0)")
    p.add_argument("--jitter", type=float_range(0, 10_000, unit="ms"), default=0.0, metavar="MS",
                   help="with --late: each chunk's delay varies uniformly by +-MS ms (seeded; default 0)")
    p.add_argument("--log", metavar="FILE", type=output_file,
                   help="append the board's stderr here (tracebacks of the supervisor)")
    p.set_defaults(func=run)


LFS_MAGIC = b"littlefs"  # in the superblock, at the start of block 0 or 1
LFS_BLOCK = 4096  # firmware/unix_board.py FileBlockDevice.BLOCK


def image_path(text: str) -> str:
    """--image: a new file, an existing littlefs image or a UF2 image for --rp2040 (never some other
    file, which the board would refuse)."""
    output_file(text)
    path = Path(text)
    if path.exists() and path.stat().st_size:
        with open(path, "rb") as f:
            head = f.read(2 * LFS_BLOCK)
        if LFS_MAGIC not in head and not head.startswith(UF2_MAGIC):
            raise argparse.ArgumentTypeError(f"{text}: not a littlefs image (no littlefs superblock in its first "
                                             f"two blocks); name a new file for a blank board")
    return text


def prepare_flash(args: argparse.Namespace, scratch: Path) -> tuple[str, str]:
    """The flash argument for the supervisor, and how to describe it."""
    if args.image and Path(args.image).is_file() and Path(args.image).read_bytes()[:4] == UF2_MAGIC:
        raise CliError(f"--image {args.image} is a UF2 firmware image: it runs on the emulated Pico, add --rp2040")
    if args.image:
        if args.flash_dir:
            raise CliError("give --image or --flash-dir, not both")
        image = Path(args.image).resolve()
        return f"{image}:{args.flash_kb}", f"littlefs image {image} ({args.flash_kb} KB)"
    if args.flash_dir:
        folder = Path(args.flash_dir).resolve()
        if folder.exists() and not folder.is_dir():
            raise CliError(f"--flash-dir {folder} exists and is not a folder")
        fresh = not folder.exists() or not any(folder.iterdir())
        folder.mkdir(parents=True, exist_ok=True)
    else:
        folder = scratch / "flash"
        folder.mkdir()
        fresh = True
    if fresh and not args.blank:
        factory_image(folder)
    return str(folder), f"folder {folder}"


STARTUP_S = 1.0  # a board that stops this soon never booted: say why instead of where to connect


def serve_until_it_stops(board: VirtualBoard, stderr_path: Path, offset: int) -> int:
    """Name the board's port for the user and wait: a board that stops by itself is trouble (status 1)."""
    print(f"  talk to it: twinbot serial {board.path}   |   flash it: twinbot flash --port {board.path}")
    print("  Ctrl-C stops the board.", flush=True)
    while board.alive():
        time.sleep(0.2)
    print(f"twinbot board: {board_trouble(board, stderr_path, offset)}", file=sys.stderr)
    return 1


def board_trouble(board: VirtualBoard, stderr_path: Path, offset: int) -> str:
    """Why a board stopped: its exit status and the last line it printed (stdout: MicroPython's
    tracebacks) or wrote on stderr (the supervisor's)."""
    try:
        with open(stderr_path, "rb") as f:
            f.seek(offset)
            lines = f.read().decode("utf-8", "replace").strip().splitlines()
    except OSError:
        lines = []
    last = lines[-1].strip() if lines else board.last_words()
    errno_text = re.fullmatch(r"OSError: \[?(?:Errno )?(\d+)\]?", last)
    if errno_text:  # MicroPython gives bare errno numbers
        last += f" ({os.strerror(int(errno_text.group(1)))})"
    reason = f": {last}" if last else ""
    return f"the board stopped (exit status {board.proc.returncode}){reason}"


def run(args: argparse.Namespace) -> int:
    # SIGTERM (kill, a test's terminate()) unwinds like Ctrl-C does, so the scratch folder goes too.
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    if args.rp2040:
        return run_rp2040(args)
    with tempfile.TemporaryDirectory(prefix="twinbot-board-") as scratch:
        return run_in(args, Path(scratch))


def run_in(args: argparse.Namespace, scratch: Path) -> int:
    """`twinbot board` with a scratch folder (the temporary flash, the board's stderr) removed afterwards."""
    world = load_world(args)  # before anything is started or written
    flash, described = prepare_flash(args, scratch)
    standin, twin, hw_port = start_hardware(args, world)
    stderr_path, offset = board_stderr(args.log, scratch)
    board = VirtualBoard(flash, hw_port, stderr_path, late_s=args.late / 1000.0, jitter_s=args.jitter / 1000.0)
    lines = [f"  flash: {described}"]
    if standin:
        lines.append("  hardware: STAND-IN with fixed readings (a wall ahead, wheels that do not turn)")
    elif twin and world:
        lines.append(f"  hardware: the simulated twin in {world.name}, real time "
                     f"(start at x={world.start[0]:.2f} m, y={world.start[1]:.2f} m)")
    else:
        lines.append(f"  hardware: simulator at 127.0.0.1:{hw_port}")
    if args.late or args.jitter:
        lines.append(f"  link: LATE, the board's output reaches the pty {args.late:g} +- {args.jitter:g} ms later")
    try:
        return serve_board(board, stderr_path, offset, lambda: virtual_board_trouble(board, stderr_path, offset,
                                                                                     described), lines)
    finally:
        if standin:
            standin.stop()
        if twin:
            say_where_the_twin_ended(twin)


def virtual_board_trouble(board: VirtualBoard, stderr_path: Path, offset: int, described: str) -> str | None:
    """Why the board stopped within STARTUP_S of starting, or None when it is still running."""
    deadline = time.monotonic() + STARTUP_S
    while board.alive() and time.monotonic() < deadline:
        time.sleep(0.05)
    return None if board.alive() else f"{board_trouble(board, stderr_path, offset)}; flash: {described}"


RP2040_STARTUP_S = 120.0  # the emulated boot runs at a fraction of real time on a loaded host
NOT_ON_RP2040 = ("flash_dir", "blank", "standin", "late", "jitter")


def run_rp2040(args: argparse.Namespace) -> int:
    """`twinbot board --rp2040`: the emulated Pico behind a pty, with the virtual board's face; the twin
    in --world (or the simulator at --hw-port) drives its pins in lockstep with the firmware's cycles."""
    from host_sim.board.micropython_runner import RigError
    from host_sim.board.rp2040_board import Rp2040Board, image_files

    clash = [name for name in NOT_ON_RP2040 if getattr(args, name)]
    if clash:
        raise CliError(f"--{clash[0].replace('_', '-')} is not for --rp2040: the emulated Pico's pins are the "
                       f"twin's, its flash its own")
    world = load_world(args)
    try:
        image, bootrom = image_files(args.image, args.bootrom)
    except RigError as exc:
        raise CliError(str(exc)) from None
    _, twin, hw_port = start_hardware(args, world, lockstep=True)
    try:
        with tempfile.TemporaryDirectory(prefix="twinbot-board-") as scratch:
            stderr_path, offset = board_stderr(args.log, Path(scratch))
            board = Rp2040Board(image, bootrom, stderr_path, hw_port=hw_port)
            lines = [f"  image: {image} on an emulated RP2040 (rp2040js, 125 MHz), its REPL on USB CDC"]
            if twin:
                lines.append(f"  hardware: the simulated twin in {twin.sim.world.name} on the chip's pins, in "
                             f"lockstep with the firmware's cycles (slower than real time)")
            else:
                lines.append(f"  hardware: simulator at 127.0.0.1:{hw_port}, on the chip's pins")
            return serve_board(board, stderr_path, offset, lambda: rp2040_trouble(board, stderr_path, offset,
                                                                                   image), lines)
    except RigError as exc:
        raise CliError(str(exc)) from None
    finally:
        if twin:
            say_where_the_twin_ended(twin)


def rp2040_trouble(board, stderr_path: Path, offset: int, image: Path) -> str | None:  # type: ignore[no-untyped-def]
    """Why the emulated Pico's USB serial port did not come up within RP2040_STARTUP_S, or None when it did."""
    if board.wait_port_up(timeout=RP2040_STARTUP_S):
        return None
    trouble = board_trouble(board, stderr_path, offset) if not board.alive() else \
        f"its USB serial port did not come up within {RP2040_STARTUP_S:g} s"
    return f"{trouble}; image: {image}"


def board_stderr(log: str | None, scratch: Path) -> tuple[Path, int]:
    """Where the board's stderr goes (--log, else the scratch folder), and how long that file already is:
    board_trouble reads only what this board wrote."""
    stderr_path = Path(log) if log else scratch / "board-stderr.txt"
    return stderr_path, stderr_path.stat().st_size if stderr_path.exists() else 0


def serve_board(board, stderr_path: Path, offset: int, start_trouble: Callable[[], str | None],  # type: ignore[no-untyped-def]
                lines: list[str]) -> int:
    """Wait for the board to start (start_trouble: why it did not, or None), name its port and then `lines`
    (what it runs on), and serve it until it stops; Ctrl-C is a clean stop (0).  The board is closed either way."""
    try:
        trouble = start_trouble()
        if trouble:
            raise CliError(trouble)
        print(f"twinbot board: {board.path}", flush=True)
        for line in lines:
            print(line)
        return serve_until_it_stops(board, stderr_path, offset)
    except KeyboardInterrupt:
        return 0
    finally:
        board.close()


def say_where_the_twin_ended(twin) -> None:  # type: ignore[no-untyped-def]
    x, y, phi = twin.pose
    print(f"twinbot board: the twin ended at x={x:.3f} m, y={y:.3f} m, heading {phi:.2f} rad, "
          f"{plural(twin.sim.robot.collisions, 'collision')}")
    twin.stop()


def load_world(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    """The twin's world, or None when the hardware is the stand-in or another simulator."""
    if args.hw_port is not None or args.standin:
        return None
    from host_sim.physics.params import DEFAULT
    from host_sim.physics.world import WorldError, world_by_name_or_path

    try:
        return world_by_name_or_path(args.world, DEFAULT.body_radius)
    except WorldError as exc:
        raise CliError(str(exc)) from None


def start_hardware(args: argparse.Namespace, world, lockstep: bool = False):  # type: ignore[no-untyped-def]
    """(stand-in, twin, TCP port) of the board's hardware link; lockstep: the twin steps with the firmware's
    cycles (the emulated Pico) instead of in real time."""
    if args.hw_port is not None:
        return None, None, args.hw_port
    if args.standin:
        standin = StandInHardware()
        standin.start()
        return standin, None, standin.port
    from host_sim.board.board_twin import BoardTwin
    from host_sim.physics.params import DEFAULT

    twin = BoardTwin(world, DEFAULT, lockstep=lockstep)
    twin.start()
    return None, twin, twin.port
