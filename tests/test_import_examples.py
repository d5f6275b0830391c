"""The three MAP examples of docs/recordings.md ("Import"), each imported from a log in its robot's own columns."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from host_sim.recordings.recording import load_recording
from tools.cli.main import main

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "docs" / "examples"


def _import(tmp_path, log, name):
    return main(["import", str(log), "--map", str(EXAMPLES / f"{name}_map.json"),
                 "--robot", str(EXAMPLES / f"{name}_robot.json" if name != "pwm" else EXAMPLES / "pwm_robot.json"),
                 "--out", str(tmp_path / "rec.csv")])


def test_the_pwm_robots_example(tmp_path):
    log = tmp_path / "pwm.csv"
    rows = ["time,leftCommand,rightCommand,leftSpeed,rightSpeed"]
    rows += [f"{10 * k},{min(255, 5 * k)},{min(255, 5 * k)},{min(600.0, 12.0 * k)},{min(600.0, 12.0 * k)}"
             for k in range(120)]
    log.write_text("\n".join(rows) + "\n")
    assert main(["import", str(log), "--map", str(EXAMPLES / "pwm_robot_map.json"),
                 "--robot", str(EXAMPLES / "pwm_robot.json"), "--out", str(tmp_path / "rec.csv")]) == 0
    rec = load_recording(tmp_path / "rec.csv")
    robot = json.loads((EXAMPLES / "pwm_robot.json").read_text())
    assert rec.meta["drive"]["kind"] == "duty" and rec.meta["robot"]["pwm_decay"] == "coast"
    assert rec.cmd[-1].tolist() == [1.0, 1.0] and rec.vbat[0] == 7.9 and rec.n_ir == 0 and rec.pose is None
    turns = 300 / 60 * 0.5 + 600 / 60 * 0.69  # the ramp to 600 rpm over 0.5 s, then 0.69 s at 600 rpm
    assert rec.enc[-1, 0] == math.floor(turns * robot["ticks_per_rev"])


def test_the_speed_set_point_robots_example(tmp_path):
    log = tmp_path / "thymio.csv"
    prox = [f"prox{i}" for i in range(6)]
    rows = ["timestamp,target_left,target_right,speed_left,speed_right,battery," + ",".join(prox)
            + ",cam_x,cam_y,cam_theta"]
    for k in range(100):
        pose = ",," if k in (40, 41) else f"{500 + 1.0 * k},{300.0},{90.0}"
        rows.append(f"{0.01 * k:.2f},0.05,0.05,0.049,0.051,{4100 - k}," + ",".join(str(100 + i) for i in range(6))
                    + f",{pose}")
    log.write_text("\n".join(rows) + "\n")
    assert main(["import", str(log), "--map", str(EXAMPLES / "speed_setpoint_map.json"),
                 "--robot", str(EXAMPLES / "speed_setpoint_robot.json"), "--out", str(tmp_path / "rec.csv")]) == 0
    rec = load_recording(tmp_path / "rec.csv")
    assert rec.meta["drive"]["unit"] == "rad/s" and rec.cmd[0, 0] == pytest.approx(0.05 / 0.0215)
    assert rec.n_ir == 6 == len(rec.meta["robot"]["ir_bearings"]) and not rec.ambient_recorded and rec.vbat[0] == 4.1
    assert rec.pose_rows.sum() == 98 and rec.pose[0].tolist() == pytest.approx([0.5, 0.3, math.pi / 2])


def _firmware_log(rec, path):
    """The recording's rows as the firmware's TELEMETRY fields, in their units (mA, mV, mm/s, um, 2^-30 turn)."""
    names = ["tick_ms", "i_ref_l_ma", "i_ref_r_ma", "enc_l", "enc_r", *(f"ir_on_{i}" for i in range(8)),
             *(f"ir_amb_{i}" for i in range(8)), "vbat_mv", "emitter_pct", "mode", "sp_l", "sp_r", "odo_x", "odo_y",
             "odo_heading"]
    lines = [",".join(names)]
    for k in range(len(rec)):
        fw = rec.firmware[k]
        heading = round(fw[5] / (2 * math.pi) * (1 << 30)) % (1 << 30)
        cells = [round(rec.t[k] * 1000), *(round(c * 1000) for c in rec.cmd[k]), *rec.enc[k], *rec.ir_on[k],
                 *rec.ir_amb[k], round(rec.vbat[k] * 1000), round(rec.emitter[k]), int(fw[0]),
                 *(round(v * 1000) for v in fw[1:3]), *(round(v * 1e6) for v in fw[3:5]), heading]
        lines.append(",".join(str(c) for c in cells))
    path.write_text("\n".join(lines) + "\n")


def test_this_projects_firmware_log_imports_as_the_recording_it_came_from(tmp_path):
    env = {"PYTHONPATH": str(REPO)}
    sim = subprocess.run([sys.executable, "-m", "tools.cli.main", "sim", "--world", "arena", "--duration", "4",
                          "--record", str(tmp_path / "sim.csv")], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert sim.returncode == 0, sim.stderr
    original = load_recording(tmp_path / "sim.csv")
    _firmware_log(original, tmp_path / "firmware.csv")
    assert main(["import", str(tmp_path / "firmware.csv"), "--map", str(EXAMPLES / "firmware_map.json"),
                 "--robot", str(EXAMPLES / "firmware_robot.json"), "--out", str(tmp_path / "rec.csv")]) == 0
    rec = load_recording(tmp_path / "rec.csv")
    np.testing.assert_allclose(rec.t, original.t, atol=5e-4)  # the firmware's clock counts whole ms
    for name in ("cmd", "enc", "ir_on", "ir_amb", "vbat", "emitter"):
        np.testing.assert_array_equal(getattr(rec, name), getattr(original, name), err_msg=name)
    np.testing.assert_allclose(rec.firmware, original.firmware, atol=1e-6)
    assert rec.pose is None and rec.meta["world"] is None
    # Encoders alone, no world: replay and the plot take it as it is.
    for args in (["replay", str(tmp_path / "rec.csv")], ["plot", "recording", str(tmp_path / "rec.csv")]):
        run = subprocess.run([sys.executable, "-m", "tools.cli.main", *args], cwd=tmp_path, env=env,
                             capture_output=True, text=True)
        assert run.returncode == 0, run.stderr
    assert "in an empty world" in run.stdout or (tmp_path / "rec.png").exists()
