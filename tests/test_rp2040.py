"""The emulated RP2040 (docs/rp2040.md): the bridge's own logic always; the rp2 build when one is given.

No MicroPython rp2 image ships with the project, so the tests that run one skip unless
TWINBOT_RP2040_IMAGE and TWINBOT_RP2040_BOOTROM name the user's files; the bridge's UF2 and
bootrom handling, its argument checks and the command line's checks run everywhere.
"""
from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from host_sim.board.micropython_runner import RigError
from host_sim.board.rp2040_board import BOOTROM_ENV, BRIDGE, IMAGE_ENV, emulator, image_files
from tests.helpers import run_twinbot

NEEDS_IMAGE = pytest.mark.skipif(
    not (os.environ.get(IMAGE_ENV) and os.environ.get(BOOTROM_ENV)),
    reason=f"needs {IMAGE_ENV} (the RPI_PICO .uf2 from micropython.org) and {BOOTROM_ENV} (the RP2040's 16 KB bootrom)")
RP2040_FAMILY = 0xE48BFF56


def uf2_block(target: int, payload: bytes, flags: int = 0x2000, family: int = RP2040_FAMILY) -> bytes:
    head = struct.pack("<8I", 0x0A324655, 0x9E5D5157, flags, target, len(payload), 0, 1, family)
    return head + payload.ljust(476, b"\0") + struct.pack("<I", 0x0AB16F30)


def bridge_eval(expression: str, files: dict[str, bytes], tmp_path: Path) -> object:
    """The bridge module's functions run by Node on files written to tmp_path; the JSON of the expression."""
    emulator()
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    script = (f"import fs from 'node:fs'; import * as B from {json.dumps(BRIDGE.as_uri())};\n"
              f"const read = (n) => fs.readFileSync({json.dumps(str(tmp_path))} + '/' + n);\n"
              f"try {{ console.log(JSON.stringify({expression})); }} catch (e) {{ console.log(JSON.stringify({{error: e.message}})); }}\n")
    r = subprocess.run(["node", "--input-type=module", "-e", script], capture_output=True, text=True, timeout=60,
                       cwd=BRIDGE.parent, check=False)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_uf2_blocks_keep_the_rp2040_flash_blocks_only(tmp_path: Path) -> None:
    uf2 = (uf2_block(0x10000000, b"\x01\x02") + uf2_block(0x10000100, b"\x03")
           + uf2_block(0x10000200, b"x", family=0x12345678) + uf2_block(0x10000300, b"y", flags=0x2001))
    blocks = bridge_eval("B.uf2Blocks(read('a.uf2')).map(([o, b]) => [o, Array.from(b)])", {"a.uf2": uf2}, tmp_path)
    assert blocks == [[0, [1, 2]], [0x100, [3]]]


@pytest.mark.parametrize("data, words", [(b"\0" * 511, "multiple of 512"), (b"\0" * 512, "bad magic")])
def test_uf2_refuses_what_is_not_one(data: bytes, words: str, tmp_path: Path) -> None:
    assert words in bridge_eval("B.uf2Blocks(read('b.uf2'))", {"b.uf2": data}, tmp_path)["error"]


def test_bootrom_from_a_binary_or_a_word_list(tmp_path: Path) -> None:
    raw = struct.pack("<4096I", *range(4096))
    listing = ("export const rom = new Uint32Array([" + ", ".join(hex(w) for w in range(4096)) + "]);").encode()
    got = bridge_eval("[B.bootromWords(read('r.bin'))[4095], B.bootromWords(read('r.ts'))[4095]]",
                      {"r.bin": raw, "r.ts": listing}, tmp_path)
    assert got == [4095, 4095]
    assert "16384-byte" in bridge_eval("B.bootromWords(read('x'))", {"x": b"short"}, tmp_path)["error"]


def test_flash_routines_become_breakpoints(tmp_path: Path) -> None:
    """The bootrom's flash_range_erase ('RE') and flash_range_program ('RP') entries are found through its
    function table (a 16-bit pointer at 0x14) and replaced by BKPT #0xe0 and #0xe1."""
    rom = bytearray(16384)
    struct.pack_into("<H", rom, 0x14, 0x100)
    struct.pack_into("<HHHHHHH", rom, 0x100, ord("R") | ord("E") << 8, 0x201, ord("R") | ord("P") << 8, 0x301,
                     ord("I") | ord("F") << 8, 0x401, 0)
    got = bridge_eval("(() => { const w = B.patchFlashRoutines(B.bootromWords(read('rom.bin'))); "
                      "const v = new DataView(w.buffer); return [v.getUint16(0x200, true), v.getUint16(0x300, true), "
                      "v.getUint16(0x400, true)]; })()", {"rom.bin": bytes(rom)}, tmp_path)
    assert got == [0xBEE0, 0xBEE1, 0]


def test_bridge_without_its_files_says_what_it_needs() -> None:
    emulator()
    r = subprocess.run(["node", str(BRIDGE)], capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 2 and r.stderr.strip().startswith("rp2040: usage:") and r.stdout == ""


def test_image_files_name_what_to_provide(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(IMAGE_ENV, raising=False)
    monkeypatch.delenv(BOOTROM_ENV, raising=False)
    with pytest.raises(RigError, match=f"{IMAGE_ENV}.*{BOOTROM_ENV}"):
        image_files()
    (tmp_path / "x.uf2").write_bytes(b"not a uf2")
    (tmp_path / "rom.bin").write_bytes(b"\0" * 16384)
    with pytest.raises(RigError, match="not a UF2 image"):
        image_files(str(tmp_path / "x.uf2"), str(tmp_path / "rom.bin"))


def test_board_command_line_checks(tmp_path: Path) -> None:
    """--rp2040 refuses the virtual board's own hardware options; a UF2 without --rp2040 is named as such."""
    r = run_twinbot("board", "--rp2040", "--standin")
    assert r.returncode == 2 and "--standin" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    uf2 = tmp_path / "fw.uf2"
    uf2.write_bytes(uf2_block(0x10000000, b"\0"))
    r = run_twinbot("board", "--image", str(uf2), "--standin")
    assert r.returncode == 2 and "--rp2040" in r.stderr and len(r.stderr.strip().splitlines()) == 1


@NEEDS_IMAGE
def test_the_emulated_pico_boots_to_its_repl(tmp_path: Path) -> None:
    from host_sim.board.rp2040_board import Rp2040Board

    board = Rp2040Board(*image_files(), tmp_path / "bridge.log")
    try:
        assert board.wait_port_up(timeout=300), board.log()
        r = subprocess.run([sys.executable, "-m", "mpremote", "connect", board.path, "resume", "exec",
                            "import sys; print(sys.platform, sys.implementation._build)"],
                           capture_output=True, text=True, timeout=300, check=False)
        assert r.stdout.split() == ["rp2", "RPI_PICO"], r.stdout + r.stderr
    finally:
        board.close()


@NEEDS_IMAGE
def test_flash_vectors_cycles_and_watchdog_on_the_rp2_build(tmp_path: Path) -> None:
    """`twinbot bench firmware --rp2040`'s measurements, on few cycles: HELLO after flashing, golden vectors
    identical (free and under heap_lock), 0 B per cycle, >= 100 KB free, and the watchdog's reset back to HELLO."""
    from tools.bench.firmware_rp2040 import measure

    f = measure(*image_files(), tmp_path, 50)
    assert f["flash"]["hello"], f["flash"]
    assert f["vectors"]["free"].startswith("ok") and f["vectors"]["locked"].startswith("ok"), f["vectors"]
    assert f["cycle"]["alloc_bytes_per_cycle"] == 0 and f["cycle"]["heap_locked_cycles_ok"]
    assert f["cycle"]["heap_free"] >= 100 * 1024 and f["cycle"]["max_us"] < 40_000
    assert f["watchdog"]["watchdog_reset"] and f["watchdog"]["hello_after"], f["watchdog"]


def test_duties_give_back_the_firmware_s_values() -> None:
    """The bridge reports PWM compare values (6,250 counts at 20 kHz, fewer than duty_u16's 65,536): every
    current in mA and every emitter power in % the firmware can set comes back exactly."""
    from host_sim.board.rp2040_pins import _compare_value, value_of_duty

    for full_scale in (1000, 100):
        for top_plus_1 in (6250, 65535):
            assert all(value_of_duty(_compare_value(v, full_scale, top_plus_1), top_plus_1, full_scale) == v
                       for v in range(full_scale + 1))


PINS_CHECK = """
import { PinDriver } from %s;
const counts = [0, 0], levels = {};
const gpio = Array.from({ length: 30 }, (_, n) => ({
  irqStatus: 0, outputValue: false,
  setInputValue(v) {  // the firmware's handlers (firmware/hal_rp2040.py _edge_left, _edge_right) on channel A
    levels[n] = v;
    if (n === 6) counts[0] += v !== !!levels[7] ? 1 : -1;
    if (n === 8) counts[1] += v === !!levels[9] ? 1 : -1;
  },
}));
const alarm = { schedule() {}, cancel() {} };
const watchdog = { enable: true, writeUint32() {} };
const mcu = { gpio, clock: { createAlarm: () => alarm, nanos: 0 }, adc: { completeADCRead() {} },
  core: { currentMode: 0 }, peripherals: { [0x40058000 >>> 12]: watchdog },
  pwm: { channels: Array.from({ length: 8 }, () => ({ cc: 0, top: 6249 })) } };
const pins = { mux: [10, 11, 12], ir_adc: 0, battery_adc: 2, emitter: 13, motor_pwm: [16, 18], motor_dir: [17, 19],
  enc_a: [6, 8], enc_b: [7, 9], mirrored: [false, true] };
const reports = [];
const driver = new PinDriver(mcu, pins, (m) => reports.push(m));
const seen = [];
for (const enc of [[0, 0], [5, -3], [2, 4], [-7, 4]]) {
  driver.apply({ off: [0, 0, 0, 0, 0, 0, 0, 0], on: [0, 0, 0, 0, 0, 0, 0, 0], enc, battery: 0 });
  for (let k = 0; k < 40; k++) driver.nextEdge();
  seen.push([...counts]);
  watchdog.writeUint32(4, 1);
}
console.log(JSON.stringify({ seen, reports: reports.map((m) => Object.keys(m)[0]), held: driver.held }));
"""


def test_encoder_edges_count_as_the_firmware_counts(tmp_path: Path) -> None:
    """The pin driver's edges on channels A and B, counted by the firmware's own rule (the right motor
    mirrored), reach the twin's counts both ways; each cycle's end reports the outputs and holds the chip."""
    emulator()
    script = tmp_path / "check.mjs"
    script.write_text(PINS_CHECK % json.dumps((BRIDGE.parent / "pins.mjs").as_uri()))
    r = subprocess.run(["node", str(script)], capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    assert got["seen"] == [[0, 0], [5, -3], [2, 4], [-7, 4]]
    assert got["reports"] == ["actuate"] * 4 and got["held"]


@NEEDS_IMAGE
def test_sixty_seconds_on_the_emulated_pico_are_the_sil_run(tmp_path: Path) -> None:
    """Issue 41's SIL-equivalent run: a blank emulated Pico flashed by `twinbot flash` (HELLO), then 60 s of
    the firmware in autonomous mode with the twin on its pins (ADC, encoder edges, PWM duties), in lockstep:
    the same commands and the same trajectory as the SIL run of the same world and seed, bit for bit."""
    import time

    import numpy as np

    from host_sim.board.pil import PilLink
    from host_sim.board.rp2040_board import Rp2040Board, Rp2040Controller
    from host_sim.controller.sil import SilController
    from host_sim.loops.simulation import Simulation
    from host_sim.physics.params import DEFAULT
    from host_sim.physics.world import builtin_world
    from tools.bench.firmware_rp2040 import flash_and_hello

    room = builtin_world("paper_room")
    link = PilLink()
    board = Rp2040Board(*image_files(), tmp_path / "bridge.log", hw_port=link.port)
    try:
        assert board.wait_port_up(timeout=300), board.log()
        flashed = flash_and_hello(board)
        assert flashed["hello"], flashed
        controller = Rp2040Controller(board, link, 1)
        t0 = time.monotonic()
        pico = Simulation(room, DEFAULT, controller, seed=3).run_fixed(60.0)
        wall_s = time.monotonic() - t0
        controller.close()
    finally:
        board.close()
        link.close()
    sil = Simulation(room, DEFAULT, SilController(1), seed=3).run_fixed(60.0)
    assert len(pico.t) == 1500 and b"(watchdog)" not in board.log()  # no cycle stalled the chip
    assert np.array_equal(sil.cmd, pico.cmd), f"{wall_s:.0f} s of wall time"
    assert np.array_equal(sil.pose, pico.pose) and pico.collisions == sil.collisions
    assert np.hypot(*(pico.pose[-1, :2] - pico.pose[0, :2])) > 0.5  # it explored
