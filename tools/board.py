"""`twinbot board`: the firmware on a virtual board, behind a pseudo-terminal.

The board is the MicroPython unix port running firmware/unix_board.py: it boots
main.py from its own flash (a folder, or a littlefs image of a given size),
offers the REPL that mpremote drives, and runs the firmware, whose host
link is the board's stdin/stdout.  This module relays those to a
pseudo-terminal, so `twinbot serial`, mpremote or any terminal program
opens the printed /dev/pts/N as they would a Pico's /dev/ttyACM0.

The firmware's electrical I/O (HW_SENSE / HW_ACTUATE) goes to the robot's
twin: the simulator, in real time, in the world of --world (the paper's
room by default).  Drive the board as the real robot: `twinbot serial
/dev/pts/N --command autonomous 0 0` and it explores.  --standin serves
fixed readings instead (a wall in front, wheels that do not turn).
"""
from __future__ import annotations

import argparse
import select
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

from host_sim.board_process import VirtualBoard, factory_image
from host_sim.interface import TICK_MASK
from protocol import messages as M
from protocol.framing import FrameDecoder, FrameEncoder
from tools.cli import CliError


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
               "then, in another terminal:\n"
               "  twinbot serial /dev/pts/N          live telemetry\n"
               "  twinbot flash --port /dev/pts/N    flash it\n"
               "  mpremote connect /dev/pts/N resume repl",
    )
    p.add_argument("--flash-dir", metavar="DIR",
                   help="the board's flash as a folder (default: a new temporary folder holding this "
                        "checkout's firmware); kept between runs")
    p.add_argument("--image", metavar="FILE", help="the board's flash as a littlefs image file (blank if new)")
    p.add_argument("--flash-kb", type=int, default=1024, help="size of a new --image, KB (default 1024)")
    p.add_argument("--blank", action="store_true", help="start with empty flash (nothing to run until flashed)")
    p.add_argument("--world", default="paper_room", help="the twin's world (default paper_room)")
    p.add_argument("--standin", action="store_true", help="fixed readings instead of the simulated twin")
    p.add_argument("--hw-port", type=int,
                   help="TCP port on 127.0.0.1 of another simulator serving the hardware link")
    p.add_argument("--log", metavar="FILE", help="append the board's stderr here (tracebacks of the supervisor)")
    p.set_defaults(func=run)


def prepare_flash(args: argparse.Namespace) -> tuple[str, str]:
    """The flash argument for the supervisor, and how to describe it."""
    if args.image:
        if args.flash_dir:
            raise CliError("give --image or --flash-dir, not both")
        if args.flash_kb < 64:
            raise CliError("--flash-kb must be at least 64 (littlefs needs a few blocks)")
        image = Path(args.image).resolve()
        return f"{image}:{args.flash_kb}", f"littlefs image {image} ({args.flash_kb} KB)"
    if args.flash_dir:
        folder = Path(args.flash_dir).resolve()
        if folder.exists() and not folder.is_dir():
            raise CliError(f"--flash-dir {folder} exists and is not a folder")
        fresh = not folder.exists() or not any(folder.iterdir())
        folder.mkdir(parents=True, exist_ok=True)
    else:
        folder = Path(tempfile.mkdtemp(prefix="twinbot-board-"))
        fresh = True
    if fresh and not args.blank:
        factory_image(folder)
    return str(folder), f"folder {folder}"


def run(args: argparse.Namespace) -> int:
    flash, described = prepare_flash(args)
    standin = None
    twin = None
    if args.hw_port is not None:
        hw_port = args.hw_port
    elif args.standin:
        standin = StandInHardware()
        standin.start()
        hw_port = standin.port
    else:
        from host_sim.params import DEFAULT
        from host_sim.board_twin import BoardTwin
        from host_sim.world import WorldError, world_by_name_or_path

        try:
            world = world_by_name_or_path(args.world, DEFAULT.body_radius)
        except WorldError as exc:
            raise CliError(str(exc)) from None
        twin = BoardTwin(world, DEFAULT)
        twin.start()
        hw_port = twin.port
    board = VirtualBoard(flash, hw_port, Path(args.log) if args.log else None)
    print(f"twinbot board: {board.path}", flush=True)
    print(f"  flash: {described}")
    if standin:
        print("  hardware: STAND-IN with fixed readings (a wall ahead, wheels that do not turn)")
    elif twin:
        print(f"  hardware: the simulated twin in {world.name}, real time "
              f"(start at x={world.start[0]:.2f} m, y={world.start[1]:.2f} m)")
    else:
        print(f"  hardware: simulator at 127.0.0.1:{hw_port}")
    print(f"  talk to it: twinbot serial {board.path}   |   flash it: twinbot flash --port {board.path}")
    print("  Ctrl-C stops the board.", flush=True)
    try:
        while board.alive():
            time.sleep(0.2)
        print(f"twinbot board: the board stopped (exit status {board.proc.returncode})", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    finally:
        board.close()
        if standin:
            standin.stop()
        if twin:
            x, y, phi = twin.pose
            print(f"twinbot board: the twin ended at x={x:.3f} m, y={y:.3f} m, heading {phi:.2f} rad, "
                  f"{twin.sim.robot.collisions} collisions")
            twin.stop()

