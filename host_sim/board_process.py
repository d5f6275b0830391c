"""The virtual board as a process: MicroPython running firmware/unix_board.py,
its stdin/stdout relayed to a pseudo-terminal.

`twinbot board` and the simulator's PIL mode both start boards through
this.  The board's hardware link connects to a TCP port on 127.0.0.1 where
a simulator (or the stand-in of `twinbot board --standin`) serves
HW_SENSE / HW_ACTUATE frames.
"""
from __future__ import annotations

import errno
import os
import select
import shutil
import subprocess
import threading
import tty
from pathlib import Path

from firmware.manifest import BOARD_FILES, MAIN_PY
from host_sim.micropython_tools import REPO_ROOT, micropython_exe

SUPERVISOR = REPO_ROOT / "firmware" / "unix_board.py"
TAIL_BYTES = 2048


def factory_image(folder: Path) -> None:
    """Write what a freshly flashed board holds: the manifest's sources and main.py."""
    for rel in BOARD_FILES:
        dst = folder / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO_ROOT / rel, dst)
    (folder / "main.py").write_text(MAIN_PY)


class VirtualBoard:
    """A running virtual board: the MicroPython process, its pty and its relay."""

    def __init__(self, flash: str, hw_port: int, stderr_path: Path | None = None) -> None:
        self.flash = flash
        self.hw_port = hw_port
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        os.set_blocking(self.master, False)
        env = dict(os.environ, TWINBOT_HW=f"127.0.0.1:{hw_port}", MICROPYPATH="")
        self._stderr = open(stderr_path, "ab") if stderr_path else subprocess.DEVNULL
        self.proc = subprocess.Popen(
            [micropython_exe(), str(SUPERVISOR), flash], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=self._stderr, env=env, bufsize=0,
        )
        self.dropped = 0  # bytes the board sent while nobody read the port
        self._tail = b""  # the board's last output: a traceback when it dies (the unix port prints it on stdout)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._relay, name="pty relay", daemon=True)
        self._thread.start()

    def _relay(self) -> None:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        board_out = self.proc.stdout.fileno()
        board_in = self.proc.stdin.fileno()
        # Until the board's stdout ends (not until it exits): its last words are read too.
        while not self._stop.is_set():
            ready, _, _ = select.select([board_out, self.master], [], [], 0.1)
            if board_out in ready:
                data = os.read(board_out, 4096)
                if not data:
                    return
                self._tail = (self._tail + data)[-TAIL_BYTES:]
                try:
                    os.write(self.master, data)
                except OSError as exc:  # nobody reads the port and its buffer is full
                    if exc.errno not in (errno.EAGAIN, errno.EIO):
                        raise
                    self.dropped += len(data)
            if self.master in ready:
                try:
                    data = os.read(self.master, 4096)
                except OSError:
                    continue
                if data:
                    try:
                        os.write(board_in, data)
                    except BrokenPipeError:
                        return

    def alive(self) -> bool:
        return self.proc.poll() is None

    def last_words(self) -> str:
        """The last line of text the board printed (after it stopped: the error that stopped it)."""
        if not self.alive():
            self._thread.join(1.0)
        text = self._tail.replace(b"\r", b"\n").decode("utf-8", "replace")
        lines = [line.strip() for line in text.split("\n")
                 if line.strip() and all(c.isprintable() for c in line.strip())]
        return lines[-1] if lines else ""

    def close(self) -> None:
        self._stop.set()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._thread.join(2)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass
        if self._stderr is not subprocess.DEVNULL:
            self._stderr.close()  # type: ignore[union-attr]
