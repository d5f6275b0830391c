"""Test helpers: real pseudo-terminals and running the twinbot command."""
from __future__ import annotations

import os
import subprocess
import sys
import tty
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


class Pty:
    """A real pseudo-terminal pair: a program opens `path`, the test holds `master`."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line editing: bytes pass as they are
        self.path = os.ttyname(self.slave)

    def write(self, data: bytes) -> None:
        os.write(self.master, data)

    def read_available(self, timeout: float = 0.2) -> bytes:
        import select

        out = b""
        while True:
            ready, _, _ = select.select([self.master], [], [], timeout)
            if not ready:
                return out
            try:
                chunk = os.read(self.master, 4096)
            except OSError:
                return out
            if not chunk:
                return out
            out += chunk
            timeout = 0.05

    def close(self) -> None:
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


def twinbot_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "tools.cli.main", *args]


def run_twinbot(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(twinbot_cmd(*args), capture_output=True, text=True, timeout=timeout, cwd=REPO, check=False)
