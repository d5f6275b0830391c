"""`twinbot serial`: the protocol test harness over real ports.

Pseudo-terminals stand where a robot's USB serial port would be; pyserial
opens them as it opens /dev/ttyACM0.  loop:// is pyserial's own loop-back.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import numpy as np
import pytest
import serial

from protocol import messages as M
from protocol.framing import FrameDecoder, FrameEncoder
from tests.helpers import REPO, run_twinbot, twinbot_cmd
from host_sim.board.frame_log import FrameLogError, read_frame_log


def telemetry_frame(enc: FrameEncoder, k: int) -> bytes:
    return enc.encode(M.TELEMETRY, M.pack_payload(M.TELEMETRY, {
        "tick_ms": 40 * k, "mode": M.MODE_HOST, "flags": M.FLAG_WATCHDOG if k == 3 else 0,
        "enc_l": k, "enc_r": -k, "ir_on": [k] * 8, "ir_amb": [1] * 8,
        "i_ref_l_ma": 10, "i_ref_r_ma": -10, "vbat_mv": 7400, "sp_l": 0, "sp_r": 0,
        "odo_x": 0, "odo_y": 0, "odo_heading": 0, "emitter_pct": 60,
    }))


def test_loop_url_shows_frames_sent_to_itself(tmp_path):
    """On loop:// every frame sent comes back decoded, and the counts add up."""
    log = tmp_path / "loop.jsonl"
    r = run_twinbot("serial", "loop://", "--hello", "--param-set", "emitter_pct=80", "--param-get", "rule_set",
                    "--command", "host", "120", "-40", "--rate", "0", "--count", "4", "--duration", "5",
                    "--record", str(log))
    assert r.returncode == 0, r.stderr
    rx = [line for line in r.stdout.splitlines() if " rx #" in line]
    assert [line.split()[3] for line in rx] == ["HELLO", "PARAM_SET", "PARAM_GET", "COMMAND"]
    assert "left=120mm/s right=-40mm/s" in rx[3]
    assert "good frames 4 | CRC errors 0" in r.stdout
    records = read_frame_log(log)
    frames = [rec for rec in records if rec["kind"] == "frame"]
    assert [(f["dir"], f["type"]) for f in frames if f["dir"] == "rx"] == [
        ("rx", "HELLO"), ("rx", "PARAM_SET"), ("rx", "PARAM_GET"), ("rx", "COMMAND")]
    assert sum(f["dir"] == "tx" for f in frames) == 4
    assert records[-1]["kind"] == "stats" and records[-1]["decoder"]["frames"] == 4


def test_pty_decodes_counts_crc_errors_and_sequence_gaps(pty_pair, tmp_path):
    """Telemetry from a 'robot' on a pseudo-terminal: corrupted and missing frames are counted."""
    log = tmp_path / "pty.jsonl"
    proc = subprocess.Popen(twinbot_cmd("serial", pty_pair.path, "--count", "7", "--duration", "20",
                                        "--record", str(log)),
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)  # let the harness open the port
    enc = FrameEncoder()
    stream = b""
    for k in range(10):
        frame = telemetry_frame(enc, k)
        if k == 4:
            frame = frame[:20] + bytes([frame[20] ^ 0x10]) + frame[21:]  # bit flip: CRC error
        if k in (6, 7):
            continue  # lost on the wire: a sequence gap of 2
        stream += frame
    stream = b"\x17\x99garbage" + b"\x00" + stream  # line noise before the first frame
    for i in range(0, len(stream), 7):  # arrives in odd-sized pieces
        pty_pair.write(stream[i:i + 7])
        time.sleep(0.002)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert out.count(" rx #") == 7
    assert "flags=WATCHDOG" in out
    assert "CRC errors 1" in out
    assert "sequence gaps 2 (3 frames lost)" in out  # #4 (corrupt) and #6, #7 (dropped)
    frames = [rec for rec in read_frame_log(log) if rec["kind"] == "frame"]
    assert [f["seq"] for f in frames] == [0, 1, 2, 3, 5, 8, 9]


def test_pty_sends_commands_at_the_requested_rate(pty_pair):
    """--command is repeated at --rate, as a robot's watchdog needs."""
    proc = subprocess.Popen(twinbot_cmd("serial", pty_pair.path, "--command", "teleop", "200", "180",
                                        "--rate", "20", "--duration", "1.5", "--quiet"),
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    received = b""
    deadline = time.monotonic() + 15
    while proc.poll() is None and time.monotonic() < deadline:
        received += pty_pair.read_available(0.1)
    received += pty_pair.read_available(0.1)
    proc.communicate(timeout=10)
    assert proc.returncode == 0
    dec = FrameDecoder()
    frames = dec.decode_all(received)
    assert dec.errors == 0 and dec.seq_gaps == 0
    commands = [M.unpack_payload(t, p) for t, _s, p in frames if t == M.COMMAND]
    assert 15 <= len(commands) <= 32  # 20 Hz for 1.5 s, on a busy machine
    assert commands[0] == {"mode": M.MODE_TELEOP, "left": 200, "right": 180}


def _wait_for_frame(pty_pair, msg_type: int, timeout: float) -> bool:
    """Read the harness's side of the pty until a frame of msg_type comes (False at the timeout)."""
    dec = FrameDecoder()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if any(t == msg_type for t, _s, _p in dec.decode_all(pty_pair.read_available(0.2))):
            return True
    return False


def test_recording_survives_kill(pty_pair, tmp_path):
    """Frames recorded before a SIGKILL are all in the log, each line complete."""
    log = tmp_path / "killed.jsonl"
    proc = subprocess.Popen(twinbot_cmd("serial", pty_pair.path, "--hello", "--record", str(log), "--quiet"),
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        # Its HELLO says the harness has the port open: what was written before, its opening flushed.
        # The ceilings are generous (a loaded machine), the waits end on their conditions.
        assert _wait_for_frame(pty_pair, M.HELLO, 60), "the harness never opened the port"
        enc = FrameEncoder()
        for k in range(50):
            pty_pair.write(telemetry_frame(enc, k))
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if log.read_text().count('"dir":"rx"') >= 50:
                break
            time.sleep(0.05)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    frames = [rec for rec in read_frame_log(log) if rec["kind"] == "frame"]
    assert [(f["dir"], f["seq"]) for f in frames] == [("tx", 0)] + [("rx", k) for k in range(50)]


def test_missing_port_is_a_clear_error():
    r = run_twinbot("serial", "/dev/ttyTWINBOT_NO_SUCH_PORT", "--duration", "1")
    assert r.returncode == 2
    assert "no such port '/dev/ttyTWINBOT_NO_SUCH_PORT'" in r.stderr
    assert "Traceback" not in r.stderr


def test_busy_port_is_a_clear_error(pty_pair):
    holder = serial.Serial(pty_pair.path, exclusive=True)
    try:
        r = run_twinbot("serial", pty_pair.path, "--duration", "1")
    finally:
        holder.close()
    assert r.returncode == 2
    assert "is busy" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("args, message", [
    (["--param-set", "emitter_pct=101"], "emitter_pct must be in 0..100"),
    (["--param-set", "no_such=1"], "unknown parameter 'no_such'"),
    (["--param-get", "bogus"], "unknown parameter 'bogus'"),
    (["--command", "fly", "1", "2"], "unknown mode 'fly'"),
    (["--command", "host", "1.5", "2"], "must be integers"),
    (["--command", "host", "40000", "2"], "out of range"),
])
def test_bad_arguments_say_what_is_wrong(args, message):
    r = run_twinbot("serial", "loop://", *args, "--duration", "0.1")
    assert r.returncode == 2
    assert message in r.stderr


def test_unknown_url_scheme():
    r = run_twinbot("serial", "bogus://x", "--duration", "0.1")
    assert r.returncode == 2 and "cannot open 'bogus://x'" in r.stderr


def test_frame_log_reader_names_the_broken_line(tmp_path):
    """A damaged frame log is refused with file:line, never half-read."""
    log = tmp_path / "ok.jsonl"
    assert run_twinbot("serial", "loop://", "--hello", "--count", "1", "--duration", "5",
                       "--record", str(log)).returncode == 0
    lines = log.read_text().splitlines()
    rec = json.loads(lines[1])
    rec["frame"] = rec["frame"][:8] + ("0" if rec["frame"][8] != "0" else "1") + rec["frame"][9:]
    bad = tmp_path / "bad.jsonl"
    bad.write_text("\n".join([lines[0], json.dumps(rec), *lines[2:]]) + "\n")
    with pytest.raises(FrameLogError, match=r"bad.jsonl:2: 'frame' bytes"):
        read_frame_log(bad)
    cut = tmp_path / "cut.jsonl"
    cut.write_text(log.read_text()[:-5])
    with pytest.raises(FrameLogError, match=r"cut.jsonl:\d+: last line is cut short"):
        read_frame_log(cut)
    other = tmp_path / "other.jsonl"
    other.write_text('{"hello": 1}\n')
    with pytest.raises(FrameLogError, match="other.jsonl:1: expected a JSON object with a 'kind'"):
        read_frame_log(other)


def test_demo_runs_and_catches_the_injected_faults(tmp_path):
    r = run_twinbot("demo", "--loopback", "--record", str(tmp_path / "demo.jsonl"))
    assert r.returncode == 0, r.stderr
    assert "CRC errors 1" in r.stdout and "sequence gaps 2 (2 frames lost)" in r.stdout
    assert "re-read and verified" in r.stdout


def test_record_csv_writes_the_recording_format(pty_pair, tmp_path):
    """`--record FILE.csv`: the robot's TELEMETRY as a recording the simulator's tools read."""
    from host_sim.recordings.recording import load_recording

    path = tmp_path / "robot.csv"
    proc = subprocess.Popen(twinbot_cmd("serial", pty_pair.path, "--count", "6", "--duration", "20",
                                        "--record", str(path), "--quiet"),
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)
    enc = FrameEncoder()
    for k in range(6):
        pty_pair.write(telemetry_frame(enc, k))
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    rec = load_recording(path)
    assert rec.meta["source"] == "robot" and rec.meta["complete"] and rec.pose is None
    np.testing.assert_allclose(rec.t, [0.04 * k for k in range(6)])
    assert rec.enc[:, 0].tolist() == list(range(6)) and rec.cmd[0].tolist() == [0.01, -0.01]
    assert rec.ir_on[3].tolist() == [3] * 8 and rec.vbat[0] == 7.4


def _poll_until(link, want: int, timeout: float = 60.0) -> list:
    got: list = []
    deadline = time.monotonic() + timeout
    while len(got) < want and time.monotonic() < deadline:
        got += link.poll(0.02)
    return got


def test_host_abandons_a_stale_partial_frame_on_a_pty(pty_pair):
    """A sender that dies mid-frame: after IDLE_TIMEOUT_S of silence the host drops the half frame
    (counted in 'abandoned'), so its tail cannot glue onto what comes next; a frame that only
    pauses for less than that still arrives whole."""
    from host_sim.board.serial_link import IDLE_TIMEOUT_S, SerialLink

    link = SerialLink.open(pty_pair.path)
    # The link's clock is the test's: a loaded machine cannot stretch a short pause past the timeout,
    # and each pause lasts exactly what it says between bytes that have all been read.
    clock = [0.0]
    link.now = lambda: clock[0]  # type: ignore[method-assign]
    fed = bytearray()
    feed = link.feed

    def counting_feed(data: bytes) -> list:
        fed.extend(data)
        return feed(data)

    link.feed = counting_feed  # type: ignore[method-assign]
    try:
        enc = FrameEncoder()
        frame = telemetry_frame(enc, 1)
        # A pause shorter than the timeout: the frame arrives whole.
        pty_pair.write(frame[:30])
        assert _read_until(link, fed, 30) == [] and link.decoder.partial
        clock[0] += IDLE_TIMEOUT_S / 4
        pty_pair.write(frame[30:])
        got = _poll_until(link, 1)
        assert [f.seq for f in got] == [0] and link.decoder.abandoned == 0
        # A dead sender: half a frame, silence, then a new sender's bytes without a leading 0x00.
        stale = telemetry_frame(enc, 2)
        pty_pair.write(stale[:30])
        assert _read_until(link, fed, len(frame) + 30) == [] and link.decoder.partial
        clock[0] += IDLE_TIMEOUT_S * 2
        fresh = telemetry_frame(enc, 3)[1:]  # no leading 0x00: only the timeout separates it
        pty_pair.write(fresh)
        got = _poll_until(link, 1)
        assert link.decoder.abandoned == 1
        assert [f.seq for f in got] == [2]  # telemetry #3 carries seq 2 (#2 never completed)
        assert got[0].fields["tick_ms"] == 120
    finally:
        link.close()


def _read_until(link, fed: bytearray, total: int, timeout: float = 60.0) -> list:
    """Poll until `total` bytes have been read in all (the pty may hand them over late, or in pieces)."""
    got: list = []
    deadline = time.monotonic() + timeout
    while len(fed) < total and time.monotonic() < deadline:
        got += link.poll(0.02)
    assert len(fed) == total, (len(fed), total)
    return got


def test_predict_says_where_the_robot_is_now_from_late_reports(pty_pair):
    """--predict: the ghost advances the last reported pose through the commands sent since."""
    proc = subprocess.Popen(twinbot_cmd("serial", pty_pair.path, "--predict", "--command", "host", "200", "200",
                                        "--rate", "20", "--duration", "2.5", "--quiet"),
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    enc = FrameEncoder()
    fields = next(f for t, _n, f in M.LAYOUTS if t == M.TELEMETRY)
    time.sleep(0.5)
    for k in range(40):  # a robot reporting at 25 Hz, standing at the origin: its reports are stale
        values = {name: ([0] * count if count > 1 else 0) for name, _code, count in fields}
        values.update({"tick_ms": 40 * k, "mode": M.MODE_HOST, "vbat_mv": 7400, "ir_on": [5] * 8, "ir_amb": [5] * 8})
        pty_pair.write(enc.encode(M.TELEMETRY, M.pack_payload(M.TELEMETRY, values)))
        pty_pair.read_available(0.04)
    out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    lines = [line for line in out.splitlines() if line.startswith("predict:")]
    assert len(lines) >= 2
    assert "last report (+0.000, +0.000) m" in lines[-1]  # what the late reports say
    now_x = float(lines[-1].split("now (")[1].split(",")[0])
    assert now_x > 0.0  # the ghost drove on at the commanded 200 mm/s from the last report
