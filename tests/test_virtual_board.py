"""The virtual board: the firmware under MicroPython behind a real pseudo-terminal.

Everything here goes through the pty with pyserial, mpremote or the twinbot
command, as it would with a Pico on /dev/ttyACM0.
"""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from protocol import messages as M
from tests.helpers import run_twinbot
from host_sim.board.virtual_board import VirtualBoard, factory_image
from tools.cli.board import STANDIN_AMBIENT, STANDIN_REFLECTION, StandInHardware
from tools.cli.flash import BoardInfo, check_mpy_compatible, mpy_cross_version, probe
from tools.arguments import CliError
from host_sim.board.serial_link import SerialLink


@pytest.fixture
def standin():
    hw = StandInHardware()
    hw.start()
    yield hw
    hw.stop()


@pytest.fixture
def board(tmp_path, standin):
    """A virtual board flashed with this checkout's firmware (sources)."""
    flash = tmp_path / "flash"
    flash.mkdir()
    factory_image(flash)
    vb = VirtualBoard(str(flash), standin.port, tmp_path / "board.log")
    yield vb
    vb.close()


def mpremote(port, *args, timeout=60):
    return subprocess.run([sys.executable, "-m", "mpremote", "connect", port, "resume", *args],
                          capture_output=True, text=True, timeout=timeout, check=False)


def collect(link, seconds, msg_type=M.TELEMETRY):
    out = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        out += [f for f in link.poll(0.05) if f.msg_type == msg_type]
    return out


def test_telemetry_flows_with_ambient_removed_by_the_firmware(board):
    link = SerialLink.open(board.path)
    try:
        link.send(M.HELLO, {"protocol": 1, "fw_major": 0, "fw_minor": 0, "fw_patch": 0, "board": 1, "sensors": 0,
                            "wheel_diameter_um": 0, "wheel_base_um": 0, "ticks_per_rev": 0})
        hello = link.wait_for(M.HELLO, 5)
        assert hello is not None and hello.fields["board"] == M.BOARD_VIRTUAL and hello.fields["sensors"] == 8
        frames = collect(link, 1.0)
    finally:
        link.close()
    assert len(frames) >= 15  # 25 Hz
    assert link.decoder.errors == 0 and link.decoder.seq_gaps == 0
    last = frames[-1].fields
    assert list(last["ir_amb"]) == list(STANDIN_AMBIENT)
    # The stand-in answers the firmware's default emitter power (60 %).
    assert [on - amb for on, amb in zip(last["ir_on"], last["ir_amb"])] == [
        min(4095, a + r * 60 // 100) - a for a, r in zip(STANDIN_AMBIENT, STANDIN_REFLECTION)]
    ticks = [f.fields["tick_ms"] for f in frames]
    assert all(b - a == 40 for a, b in zip(ticks, ticks[1:]))


def test_host_mode_and_watchdog_over_the_port(board, standin):
    link = SerialLink.open(board.path)
    try:
        end = time.monotonic() + 1.0
        while time.monotonic() < end:  # drive at 10 Hz
            link.send(M.COMMAND, {"mode": M.MODE_HOST, "left": 120, "right": 120})
            link.poll(0.1)
        driving = collect(link, 0.05)
        silent = collect(link, 0.8)  # stop sending: the watchdog trips
    finally:
        link.close()
    assert driving and driving[-1].fields["mode"] == M.MODE_HOST
    assert driving[-1].fields["i_ref_l_ma"] > 0  # wheels that do not turn: the PI pushes
    assert not driving[-1].fields["flags"] & M.FLAG_WATCHDOG
    assert silent[-1].fields["flags"] & M.FLAG_WATCHDOG
    assert silent[-1].fields["i_ref_l_ma"] == 0 and silent[-1].fields["i_ref_r_ma"] == 0
    assert standin.last_actuate is not None and standin.last_actuate["i_ref_l_ma"] == 0



class JunkFlood:
    """Random bytes on the board's port at 50 KB/s of the board's own time: 2,000 bytes for every
    TELEMETRY frame (one 40 ms cycle) it sends, so a loaded host slows the flood with the board."""

    PER_CYCLE = 2000

    def __init__(self, link: SerialLink, seed: int = 11) -> None:
        import random

        self.link, self.rng, self.sent = link, random.Random(seed), 0

    def poll(self, wait: float) -> list:
        frames = self.link.poll(wait)
        for f in frames:
            if f.msg_type == M.TELEMETRY:
                # No CR: a break needs a silent cycle first, and a flood has none; this keeps it certain.
                self.link.send_raw(self.rng.randbytes(self.PER_CYCLE).replace(b"\r", b"\x0e"))
                self.sent += self.PER_CYCLE
        return frames


def frames_until(poll, seconds, done):
    """TELEMETRY frames received (through poll) until done(frame), or until the ceiling of seconds."""
    out = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for f in poll(0.02):
            if f.msg_type == M.TELEMETRY:
                out.append(f)
                if done(f):
                    return out
    return out


def test_stop_acts_within_two_periods_under_a_junk_flood(board):
    """50 KB/s of junk in HOST mode: the newest COMMAND wins at once, and STOP acts within two periods,
    both counted in the board's own cycles (its TELEMETRY frames)."""
    link = SerialLink.open(board.path)
    flood = JunkFlood(link)
    try:
        assert frames_until(link.poll, 60, lambda f: True), "the firmware runs"
        for speed in (60, 90, 120, 150, 180, 100):  # changing orders, five board cycles each, under the flood
            link.send(M.COMMAND, {"mode": M.MODE_HOST, "left": speed, "right": -speed})
            for _ in range(5):
                frames_until(flood.poll, 10, lambda f: True)
                link.send(M.COMMAND, {"mode": M.MODE_HOST, "left": speed, "right": -speed})
        seen = frames_until(flood.poll, 10, lambda f: f.fields["sp_l"] == 100)
        link.send(M.COMMAND, {"mode": M.MODE_STOP, "left": 0, "right": 0})
        stop = frames_until(flood.poll, 10, lambda f: f.fields["mode"] == M.MODE_STOP)
    finally:
        link.close()
    assert flood.sent >= 30 * JunkFlood.PER_CYCLE, flood.sent  # the flood ran through every order
    assert seen and seen[-1].fields["sp_l"] == 100 and len(seen) <= 3, [f.fields["sp_l"] for f in seen]
    assert stop and stop[-1].fields["mode"] == M.MODE_STOP, "STOP never acted"
    late = [f for f in stop if f.fields["mode"] != M.MODE_STOP]
    assert len(late) <= 2, f"{len(late)} cycles in HOST mode after the STOP was sent"
    assert stop[-1].fields["sp_l"] == 0 and stop[-1].fields["i_ref_l_ma"] == 0


def test_mpremote_breaks_in_and_reset_restarts_the_firmware(board):
    r = mpremote(board.path, "exec", "import sys; print('board', sys.platform, sys.implementation._mpy)")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["board", "linux", str(mpy_cross_version()[0] | (mpy_cross_version()[1] << 8) | 2 << 10)]
    r = mpremote(board.path, "ls")
    assert "main.py" in r.stdout and "firmware/" in r.stdout
    mpremote(board.path, "reset")
    link = SerialLink.open(board.path)
    try:
        frames = collect(link, 1.0)
    finally:
        link.close()
    assert len(frames) >= 10  # the firmware runs again



def test_a_soft_reset_starts_with_hello(board):
    """After a soft reset the firmware's first frame is HELLO, so the host counts no gap and no lost frame."""
    link = SerialLink.open(board.path)
    try:
        _break_to_the_repl(link)
        link.port.reset_input_buffer()
        link.port.write(b"\x04")  # soft reset at the friendly REPL: main.py starts the firmware again
        frames = []
        deadline = time.monotonic() + 60  # a ceiling, not a wait: a loaded machine restarts MicroPython slowly
        while time.monotonic() < deadline and len(frames) < 5:
            frames += link.poll(0.1)
    finally:
        link.close()
    assert frames and frames[0].msg_type == M.HELLO, [f.msg_type for f in frames[:3]]
    assert frames[0].fields["board"] == M.BOARD_VIRTUAL
    assert link.decoder.seq_gaps == 0 and link.decoder.frames_lost == 0


@pytest.mark.slow
def test_flash_a_blank_board_then_it_answers_hello(tmp_path, standin):
    """End to end, as a user flashes a Pico: mpy-cross, mpremote cp, reset, HELLO."""
    vb = VirtualBoard(f"{tmp_path / 'flash.img'}:512", standin.port, tmp_path / "board.log")
    try:
        r = mpremote(vb.path, "ls")
        assert r.returncode == 0 and "main.py" not in r.stdout  # blank
        robot = tmp_path / "big_wheels.json"  # a robot of its own: its geometry goes on the board
        robot.write_text('{"wheel_radius": 0.026, "half_axle": 0.055}')
        r = run_twinbot("flash", "--port", vb.path, "--params", str(robot), timeout=240)
        assert r.returncode == 0, r.stdout + r.stderr
        assert "the board answered HELLO: firmware 0.3.0" in r.stdout
        assert "the board's geometry: wheel_diameter_um 52000, wheel_base_um 110000, ticks_per_rev 1200" in r.stdout
        r = mpremote(vb.path, "ls", ":firmware")
        assert "robot.mpy" in r.stdout and "robot.py" not in r.stdout
    finally:
        vb.close()


def test_flash_refuses_a_board_out_of_space(tmp_path, standin):
    vb = VirtualBoard(f"{tmp_path / 'tiny.img'}:64", standin.port, tmp_path / "board.log")
    try:
        r = run_twinbot("flash", "--port", vb.path, timeout=120)
    finally:
        vb.close()
    assert r.returncode == 2
    assert "board out of space" in r.stderr and "KB free" in r.stderr


def test_flash_refuses_what_is_not_a_micropython_board(pty_pair):
    r = run_twinbot("flash", "--port", pty_pair.path, timeout=120)
    assert r.returncode == 2
    assert "does not answer as a MicroPython board" in r.stderr


def test_flash_refuses_a_missing_port():
    r = run_twinbot("flash", "--port", "/dev/ttyTWINBOT_NONE")
    assert r.returncode == 2 and "no such port" in r.stderr


def test_mpy_version_mismatch_is_named(board):
    info = probe(board.path)
    emitted = mpy_cross_version()
    check_mpy_compatible(info, emitted)  # the virtual board matches this mpy-cross
    older = BoardInfo(info.mpy - (1 << 8), info.platform, info.block_size, info.free_blocks)  # sub-version 3 -> 2
    with pytest.raises(CliError, match=r"\.mpy version mismatch: the board loads v6\.2, this mpy-cross emits v6\.3"):
        check_mpy_compatible(older, emitted)
    with pytest.raises(CliError, match="too old"):
        check_mpy_compatible(BoardInfo(-1, "rp2", 4096, 100), emitted)


def test_board_attached_to_the_twin_explores(tmp_path):
    """`twinbot board`'s default: the simulator, in real time, is the board's hardware."""
    from host_sim.physics.params import DEFAULT
    from host_sim.board.board_twin import BoardTwin
    from host_sim.physics.world import builtin_world

    twin = BoardTwin(builtin_world("paper_room"), DEFAULT)
    twin.start()
    flash = tmp_path / "flash"
    flash.mkdir()
    factory_image(flash)
    vb = VirtualBoard(str(flash), twin.port, tmp_path / "board.log")
    try:
        start = twin.pose
        link = SerialLink.open(vb.path)
        try:
            link.send(M.COMMAND, {"mode": M.MODE_AUTONOMOUS, "left": 0, "right": 0})
            frames = collect(link, 2.0)
        finally:
            link.close()
        end = twin.pose
    finally:
        vb.close()
        twin.stop()
    assert frames[-1].fields["mode"] == M.MODE_AUTONOMOUS
    assert frames[-1].fields["enc_l"] > 100 and frames[-1].fields["enc_r"] > 100  # the wheels turn
    assert ((end[0] - start[0]) ** 2 + (end[1] - start[1]) ** 2) ** 0.5 > 0.05  # and the twin moved
    ambient = frames[-1].fields["ir_amb"]
    assert all(100 < a < 300 for a in ambient)  # the room's ambient light, with noise


@pytest.mark.slow
def test_the_firmware_on_the_board_is_a_match_idle_and_with_the_cores_oversubscribed(tmp_path):
    """The virtual board, whose hardware is the nominal twin, is a control: the manoeuvre once (46 s) recorded
    through the real serial path by `twinbot serial --excite`, idle and with six busy processes on the cores
    (the board's loop then overruns: its rows come late), is diagnosed a match both times."""
    import os

    from host_sim.board.board_twin import BoardTwin
    from host_sim.diagnosis import diagnose
    from host_sim.physics.params import DEFAULT
    from host_sim.physics.world import builtin_world
    from host_sim.recordings.recording import load_recording

    verdicts = {}
    for busy in (0, 6):
        twin = BoardTwin(builtin_world("paper_room"), DEFAULT)
        twin.start()
        flash = tmp_path / f"flash_{busy}"
        flash.mkdir()
        factory_image(flash)
        vb = VirtualBoard(str(flash), twin.port, tmp_path / f"board_{busy}.log")
        loads = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(busy)]
        run = tmp_path / f"busy_{busy}.csv"
        try:
            out = run_twinbot("serial", vb.path, "--excite", "--record", str(run), "--duration", "46", "--quiet",
                              timeout=180)
        finally:
            for proc in loads:
                proc.kill()
                proc.wait()
            vb.close()
            twin.stop()
        assert out.returncode == 0, out.stderr
        rec = load_recording(run)
        late = float(np.mean(np.abs(np.diff(rec.t) - 0.04) > 5e-4))
        d = diagnose(rec, DEFAULT, None)
        verdicts[busy] = (d.verdict, f"{late:.0%} of rows late, {os.cpu_count()} cores", d.summary())
    assert all(v[0] == "match" for v in verdicts.values()), verdicts


def _break_to_the_repl(link) -> None:
    """`\\r\\x03` after a quiet cycle stops the firmware at the friendly REPL; wait until its frames stop."""
    deadline = time.monotonic() + 60  # a generous ceiling: a loaded machine starts MicroPython slowly
    while time.monotonic() < deadline and not any(f.msg_type == M.TELEMETRY for f in link.poll(0.1)):
        pass
    assert time.monotonic() < deadline, "the firmware runs"
    link.port.write(b"\r\x03")
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and any(f.msg_type == M.TELEMETRY for f in link.poll(0.3)):
        pass


def _repl_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if "MicroPython REPL" in line]


def _harness(port: str, *args: str) -> subprocess.Popen:
    # A suite started in the background (`nohup ... &`) hands its children SIGINT ignored, and Python then
    # keeps it ignored; _stop means a terminal's Ctrl-C, so the harness gets SIGINT's default.
    return subprocess.Popen([sys.executable, "-m", "tools.cli.main", "serial", port, "--quiet", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _stderr_until(proc: subprocess.Popen, text: str) -> str:
    """stderr's lines up to the first holding `text` (or all of it, when the harness ends without)."""
    seen = ""
    for line in proc.stderr:  # type: ignore[union-attr]
        seen += line
        if text in line:
            break
    return seen


def _stop(proc: subprocess.Popen) -> tuple[int, str]:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)  # as Ctrl-C: the harness prints its counts and ends with status 0
    _, err = proc.communicate(timeout=30)
    return proc.returncode, err


def test_serial_recognises_the_repl_and_offers_the_way_back(board):
    """The firmware stops at the REPL while `twinbot serial` watches: one line says so and names --restart."""
    import serial

    # The break goes through a handle of the test's own, opened before the harness locks the port.
    handle = serial.Serial(board.path, timeout=0)
    proc = _harness(board.path, "--duration", "120")
    try:
        line = proc.stdout.readline()  # type: ignore[union-attr]
        while line and "good frames 0 " in line:  # until the harness reads the firmware's frames
            line = proc.stdout.readline()  # type: ignore[union-attr]
        assert line.startswith("status: good frames"), line
        handle.write(b"\r\x03")
        err = _stderr_until(proc, "MicroPython REPL")
        status, rest = _stop(proc)
    finally:
        handle.close()
        if proc.poll() is None:
            proc.kill()
    lines = _repl_lines(err + rest)
    assert status == 0 and len(lines) == 1, err + rest
    assert lines[0].startswith(f"twinbot serial: the board on {board.path} is at its MicroPython REPL (prompt >>>)")
    assert "--restart" in lines[0] and "no frames for" not in err + rest, err + rest


def test_serial_restarts_a_board_at_its_repl(board):
    """A board left at its REPL says nothing; --restart asks it (Ctrl-B), recognises the prompt, soft-resets
    it with Ctrl-B, Ctrl-D, and the firmware's HELLO comes back, then its telemetry."""
    link = SerialLink.open(board.path)
    try:
        _break_to_the_repl(link)
    finally:
        link.close()
    proc = _harness(board.path, "--restart", "--duration", "120")
    try:
        err = _stderr_until(proc, "the firmware restarted")
        line = proc.stdout.readline()  # type: ignore[union-attr]
        while line and "good frames 0 " in line:
            line = proc.stdout.readline()  # type: ignore[union-attr]
        status, rest = _stop(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
    lines = [line for line in (err + rest).splitlines() if line.startswith("twinbot serial:")]
    assert status == 0, err + rest
    assert len(lines) == 2, err + rest
    assert lines[0].startswith(f"twinbot serial: the board on {board.path} is at its MicroPython REPL")
    assert "restarting it with Ctrl-B, Ctrl-D" in lines[0]
    assert lines[1].startswith(f"twinbot serial: the firmware restarted on {board.path}: HELLO, firmware ")
    assert line.startswith("status: good frames") and "good frames 0 " not in line, line


def test_the_repl_is_told_by_its_prompts():
    """The prompts a REPL ends with, and nothing a running firmware sends (its bytes end with a frame's 0x00)."""
    from tools.cli.serial_harness import ReplWatch

    class NoLink:
        on_bytes = None

    for tail, kind in [(b"MicroPython v1.24.1 on 2024-11-29; linux [GCC 12.2.0] version\r\n>>> ", "prompt >>>"),
                       (b"\r\n>>> raw REPL; CTRL-B to exit\r\n>", "raw REPL"), (b"OK\x04\x04>", "raw REPL"),
                       (b"\x05>>> \x00", None), (b"", None)]:
        watch = ReplWatch(NoLink(), "PORT", restart=False)  # type: ignore[arg-type]
        watch.received(tail)
        assert watch.prompt() == kind, tail


def test_serial_restart_without_a_main_py_is_one_line(board):
    """--restart on a board whose flash holds no main.py: the soft reset leaves it at the REPL, no HELLO
    comes, and the harness says so in one line with status 2."""
    link = SerialLink.open(board.path)
    try:
        _break_to_the_repl(link)
        link.port.write(b"import os; os.rename('main.py', 'main.off')\r")
        out = b""
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not out.endswith(b">>> "):
            out += link.port.read(link.port.in_waiting or 1)
    finally:
        link.close()
    r = run_twinbot("serial", board.path, "--restart", "--quiet", "--duration", "120", timeout=180)
    errors = [line for line in r.stderr.splitlines() if "error:" in line]
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert len(errors) == 1 and "no HELLO within 10 s of the soft reset" in errors[0], r.stderr
