"""`twinbot import`: a robot's own log, in its columns and units, as a recording (docs/recordings.md, "Import")."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from host_sim.recordings.recording import RecordingError, load_recording
from tools.cli.main import main

PWM_MAP = {"time": {"column": "time", "unit": "ms"},
           "command": {"kind": "duty", "left": "leftCommand", "right": "rightCommand", "full_scale": 255,
                       "decay": "coast"},
           "wheel_speed": {"left": "leftSpeed", "right": "rightSpeed", "unit": "rpm"},
           "battery": {"value": 7.9, "unit": "V"},
           "pose": {"x": "x", "y": "y", "phi": "heading", "unit": "mm", "angle_unit": "deg"}}
PWM_ROBOT = {"ticks_per_rev": 358.32, "wheel_radius": 0.016}


def _pwm_log(path, rows=100):
    """Duty 0 then 102/255 forward on the left, back on the right; 300 rpm; a tracker that misses every 10th row."""
    lines = [" time , leftCommand,rightCommand, leftSpeed ,rightSpeed,x,y,heading"]
    for k in range(rows):
        duty = 102 if k >= 10 else 0
        rpm = 300.0 if k >= 10 else 0.0
        pose = ",," if k % 10 == 3 else f"{2.0 * k},{-1.0 * k},{0.5 * k}"
        lines.append(f"{10 * k},{duty},{-duty},{rpm},{-rpm},{pose}")
    path.write_text("\n".join(lines) + "\n")
    return path


def _files(tmp_path, mapping, robot, log_writer=_pwm_log):
    log = log_writer(tmp_path / "log.csv")
    (tmp_path / "map.json").write_text(json.dumps(mapping))
    (tmp_path / "robot.json").write_text(json.dumps(robot))
    return ["import", str(log), "--map", str(tmp_path / "map.json"), "--robot", str(tmp_path / "robot.json"),
            "--out", str(tmp_path / "rec.csv")]


def test_a_pwm_log_imports_in_the_drives_units(tmp_path, capsys):
    assert main(_files(tmp_path, PWM_MAP, PWM_ROBOT)) == 0
    assert "100 rows" in capsys.readouterr().out
    rec = load_recording(tmp_path / "rec.csv")
    assert rec.meta["drive"] == {"kind": "duty", "unit": "fraction", "source_unit": "counts", "full_scale": 255.0}
    assert rec.meta["robot"] == {**PWM_ROBOT, "drive": "duty", "pwm_decay": "coast"}
    assert rec.t[:3].tolist() == [0.0, 0.01, 0.02] and rec.sample_period == 0.01
    assert rec.cmd[50].tolist() == pytest.approx([0.4, -0.4])
    assert rec.n_ir == 0 and rec.firmware is None and rec.vbat[0] == 7.9
    # 300 rpm for 0.9 s (the speed ramps between rows 9 and 10 by trapezoids): 4.475 turns of 358.32 counts
    turns = 300 / 60 * (0.89 + 0.005)
    assert rec.enc[-1, 0] == math.floor(turns * 358.32) and rec.enc[-1, 1] == math.floor(-turns * 358.32)


def test_a_tracker_with_empty_rows_loads_and_those_rows_have_no_pose(tmp_path):
    assert main(_files(tmp_path, PWM_MAP, PWM_ROBOT)) == 0
    rec = load_recording(tmp_path / "rec.csv")
    assert rec.pose is not None
    assert rec.pose_rows.sum() == 90 and not rec.pose_rows[3] and rec.pose_rows[4]
    assert rec.pose[4].tolist() == pytest.approx([0.008, -0.004, math.radians(2.0)])


def _robot_log(path, rows=60):
    """A current-driven robot's log: mA, encoder counts, six IR pairs with ambient, the battery in mV."""
    ir = [f"p{i}" for i in range(6)] + [f"a{i}" for i in range(6)]
    lines = ["t_us,il,ir,el,er," + ",".join(ir) + ",vbat"]
    for k in range(rows):
        lines.append(f"{40000 * k},{120},{-40},{3 * k},{-k}," + ",".join(str(300 + i) for i in range(6)) + ","
                     + ",".join("100" for _ in range(6)) + f",{7400 - k}")
    path.write_text("\n".join(lines) + "\n")
    return path


ROBOT_MAP = {"time": {"column": "t_us", "unit": "us"},
             "command": {"kind": "current", "left": "il", "right": "ir", "unit": "mA"},
             "encoder": {"left": "el", "right": "er"},
             "battery": {"column": "vbat", "unit": "mV"},
             "ir": {"on": [f"p{i}" for i in range(6)], "ambient": [f"a{i}" for i in range(6)]}}


def test_six_ir_sensors_and_a_battery_in_mv(tmp_path):
    assert main(_files(tmp_path, ROBOT_MAP, {}, _robot_log)) == 0
    rec = load_recording(tmp_path / "rec.csv")
    assert rec.n_ir == 6 and rec.ir_on[0].tolist() == [300, 301, 302, 303, 304, 305]
    assert rec.ambient_recorded and rec.ir_amb[5].tolist() == [100] * 6
    assert rec.cmd[0].tolist() == [0.12, -0.04] and rec.enc[10].tolist() == [30, -10]
    assert rec.vbat[1] == 7.399 and rec.battery_recorded and rec.pose is None
    assert "drive" not in rec.meta["robot"] and rec.meta["drive"]["kind"] == "current"


def test_without_ambient_readings_the_group_is_empty(tmp_path):
    mapping = {**ROBOT_MAP, "ir": {"on": ["p0", "p1"]}}
    mapping.pop("battery")
    assert main(_files(tmp_path, mapping, {}, _robot_log)) == 0
    rec = load_recording(tmp_path / "rec.csv")
    assert rec.n_ir == 2 and not rec.ambient_recorded and not rec.battery_recorded


def test_a_speed_set_point_log_in_m_per_s(tmp_path):
    mapping = {"time": {"column": "time", "unit": "ms"},
               "command": {"kind": "wheel_speed", "left": "leftCommand", "right": "rightCommand", "unit": "rpm"},
               "wheel_speed": {"left": "leftSpeed", "right": "rightSpeed", "unit": "m/s"}}
    assert main(_files(tmp_path, mapping, {"drive": "wheel_speed", "speed_kp": 0.5, "speed_ki": 4.0,
                                           "speed_loop_period": 0.01})) == 0
    rec = load_recording(tmp_path / "rec.csv")
    assert rec.meta["drive"]["unit"] == "rad/s" and rec.meta["drive"]["source_unit"] == "rpm"
    assert rec.cmd[50, 0] == pytest.approx(102 * 2 * math.pi / 60)
    assert rec.meta["robot"]["speed_kp"] == 0.5


@pytest.mark.parametrize("change, message", [
    (lambda m, r: m["command"].update(kind="pwm"), r"map.json: command.kind: 'pwm' is not known"),
    (lambda m, r: m["command"].pop("full_scale"), r"map.json: command.full_scale: a positive number"),
    (lambda m, r: m["command"].update(full_scale=50), r"log.csv:12: command 102/-102 is beyond full_scale 50"),
    (lambda m, r: m["time"].update(unit="minutes"), r"map.json: time.unit: 'minutes' is not known"),
    (lambda m, r: m["wheel_speed"].update(left="speedL"), r"map.json: wheel_speed.left: no column 'speedL'"),
    (lambda m, r: m.update(encoder={"left": "x", "right": "y"}), r"map.json: the wheels: .*not both"),
    (lambda m, r: m.update(imu={}), r"map.json: unknown entry 'imu'"),
    (lambda m, r: m["pose"].update(angle_unit="grad"), r"map.json: pose.angle_unit"),
    (lambda m, r: r.update(drive="voltage"), r"command.kind: 'duty', but the robot file says drive 'voltage'"),
    (lambda m, r: r.update(pwm_decay="brake"), r"'coast', but the robot file says pwm_decay 'brake'"),
    (lambda m, r: r.update(ticks_per_rev=0.5), r"robot.json: 'ticks_per_rev' must be in 1..1e\+06"),
    (lambda m, r: r.update(pwm_decay="slow"), r"robot.json: 'pwm_decay' must be one of coast, brake"),
])
def test_a_bad_map_or_robot_is_one_line_and_nothing_is_written(tmp_path, capsys, change, message):
    mapping, robot = json.loads(json.dumps(PWM_MAP)), dict(PWM_ROBOT)
    change(mapping, robot)
    assert main(_files(tmp_path, mapping, robot)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("twinbot import: error: ")
    assert __import__("re").search(message, err), err
    assert not (tmp_path / "rec.csv").exists() and not (tmp_path / "rec.csv.json").exists()


@pytest.mark.parametrize("edit, message", [
    (lambda lines: lines.__setitem__(5, lines[5].replace("0,0,0.0", "0,x,0.0", 1)), r"log.csv:6: column 'rightCommand': 'x'"),
    (lambda lines: lines.__setitem__(7, lines[7] + ",1"), r"log.csv:8: 9 cells, the header names 8"),
    (lambda lines: lines.__setitem__(9, "80,0,0,0.0,0.0,16.0,,4.0"), r"log.csv:10: the pose's x, y and phi must be all"),
    (lambda lines: lines.__setitem__(0, lines[0].replace("rightSpeed", "leftSpeed")), r"log.csv:1: column 'leftSpeed' is named twice"),
])
def test_a_bad_log_names_its_line_and_column(tmp_path, capsys, edit, message):
    args = _files(tmp_path, PWM_MAP, PWM_ROBOT)
    lines = (tmp_path / "log.csv").read_text().splitlines()
    edit(lines)
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and __import__("re").search(message, err), err
    assert not (tmp_path / "rec.csv").exists()


def test_a_drive_block_the_robot_disagrees_with_is_refused_on_loading(tmp_path):
    assert main(_files(tmp_path, PWM_MAP, PWM_ROBOT)) == 0
    side = tmp_path / "rec.csv.json"
    meta = json.loads(side.read_text())
    meta["robot"]["drive"] = "voltage"
    side.write_text(json.dumps(meta))
    with pytest.raises(RecordingError, match=r"rec.csv.json: the robot's parameters say drive 'voltage', the drive "
                                             r"block says 'duty'"):
        load_recording(tmp_path / "rec.csv")


def test_counts_per_turn_need_not_be_whole():
    from host_sim.physics import motors
    from host_sim.physics.params import params_from_dict

    p = params_from_dict({"ticks_per_rev": 29.86 * 12})
    assert motors.encoder_ticks(2 * math.pi * 10, p) == math.floor(10 * 358.32)
    assert np.isclose(motors.encoder_angle(358, p), 358.5 * 2 * math.pi / 358.32)


def _robot_recording(tmp_path, capsys):
    """A simulator run, then its tracker pose and world taken away: a robot's recording of its encoders."""
    assert main(["sim", "--world", "arena", "--duration", "3", "--record", str(tmp_path / "run.csv")]) == 0
    capsys.readouterr()
    lines = (tmp_path / "run.csv").read_text().splitlines()
    (tmp_path / "robot.csv").write_text("\n".join([lines[0]] + [r.rsplit(",", 3)[0] + ",,," for r in lines[1:]]) + "\n")
    meta = json.loads((tmp_path / "run.csv.json").read_text())
    meta.update(source="robot", world=None)
    (tmp_path / "robot.csv.json").write_text(json.dumps(meta))
    return tmp_path / "robot.csv"


def test_replay_and_plot_take_the_encoders_alone_without_a_world(tmp_path, capsys):
    path = _robot_recording(tmp_path, capsys)
    assert main(["replay", str(path)]) == 0
    out = capsys.readouterr().out
    assert "in an empty world (no world known: the drive alone)" in out and "encoders at the end" in out
    assert "pose at the end" not in out
    assert main(["plot", "recording", str(path), "--png", str(tmp_path / "r.png")]) == 0
    assert (tmp_path / "r.png").stat().st_size > 10_000


def test_the_diagnosis_says_what_it_cannot_judge():
    from host_sim.diagnosis.report import check_data, without_gapped_pose
    from host_sim.physics.params import RobotParams
    from host_sim.physics.world import builtin_world
    from host_sim.recordings.recording import Recording

    n = 400
    rec = Recording(t=np.arange(n) * 0.04, cmd=np.zeros((n, 2)), enc=np.zeros((n, 2), np.int64),
                    ir_on=np.zeros((n, 6), np.int64), ir_amb=np.zeros((n, 6), np.int64), vbat=np.full(n, np.nan),
                    pose=np.zeros((n, 3)), meta={"sample_period": 0.04})
    notes = check_data(rec, builtin_world("arena"))
    assert any("6 IR sensors are not the twin's ring of 8" in s for s in notes)
    assert any("no battery voltage recorded" in s for s in notes)
    assert not any("set-points" in s for s in notes)  # a current drive's commands show the drive's load
    speed_robot = RobotParams(drive="wheel_speed")
    assert any("a match says little of it" in s for s in check_data(rec, builtin_world("arena"), speed_robot))
    rec.pose[7] = np.nan
    judged, gap = without_gapped_pose(rec)
    assert judged.pose is None and gap == ["the tracker pose is missing in 1 of 400 rows: judged without the tracker"]


SIX = [0.0, 1.0, 2.0, math.pi, -2.0, -1.0]  # rad: a ring of six pairs, not the firmware's eight


def test_a_robot_file_gives_its_ring_and_its_pairs_lists_follow():
    from host_sim.physics.params import ParamsError, params_from_dict

    p = params_from_dict({"ir_bearings": SIX})
    assert p.ir_bearings == tuple(SIX) and p.ir_gain_scale == (1.0,) * 6 and p.ambient_leakage == (0.0,) * 6
    assert params_from_dict(p.to_json()) == p
    with pytest.raises(ParamsError, match="'ir_offset' must be a list of 6 numbers, one per IR pair"):
        params_from_dict({"ir_bearings": SIX, "ir_offset": [0.0] * 8})
    with pytest.raises(ParamsError, match="'ir_bearings' must be a list of 1..64"):
        params_from_dict({"ir_bearings": []})


def test_a_ring_of_six_replays_exactly_and_cannot_run_the_firmware(tmp_path, capsys):
    from host_sim.physics.params import params_from_dict
    from host_sim.physics.world import world_from_dict
    from host_sim.recordings.recording import RecordingWriter
    from host_sim.recordings.replay import replay

    assert main(["sim", "--world", "arena", "--duration", "2", "--record", str(tmp_path / "run.csv")]) == 0
    run = load_recording(tmp_path / "run.csv")
    p = params_from_dict({"ir_bearings": SIX})
    world = world_from_dict(run.meta["world"])
    twin = replay(run, p, world, seed=5, exact_sensors=True, nominal_timing=True)
    assert twin.ir_on.shape == (len(run), 6)
    with RecordingWriter(tmp_path / "six.csv", source="simulator", sample_period=0.04, robot=p.to_json(),
                         world=run.meta["world"], extra={"mode": "fixed"}, n_ir=6) as writer:
        for k in range(len(run)):
            writer.row(twin.t[k], tuple(run.cmd[k]), tuple(twin.enc[k]), twin.ir_on[k].tolist(),
                       twin.ir_amb[k].tolist(), 7.4, tuple(twin.pose[k]), emitter_pct=float(run.emitter[k]))
    six = load_recording(tmp_path / "six.csv")
    again = replay(six, p, world, seed=5, exact_sensors=True)
    np.testing.assert_array_equal(again.ir_on, six.ir_on)
    np.testing.assert_array_equal(again.enc, six.enc)
    capsys.readouterr()
    (tmp_path / "six.json").write_text(json.dumps({"ir_bearings": SIX}))
    assert main(["sim", "--params", str(tmp_path / "six.json"), "--duration", "1"]) == 2
    assert "the firmware reads 8 IR pairs, and this robot has 6" in capsys.readouterr().err


def test_a_map_whose_ir_count_is_not_the_robots_ring_is_refused(tmp_path, capsys):
    assert main(_files(tmp_path, ROBOT_MAP, {"ir_bearings": SIX[:5]}, _robot_log)) == 2
    assert "map.json: ir.on: 6 sensors, but the robot file's ir_bearings places 5 pairs" in capsys.readouterr().err
    assert main(_files(tmp_path, ROBOT_MAP, {"ir_bearings": SIX}, _robot_log)) == 0
