"""Counters and accumulators cross their 31-bit limits alike on CPython and MicroPython, 64- and 32-bit.

The checks are in tests/mp/counters_check.py, written once for every interpreter; under MicroPython
each runs inside heap_lock(), so on the 32-bit port a value past 2**30 fails it (docs/firmware.md).
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from host_sim.board.micropython_runner import run_micropython, run_micropython_wasm

MP_DIR = Path(__file__).resolve().parent / "mp"
sys.path.insert(0, str(MP_DIR))

import counters_check  # noqa: E402


@pytest.mark.parametrize("name", counters_check.CHECKS)
def test_on_cpython(name: str) -> None:
    getattr(counters_check, name)()


def test_on_micropython_64_bit() -> None:
    r = run_micropython(MP_DIR / "counters_check.py", path=[MP_DIR])
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"counters: {len(counters_check.CHECKS)} checks ok" in r.stdout


def test_on_micropython_32_bit(wasm_micropython: object) -> None:
    r = run_micropython_wasm(MP_DIR / "counters_check.py", path=[MP_DIR])
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"counters: {len(counters_check.CHECKS)} checks ok" in r.stdout
