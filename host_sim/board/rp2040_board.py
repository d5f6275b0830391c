"""The emulated Raspberry Pi Pico: a MicroPython rp2 image the user provides, in rp2040js, behind a pty.

rp2040js (npm, pinned in host_sim/board/rp2040/package.json, installed by `npm ci` on first use)
runs the image; host_sim/board/rp2040/run_rp2040.mjs joins its USB CDC to a pipe and this puts
the virtual board's pseudo-terminal in front of it.  No image ships with the project: it is named
by --image/--bootrom or TWINBOT_RP2040_IMAGE/TWINBOT_RP2040_BOOTROM (docs/rp2040.md).
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

from host_sim.board.micropython_runner import REPO_ROOT, RigError, npm_installed
from host_sim.board.pil import PilLink
from host_sim.board.rp2040_pins import PinsCoupler, pin_map
from host_sim.board.virtual_board import VirtualBoard
from host_sim.controller.hardware_io import Actuate, Sense, setup_frames
from host_sim.physics.params import RobotParams

RP2040_DIR = REPO_ROOT / "host_sim" / "board" / "rp2040"
BRIDGE = RP2040_DIR / "run_rp2040.mjs"
EMULATOR_PACKAGE = "rp2040js"
IMAGE_ENV = "TWINBOT_RP2040_IMAGE"
BOOTROM_ENV = "TWINBOT_RP2040_BOOTROM"
BOOTROM_BYTES = 16 * 1024
UF2_MAGIC = b"UF2\n"
WHAT_TO_PROVIDE = (f"an RP2040 MicroPython image (the RPI_PICO .uf2 from micropython.org) as --image or "
                   f"{IMAGE_ENV}, and the RP2040's 16 KB bootrom as --bootrom or {BOOTROM_ENV}")


def image_files(image: str | None = None, bootrom: str | None = None) -> tuple[Path, Path]:
    """(UF2 image, bootrom) from the arguments, else from the environment; RigError says what is missing."""
    image = image or os.environ.get(IMAGE_ENV)
    bootrom = bootrom or os.environ.get(BOOTROM_ENV)
    if not image or not bootrom:
        raise RigError(f"the emulated RP2040 needs {WHAT_TO_PROVIDE}")
    uf2, rom = Path(image), Path(bootrom)
    for path in (uf2, rom):
        if not path.is_file():
            raise RigError(f"{path}: no such file ({WHAT_TO_PROVIDE})")
    with open(uf2, "rb") as f:
        if f.read(4) != UF2_MAGIC:
            raise RigError(f"{uf2}: not a UF2 image (the RPI_PICO .uf2 from micropython.org is one)")
    if rom.stat().st_size != BOOTROM_BYTES and b"Uint32Array([" not in rom.read_bytes()[:4096]:
        raise RigError(f"{rom}: not an RP2040 bootrom (its raw binary is {BOOTROM_BYTES} bytes)")
    return uf2.resolve(), rom.resolve()


def emulator() -> Path:
    """The bridge's folder, with rp2040js installed there by `npm ci` if needed."""
    return npm_installed(RP2040_DIR, EMULATOR_PACKAGE, "the emulated RP2040")


def bridge_command(image: Path, bootrom: Path, flash: Path | None = None, twin_fd: int | None = None) -> list[str]:
    cmd = ["node", str(BRIDGE), "--image", str(image), "--bootrom", str(bootrom)]
    if twin_fd is not None:
        cmd += ["--twin-fd", str(twin_fd), "--pins", json.dumps(pin_map())]
    return cmd + (["--flash", str(flash)] if flash else [])


PORT_UP = b"rp2040: USB serial port up"


class Rp2040Board(VirtualBoard):
    """The emulated Pico behind a pty, with the virtual board's face (path, alive, last_words, close).

    Its hardware is the chip's own pins in the emulator (firmware/hal_rp2040.py): at rest, or with
    hw_port, driven by the twin serving that hardware link (rp2040_pins.PinsCoupler), in lockstep with
    the firmware's cycles.  The bridge's stderr goes to stderr_path: `rp2040: boot N (REASON)` at
    every start, `rp2040: USB serial port up` when the host may talk to it (wait_port_up)."""

    def __init__(self, image: Path, bootrom: Path, stderr_path: Path, flash: Path | None = None,
                 hw_port: int | None = None) -> None:
        emulator()
        self.image, self.bootrom, self.flash_file = image, bootrom, flash
        self.pins = PinsCoupler(hw_port) if hw_port is not None else None
        self.stderr_path = stderr_path
        self._log_start = stderr_path.stat().st_size if stderr_path.exists() else 0
        super().__init__(str(flash or ""), 0, stderr_path)
        if self.pins:
            self.pins.start()

    def board_command(self) -> tuple[list[str], dict[str, str]]:
        twin_fd = self.pins.bridge_end.fileno() if self.pins else None
        return bridge_command(self.image, self.bootrom, self.flash_file, twin_fd), dict(os.environ)

    def board_fds(self) -> tuple[int, ...]:
        return (self.pins.bridge_end.fileno(),) if self.pins else ()

    def close(self) -> None:
        super().close()
        if self.pins:
            self.pins.close()

    def log(self) -> bytes:
        """What the bridge said on stderr since this board started."""
        with open(self.stderr_path, "rb") as f:
            f.seek(self._log_start)
            return f.read()

    def wait_port_up(self, count: int = 1, timeout: float = 120.0) -> bool:
        """Wait until the port has come up `count` times (once per boot); False if it did not in time."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.alive():
            if self.log().count(PORT_UP) >= count:
                return True
            time.sleep(0.1)
        return False


class Rp2040Controller:
    """The firmware on the emulated Pico as a simulation's controller (processor in the loop): the
    simulation's HW_SENSE drives the chip's pins and the duties it sets come back as HW_ACTUATE, one
    control cycle of the firmware's own clock per exchange (docs/rp2040.md, "The twin on the pins")."""

    name = "PIL (RP2040)"

    def __init__(self, board: Rp2040Board, link: PilLink, rule_set: int = 1, params: RobotParams | None = None,
                 accept_s: float = 300.0) -> None:
        from host_sim.board.serial_link import SerialLink

        self.board, self.link = board, link
        link.accept(timeout=accept_s)  # the board connects once its firmware's loop waits for readings
        self.host = SerialLink.open(board.path)
        for frame in setup_frames(rule_set, params=params):
            self.host.send_raw(frame)
        time.sleep(0.2)  # the chip is held: the frames wait at its USB port and arrive in cycle 0

    def cycle(self, s: Sense) -> Actuate:
        return self.link.exchange(s)

    def close(self) -> None:
        self.host.close()
