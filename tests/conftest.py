"""Shared fixtures."""
from __future__ import annotations

import pytest

from tests.helpers import Pty


@pytest.fixture
def pty_pair():
    """A real pseudo-terminal pair, closed after the test."""
    p = Pty()
    yield p
    p.close()


@pytest.fixture(scope="session")
def wasm_micropython():
    """The 32-bit MicroPython webassembly port, installed once by `npm ci` from host_sim/board/wasm/
    (node_modules there is git-ignored).  Skipped only when Node.js itself is missing."""
    import shutil

    from host_sim.board.micropython_runner import wasm_port

    if not shutil.which("node") or not shutil.which("npm"):
        pytest.skip("node and npm are not installed: the 32-bit MicroPython (webassembly port) needs them")
    return wasm_port()
