"""The firmware's behaviour, on CPython (one test per check) and under MicroPython (all at once).

The checks themselves are in tests/mp/firmware_behaviour.py, written once
for both interpreters.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from host_sim.board.micropython_runner import run_micropython

MP_DIR = Path(__file__).resolve().parent / "mp"
sys.path.insert(0, str(MP_DIR))

import firmware_behaviour  # noqa: E402


@pytest.mark.parametrize("name", firmware_behaviour.CHECKS)
def test_on_cpython(name):
    getattr(firmware_behaviour, name)()


def test_on_micropython():
    r = run_micropython(MP_DIR / "firmware_behaviour.py", heapsize="1m", path=[MP_DIR])
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"behaviour: {len(firmware_behaviour.CHECKS)} checks ok" in r.stdout
