"""The virtual board as a process: firmware/unix_board.py under MicroPython, behind a pty.

`twinbot board` and the simulator's PIL mode start boards through this; the board's
hardware link connects to a simulator (or a stand-in) on 127.0.0.1 (docs/firmware.md).
A late link (`late_s`, `jitter_s`) delays what the board writes, seeded and in order as on
a slow radio link, while the host's bytes reach the board at once: the late-signal twin's
bench for a real host (docs/late-signal-twin.md).
"""
from __future__ import annotations

import errno
import os
import random
import select
import shutil
import subprocess
import threading
import time
import tty
from collections import deque
from pathlib import Path

from firmware.manifest import BOARD_FILES, MAIN_PY
from host_sim.board.micropython_runner import REPO_ROOT, micropython_exe

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

    def __init__(self, flash: str, hw_port: int, stderr_path: Path | None = None, *, late_s: float = 0.0,
                 jitter_s: float = 0.0, seed: int = 0) -> None:
        self.flash = flash
        self.late_s, self.jitter_s = late_s, jitter_s
        self._rng = random.Random(seed)
        self._due: deque[tuple[float, bytes]] = deque()  # the board's output in flight on a late link
        self._last_due = 0.0
        self.hw_port = hw_port
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        os.set_blocking(self.master, False)
        self._stderr = open(stderr_path, "ab") if stderr_path else subprocess.DEVNULL
        command, env = self.board_command()
        self.proc = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self._stderr, env=env, bufsize=0, pass_fds=self.board_fds())
        self.dropped = 0  # bytes the board sent while nobody read the port
        self._tail = b""  # the board's last output: a traceback when it dies (the unix port prints it on stdout)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._relay, name="pty relay", daemon=True)
        self._thread.start()

    def board_command(self) -> tuple[list[str], dict[str, str]]:
        """The board's process: its command line and environment (the emulated RP2040 has its own)."""
        env = dict(os.environ, TWINBOT_HW=f"127.0.0.1:{self.hw_port}", MICROPYPATH="")
        return [micropython_exe(), str(SUPERVISOR), self.flash], env

    def board_fds(self) -> tuple[int, ...]:
        """File descriptors the board's process inherits besides its stdio (the emulated RP2040's pins)."""
        return ()

    def _relay(self) -> None:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        board_out = self.proc.stdout.fileno()
        board_in = self.proc.stdin.fileno()
        # Until the board's stdout ends (not until it exits): its last words are read too.
        while not self._stop.is_set():
            wait = 0.1 if not self._due else min(0.1, max(0.0, self._due[0][0] - time.monotonic()))
            ready, _, _ = select.select([board_out, self.master], [], [], wait)
            if board_out in ready:
                data = os.read(board_out, 4096)
                if not data:
                    return
                self._tail = (self._tail + data)[-TAIL_BYTES:]
                self._to_port(data)
            self._deliver_due()
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

    def _to_port(self, data: bytes) -> None:
        """The board's output to the pty: now, or when it is due on a late link."""
        if self.late_s <= 0.0 and self.jitter_s <= 0.0:
            self._write_port(data)
            return
        delay = max(0.0, self.late_s + self._rng.uniform(-self.jitter_s, self.jitter_s))
        self._last_due = max(time.monotonic() + delay, self._last_due)  # in order, as on a serial line
        self._due.append((self._last_due, data))

    def _deliver_due(self) -> None:
        now = time.monotonic()
        while self._due and self._due[0][0] <= now:
            self._write_port(self._due.popleft()[1])

    def _write_port(self, data: bytes) -> None:
        try:
            os.write(self.master, data)
        except OSError as exc:  # nobody reads the port and its buffer is full
            if exc.errno not in (errno.EAGAIN, errno.EIO):
                raise
            self.dropped += len(data)

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
