"""The protocol's send and receive paths allocate nothing under the real MicroPython.

tests/mp/alloc_check.py feeds a few kB of frames, garbage, corrupted frames and
overflows byte by byte and in chunks, and encodes frames with pack_into +
finish + view, all inside micropython.heap_lock() (any allocation raises
MemoryError), then again with the GC disabled comparing gc.mem_alloc().
"""
from __future__ import annotations

import re
import struct
from pathlib import Path

import pytest

from protocol import messages

from host_sim.board.micropython_runner import REPO_ROOT, mpy_cross_compile, run_micropython

SCRIPT = Path(__file__).resolve().parent / "mp" / "alloc_check.py"


def _check(r) -> None:
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert "no MemoryError" in r.stdout, out
    assert "alloc: 0 bytes allocated per received byte (gc.mem_alloc delta 0 over" in r.stdout, out
    assert r.stdout.rstrip().endswith("alloc: ok"), out


def test_script_format_matches_layout() -> None:
    """The script's TELEMETRY format literal (the firmware's way) is messages.FORMATS[TELEMETRY]."""
    m = re.search(r'^TELEMETRY_FMT = "([^"]+)"', SCRIPT.read_text(), re.M)
    assert m and m.group(1) == messages.FORMATS[messages.TELEMETRY]


def test_no_allocation_default_heap() -> None:
    """Default heap, protocol/ compiled from source: zero allocations per received or sent byte."""
    r = run_micropython(SCRIPT, timeout=120)
    _check(r)
    assert "protocol/framing.py" in r.stdout


@pytest.fixture(scope="module")
def mpy_dir(tmp_path_factory) -> Path:
    """protocol/ compiled with mpy-cross, the form that goes onto the board."""
    out = tmp_path_factory.mktemp("mpy")
    (out / "protocol").mkdir()
    for src in sorted((REPO_ROOT / "protocol").glob("*.py")):
        r = mpy_cross_compile(src, out / "protocol" / (src.stem + ".mpy"))
        assert r.returncode == 0, r.stdout + r.stderr
    return out


@pytest.mark.parametrize("form", ["source", "mpy"])
def test_no_allocation_64k_heap(form: str, mpy_dir: Path) -> None:
    """In a 64 kB heap (from source, and as the .mpy files that go onto the board) the same
    run passes: fixed buffers suffice and nothing grows."""
    path = [mpy_dir] if form == "mpy" else None
    r = run_micropython(SCRIPT, heapsize="64k", path=path, timeout=120)
    _check(r)
    assert ("framing.mpy" if form == "mpy" else "protocol/framing.py") in r.stdout


def test_firmware_formats_match_layouts() -> None:
    """firmware/robot.py packs TELEMETRY and HELLO with the layouts' formats and sizes."""
    from firmware import robot

    assert robot._TELEMETRY_FMT == messages.FORMATS[messages.TELEMETRY]
    assert robot._TELEMETRY_SIZE == messages.PAYLOAD_SIZE[messages.TELEMETRY]
    assert struct.calcsize(robot._HELLO_FMT) == struct.calcsize(messages.FORMATS[messages.HELLO])
    assert robot._HELLO_FMT.replace("6B", "BBBBBB") == messages.FORMATS[messages.HELLO]
    assert robot._HELLO_SIZE == messages.PAYLOAD_SIZE[messages.HELLO]
