"""The identification manoeuvre: its schedule, its guards, in the simulator and through the harness."""
from __future__ import annotations

import os
import select
import subprocess
import time

import numpy as np

from host_sim.loops.excitation import CYCLE_S, SEGMENTS, Manoeuvre, schedule
from host_sim.recordings.recording import load_recording
from protocol import messages as M
from protocol.framing import FrameDecoder, FrameEncoder
from tests.helpers import REPO, run_twinbot, twinbot_cmd


def test_the_schedule_asks_for_each_kind_of_motion():
    names = [schedule(t)[0] for t in np.arange(0, CYCLE_S, 0.04)]
    assert [n for n, _d, _f in SEGMENTS] == list(dict.fromkeys(names))
    commands = np.array([schedule(t)[1:] for t in np.arange(0, CYCLE_S, 0.04)])
    assert (commands > 0).any() and (commands < 0).any()  # forwards and backwards
    assert ((commands[:, 0] * commands[:, 1]) < 0).any()  # spins in place
    assert np.abs(commands).max() >= 300 and 0 < np.abs(commands[commands != 0]).min() <= 30  # bursts and creep


def test_a_wall_ahead_turns_the_command_into_a_spin_and_far_away_it_heads_home():
    m = Manoeuvre()
    t_forward = 0.5  # creeping forwards
    clear = [10] * 8
    assert m.command(t_forward, clear) == (25, 25)
    wall_ahead = [10] * 8
    wall_ahead[0] = 900
    assert m.command(t_forward, wall_ahead) == (-100, 100) and m.guarded == 1
    far_east_facing_away = (0.8, 0.0, 0.0)  # the start lies behind: turn around first
    left, right = m.command(t_forward, clear, far_east_facing_away)
    assert left == -right != 0 and m.homing == 1
    far_east_facing_home = (0.8, 0.0, np.pi)
    left, right = m.command(t_forward, clear, far_east_facing_home)
    assert left > 0 and right > 0


def test_sim_excite_records_a_manoeuvre_the_diagnosis_reads(tmp_path):
    path = tmp_path / "excite.csv"
    r = run_twinbot("sim", "--excite", "--world", "arena", "--duration", "30", "--record", str(path), timeout=120)
    assert r.returncode == 0, r.stderr
    rec = load_recording(path)
    assert rec.meta["excitation"] == "manoeuvre"
    speeds = np.diff(rec.enc, axis=0)
    assert (speeds > 0).any() and (speeds < 0).any() and (speeds[:, 0] * speeds[:, 1] < 0).any()
    d = run_twinbot("diagnose", str(path), "--quiet", timeout=120)
    assert d.returncode == 0 and ": match" in d.stdout, d.stdout + d.stderr


def telemetry(enc: FrameEncoder, k: int, front: int) -> bytes:
    """A TELEMETRY frame with every field of this protocol's layout; S1 sees `front` reflected counts."""
    fields = next(f for t, _n, f in M.LAYOUTS if t == M.TELEMETRY)
    values: dict[str, object] = {name: ([0] * count if count > 1 else 0) for name, _code, count in fields}
    values.update({"tick_ms": 40 * k, "mode": M.MODE_HOST, "ir_on": [front + 5] + [5] * 7, "ir_amb": [5] * 8,
                   "vbat_mv": 7400})
    return enc.encode(M.TELEMETRY, M.pack_payload(M.TELEMETRY, values))  # type: ignore[arg-type]


def test_serial_excite_commands_host_mode_and_obeys_the_robots_ir(pty_pair):
    proc = subprocess.Popen(twinbot_cmd("serial", pty_pair.path, "--excite", "--duration", "2.5", "--quiet"),
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    received, enc = b"", FrameEncoder()
    start = time.monotonic()
    k = 0
    while proc.poll() is None and time.monotonic() - start < 20:
        ready, _, _ = select.select([pty_pair.master], [], [], 0.04)
        if ready:
            received += os.read(pty_pair.master, 4096)
        wall = time.monotonic() - start > 1.2  # a wall appears in front of the robot
        pty_pair.write(telemetry(enc, k, 900 if wall else 0))  # the robot's 25 Hz report
        k += 1
    proc.communicate(timeout=10)
    assert proc.returncode == 0
    commands = [M.unpack_payload(t, p) for t, _s, p in FrameDecoder().decode_all(received) if t == M.COMMAND]
    assert len(commands) >= 30 and all(c["mode"] == M.MODE_HOST for c in commands)  # 25 Hz
    assert commands[0]["left"] == commands[0]["right"] == 25  # it starts by creeping forwards
    pairs = [(c["left"], c["right"]) for c in commands]
    assert (-100, 100) in pairs  # the wall ahead while creeping forwards: spin away
    assert pairs[-1] == (-25, -25)  # creeping backwards after 2 s: the wall in front is no obstacle
