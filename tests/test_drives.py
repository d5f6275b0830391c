"""The drives a robot's parameters choose (docs/motors.md "Drives"): current (today's, unchanged), an H-bridge
driven by voltage or duty with coast or brake decay, and wheel-speed set-points to the robot's own loop.

The bridge's cycle-average current (motors.bridge_current, a closed form) is checked against a brute-force
integration of the switched circuit written here, and the drives run through SimRobot and BatchSim alike.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from host_sim.physics import drivetrain_effects, motors
from host_sim.physics.params import DEFAULT, ParamsError, RobotParams, params_from_dict
from host_sim.robot.batch import BatchSim
from host_sim.robot.sim_robot import SimRobot
from host_sim.physics.world import World

EMPTY = World(name="empty", size=(100.0, 100.0), walls=[])


def switched_circuit(duty: float, emf: float, volts: float, res: float, ind: float, freq: float, brake: bool,
                     cycles: int = 40, steps: int = 2000, battery: bool = False) -> float:
    """The mean current over the last PWM cycle of L di/dt = u - R i - e from i = 0, u the bridge's: V over the
    on-phase; off, 0 (brake) or, coasting, -V sign(i) through the diodes while current flows and e once it
    has stopped (exact exponential steps; a step that crosses zero while coasting stops there).  battery: the
    mean current the supply delivers instead, u / V of the motor's while the bridge connects it (on, or
    coasting through the diodes), 0 while it brakes or no current flows."""
    period, sign = 1.0 / freq, (1.0 if duty >= 0 else -1.0)
    d, e = abs(duty), sign * emf
    h = period / steps
    decay = math.exp(-h * res / ind)
    i, mean, drawn = 0.0, 0.0, 0.0
    for _ in range(cycles):
        mean = drawn = 0.0
        for k in range(steps):
            on = (k + 0.5) * h < d * period
            if on:
                u = volts
            elif brake:
                u = 0.0
            elif i != 0.0:
                u = -volts if i > 0 else volts
            else:
                u = e if abs(e) < volts else math.copysign(volts, e)
            target = (u - e) / res
            new = target + (i - target) * decay
            if not on and not brake and i != 0.0 and new * i < 0.0:
                new = 0.0
            mean += 0.5 * (i + new) / steps
            if on or (not brake and abs(u) == volts):
                drawn += u / volts * 0.5 * (i + new) / steps
            i = new
    return drawn if battery else sign * mean


@pytest.mark.parametrize("brake", [False, True], ids=["coast", "brake"])
@pytest.mark.parametrize("ind,freq", [(1e-3, 20000.0), (2e-4, 5000.0)])
def test_the_bridge_current_is_the_switched_circuits_cycle_average(brake, ind, freq):
    volts, res = 7.4, 10.0
    cases = [(d, e) for d in (0.05, 0.2, 0.4, 0.7, 1.0, -0.3) for e in (-9.0, -2.0, 0.0, 1.5, 4.0, 7.0, 8.0)]
    closed = motors.bridge_current(np.array([c[0] for c in cases]), np.array([c[1] for c in cases]), volts, res,
                                   ind, freq, brake)
    for (d, e), got in zip(cases, closed):
        want = switched_circuit(d, e, volts, res, ind, freq, brake, cycles=25, steps=800)
        assert got == pytest.approx(want, rel=3e-3, abs=2e-5), (d, e)


@pytest.mark.parametrize("brake", [False, True], ids=["coast", "brake"])
@pytest.mark.parametrize("ind,freq", [(2e-4, 20000.0), (1e-3, 5000.0)])
def test_the_battery_current_is_the_switched_circuits_cycle_average(brake, ind, freq):
    """What the supply gives a bridge, its ripple's R <i^2> included: at light duty far more than the mean
    current's (R i + e) i / V."""
    volts, res = 7.4, 10.0
    cases = [(d, e) for d in (0.05, 0.2, 0.4, 0.7, 1.0, -0.3) for e in (-9.0, -2.0, 0.0, 1.5, 4.0, 7.0, 8.0)]
    d, e = np.array([c[0] for c in cases]), np.array([c[1] for c in cases])
    mean, closed = motors.bridge_currents(d, e, volts, res, ind, freq, brake)
    assert np.array_equal(mean, motors.bridge_current(d, e, volts, res, ind, freq, brake))
    for (duty, emf), got in zip(cases, closed):
        want = switched_circuit(duty, emf, volts, res, ind, freq, brake, cycles=25, steps=800, battery=True)
        assert got == pytest.approx(want, rel=3e-3, abs=2e-5), (duty, emf)
    i = motors.bridge_current(0.2, 0.0, volts, res, 2e-4, 2e4, False)
    mean, drawn = motors.bridge_currents(0.2, 0.0, volts, res, 2e-4, 2e4, False)
    assert mean == i and drawn > 2.0 * res * i * i / volts


def test_a_bridged_robots_supply_sags_with_what_its_bridges_draw():
    """The sagged V_s = V_bat - R_int (i_e + both bridges' draw), each the switched circuit's at the wheel's
    speed and V_s itself."""
    p = RobotParams(drive="duty", battery_resistance=2.0)
    sim = BatchSim(None, p, bench=True)
    res = sim.run_inputs(np.tile([0.25, -0.6], (200, 1)), sensors=False)
    v_s, w = float(res.vbat[-1, 0]), sim.v[0]
    emf = p.torque_constant * p.gear_ratio * w
    drawn = sum(switched_circuit(duty, e, v_s, p.armature_resistance, p.motor_inductance, p.pwm_frequency, False,
                                 battery=True) for duty, e in zip((0.25, -0.6), emf))
    assert v_s == pytest.approx(p.battery_voltage - 2.0 * (p.electronics_current + drawn), abs=2e-4)
    assert v_s < p.battery_voltage - 2.0 * (p.electronics_current + 0.001)


def test_brake_is_the_linear_average_and_coast_is_not_at_light_load():
    d, e = np.linspace(-1, 1, 41)[:, None], np.linspace(-8, 8, 33)[None, :]
    brake = motors.bridge_current(d, e, 7.4, 10.0, 1e-3, 2e4, True)
    assert np.allclose(brake, (d * 7.4 - e) / 10.0, rtol=0, atol=1e-15)
    # coasting at 40 % duty against a back-EMF of 60 % of the supply: the linear model brakes, coast still drives
    assert motors.bridge_current(0.4, 0.6 * 7.4, 7.4, 10.0, 1e-3, 2e4, False) > 0.0
    assert motors.bridge_current(0.4, 0.6 * 7.4, 7.4, 10.0, 1e-3, 2e4, True) < 0.0


def test_the_coast_current_is_continuous_across_its_regimes():
    """Where the current stops flowing within the cycle and where it does not, the closed forms meet."""
    e = np.linspace(-12.0, 12.0, 200001)
    for d in (0.0, 0.1, 0.5, 0.9, 1.0):
        for ind in (0.0, 1e-4, 1e-3, 1e-2):
            i = motors.bridge_current(d, e, 7.4, 10.0, ind, 2e4, False)
            assert np.all(np.isfinite(i))
            assert np.max(np.abs(np.diff(i))) < 2e-5, (d, ind)  # slope 1/R at most: 1.2e-5 per step of e


def test_without_inductance_the_current_follows_the_bridge_at_once():
    """L = 0: V - e over the on-phase, nothing after it while e < V."""
    d, e = np.array([0.1, 0.5, 0.9]), np.array([0.0, 3.0, 6.0])
    assert np.allclose(motors.bridge_current(d, e, 7.4, 10.0, 0.0, 2e4, False), d * (7.4 - e) / 10.0)


def test_deadband_and_dead_time_take_duty_off():
    duty = np.array([-1.0, -0.5, -0.05, 0.0, 0.05, 0.5, 1.0, 1.5])
    out = motors.bridge_duty(duty, 0.1, 0.0, 2e4)
    assert np.allclose(out, [-1.0, -0.4 / 0.9, 0.0, 0.0, 0.0, 0.4 / 0.9, 1.0, 1.0])
    assert np.allclose(motors.bridge_duty(duty, 0.0, 1e-6, 2e4), np.sign(duty) * np.maximum(
        np.minimum(np.abs(duty), 1.0) - 0.02, 0.0))


def test_a_parameter_file_names_the_drive_and_writes_it_back():
    p = params_from_dict({"drive": "duty", "pwm_decay": "brake", "ticks_per_rev": 358.32, "motor_inductance": 5e-4})
    assert p.drive_kind == "duty" and p.pwm_decay == 1.0 and p.ticks_per_rev == 358.32
    written = p.to_json()
    assert written["drive"] == "duty" and written["pwm_decay"] == "brake"
    assert params_from_dict(written) == p
    assert DEFAULT.to_json()["drive"] == "current" and RobotParams(drive="wheel_speed").drive == 3.0
    for bad in ({"drive": "pwm"}, {"drive": 1}, {"pwm_decay": "slow"}, {"driver_deadband": 1.0},
                {"ticks_per_rev": 0.5}):
        with pytest.raises(ParamsError):
            params_from_dict(bad)


def test_the_current_drive_takes_the_nominal_path_unchanged():
    """drive = current is the default: the fast nominal step, the same numbers bit for bit."""
    named = RobotParams(drive="current")
    assert named == DEFAULT and not drivetrain_effects.active(named)
    cmd = np.tile([0.2, 0.15], (60, 1))
    a = BatchSim(None, named).run_inputs(cmd, sensors=False)
    b = BatchSim(None, DEFAULT).run_inputs(cmd, sensors=False)
    assert np.array_equal(a.pose, b.pose) and np.array_equal(a.enc, b.enc)
    assert BatchSim(None, named)._fx is None


@pytest.mark.parametrize("kind,cmd", [("voltage", 3.0), ("duty", 0.4), ("wheel_speed", 15.0)])
def test_sim_robot_and_batch_agree_for_each_drive(kind, cmd):
    p = RobotParams(drive=kind)
    robot = SimRobot(EMPTY, p, pose=(1.0, 1.0, 0.0), noise=False)
    robot.i_ref = (cmd, 0.8 * cmd)
    sim = BatchSim(EMPTY, p, poses=[[1.0, 1.0, 0.0]])
    sim.run_inputs(np.tile([cmd, 0.8 * cmd], (40, 1)), sensors=False)
    for _ in range(40 * 8):
        robot.advance(sim.cycle_s / 8)
    assert np.allclose(robot.pose, sim.pose[0], atol=1e-9)


def test_a_voltage_drive_reaches_the_speed_its_circuit_gives():
    """Brake decay, no friction: steady where the linear average current meets nothing, e = V_cmd."""
    p = RobotParams(drive="voltage", pwm_decay="brake", coulomb_friction=0.0, viscous_friction=0.0)
    sim = BatchSim(None, p, bench=True)
    sim.run_inputs(np.tile([3.0, -2.0], (400, 1)), sensors=False)
    n_ke = p.torque_constant * p.gear_ratio
    assert np.allclose(sim.v[0], [3.0 / n_ke, -2.0 / n_ke], rtol=1e-6)


def test_coast_at_light_load_turns_faster_than_the_linear_model():
    cmd = np.tile([0.3, 0.3], (300, 1))
    coast = BatchSim(None, RobotParams(drive="duty"), bench=True)
    brake = BatchSim(None, RobotParams(drive="duty", pwm_decay="brake"), bench=True)
    coast.run_inputs(cmd, sensors=False)
    brake.run_inputs(cmd, sensors=False)
    assert coast.v[0, 0] > 1.5 * brake.v[0, 0] > 0.0


def test_the_wheel_speed_drive_follows_its_set_points_through_its_own_loop():
    p = RobotParams(drive="wheel_speed")
    sim = BatchSim(None, p)
    res = sim.run_inputs(np.repeat([[10.0, -5.0], [20.0, 12.0]], 75, axis=0), sensors=False)
    speed = np.diff(res.theta[:, 0], axis=0) / sim.cycle_s
    assert np.allclose(speed[60:74], [10.0, -5.0], rtol=0.03)
    assert np.allclose(speed[-15:], [20.0, 12.0], rtol=0.03)
    # without its integral the loop leaves a steady error (friction needs a voltage kp e must supply)
    lazy = BatchSim(None, p.replace(speed_ki=0.0))
    lazy_res = lazy.run_inputs(np.tile([10.0, 10.0], (75, 1)), sensors=False)
    assert np.diff(lazy_res.theta[-15:, 0, 0]).mean() / sim.cycle_s < 0.9 * 10.0


def test_a_set_point_loop_counts_at_the_boards_scale_and_its_twin_is_smooth():
    """The board counts each encoder at its datasheet's ticks_per_rev: a left encoder 2.6 % finer holds its
    wheel 2.6 % under the set-point, the right at it.  With whole counts a loop's wheel moves in jumps as a
    parameter is nudged (a count changes); the diagnosis's twin (loop_counts_whole off) moves smoothly, so
    a finite difference gives the same slope at two steps."""
    p = RobotParams(drive="wheel_speed", ticks_per_rev_delta_l=31.0)
    sim = BatchSim(None, p)
    res = sim.run_inputs(np.tile([10.0, 10.0], (100, 1)), sensors=False)
    speed = np.diff(res.theta[-26:, 0], axis=0).mean(0) / sim.cycle_s
    assert speed[0] == pytest.approx(10.0 * 1200.0 / 1231.0, rel=0.005) and speed[1] == pytest.approx(10.0, rel=0.005)

    def end_angle(radius_share: float, whole: bool) -> float:
        sim = BatchSim(None, RobotParams(drive="wheel_speed", wheel_radius=DEFAULT.wheel_radius * (1 + radius_share)))
        sim.loop_counts_whole = whole
        cmd = np.repeat([[8.0, 8.0], [14.0, 3.0], [-6.0, 9.0]], 10, axis=0)
        return float(sim.run_inputs(cmd, sensors=False).theta[-1, 0, 0])

    for whole, smooth in ((False, True), (True, False)):
        base = end_angle(0.0, whole)
        slopes = [(end_angle(h, whole) - base) / h for h in (1e-3, 1e-4)]
        assert (abs(slopes[0] - slopes[1]) <= 0.1 * abs(slopes[0])) == smooth, (whole, slopes)


def test_the_speed_loop_runs_at_its_own_period():
    """A loop ten times slower answers a set-point step later: its first volts are held a whole period."""
    fast = BatchSim(None, RobotParams(drive="wheel_speed"))
    slow = BatchSim(None, RobotParams(drive="wheel_speed", speed_loop_period=0.1))
    cmd = np.tile([15.0, 15.0], (10, 1))
    a, b = fast.run_inputs(cmd, sensors=False), slow.run_inputs(cmd, sensors=False)
    assert not np.allclose(a.theta, b.theta, atol=1e-3)


@pytest.mark.parametrize("kind,cmd", [("voltage", (2.5, -1.0)), ("duty", (0.5, 0.3)), ("wheel_speed", (12.0, 4.0))])
def test_a_recording_of_each_drive_replays_exactly(tmp_path, kind, cmd):
    """A twin's own recording of a drive, with the drive block, replays from row 0 on the batch path and
    through SimRobot alike, tick for tick."""
    from host_sim.physics.params import DRIVE_UNITS
    from host_sim.recordings.recording import RecordingWriter, load_recording
    from host_sim.recordings.replay import replay, replay_batch

    p = RobotParams(drive=kind, battery_resistance=0.5)
    rows = np.concatenate([np.tile(cmd, (40, 1)), np.tile(cmd[::-1], (40, 1))])
    sim = BatchSim(EMPTY, p, poses=[[1.0, 1.0, 0.0]])
    res = sim.run_inputs(rows, sensors=False)
    path = tmp_path / "run.csv"
    block = {"kind": kind, "unit": DRIVE_UNITS[kind], "source_unit": DRIVE_UNITS[kind], "full_scale": None}
    with RecordingWriter(path, source="simulator", sample_period=sim.cycle_s, robot=p.to_json(),
                         extra={"drive": block, "mode": "fixed"}) as w:
        for j, row in enumerate(rows):
            w.row(j * sim.cycle_s, tuple(row), tuple(res.enc[j, 0]), [0] * 8, [0] * 8, float(res.vbat[j, 0]),
                  tuple(res.pose[j, 0]))
    rec = load_recording(path)
    assert rec.drive == kind
    # given the current drive's parameters, the replay still feeds the commands to the recording's drive
    again = replay_batch(rec, RobotParams(battery_resistance=0.5), sensors=False)
    assert np.array_equal(again.enc[:, 0], res.enc[:, 0])
    one = replay(rec, RobotParams(battery_resistance=0.5), EMPTY)
    assert np.abs(one.enc - res.enc[:, 0]).max() <= 1


def test_the_library_offers_an_effect_for_its_drives_only_and_none_of_the_floors_on_a_bench():
    from host_sim.diagnosis.fit import candidates_for
    from host_sim.physics import effects

    def names(drive, bench=False):
        return {c.name for c in candidates_for(["wheel_l"], drive, bench)}

    assert set(effects.ALL_DRIVES) == set(params_module().DRIVES)
    assert "current_limit" in names("current") and "current_limit" not in names("duty")
    assert {"motor_resistance", "driver_deadband"} <= names("voltage") and not {"motor_resistance",
                                                                                 "driver_deadband"} & names("current")
    assert {"speed_loop_kp", "speed_loop_ki"} <= names("wheel_speed") and "speed_loop_kp" not in names("duty")
    floor = {"traction_limit", "caster_drag", "turning_resistance", "com_offset", "mass", "track_width",
             "wheel_radius"}
    assert floor <= names("duty") and not floor & names("duty", bench=True)
    assert "dry_friction" in names("duty", bench=True)


def params_module():
    from host_sim.physics import params

    return params


@pytest.mark.parametrize("fields", [{"armature_resistance_delta_l": 5.0}, {"driver_deadband": 0.15},
                                    {"speed_kp": 0.3, "drive": "wheel_speed"}])
def test_the_drive_effects_change_the_twin_and_sim_robot_agrees(fields):
    base = RobotParams(drive=fields.get("drive", "duty"))
    p = base.replace(**{k: v for k, v in fields.items() if k != "drive"})
    cmd = (8.0, 6.0) if base.drive_kind == "wheel_speed" else (0.35, 0.25)
    sim = BatchSim(EMPTY, [p, base], poses=[[1.0, 1.0, 0.0]] * 2)
    res = sim.run_inputs(np.tile(cmd, (50, 1)), sensors=False)
    assert np.abs(res.pose[:, 0] - res.pose[:, 1]).max() > 1e-4
    robot = SimRobot(EMPTY, p, pose=(1.0, 1.0, 0.0), noise=False)
    robot.i_ref = cmd
    for _ in range(50 * 8):
        robot.advance(sim.cycle_s / 8)
    assert np.allclose(robot.pose, sim.pose[0], atol=1e-9)


def test_twinbot_sim_runs_a_wheel_speed_robot_and_the_gui_still_refuses_it(tmp_path):
    """sim runs the firmware on every drive, a wheel_speed robot's set-points the HAL's duty times its top speed
    (hardware_io.firmware_command); the GUI, whose recordings write the firmware's currents in A, runs current
    robots only and says so in one line, status 2."""
    import argparse

    from tests.helpers import run_twinbot
    from tools.arguments import CliError
    from tools.cli.sim import load_inputs

    path = tmp_path / "robot.json"
    path.write_text('{"drive": "wheel_speed"}')
    r = run_twinbot("sim", "--params", str(path), "--duration", "1")
    assert r.returncode == 0 and "coverage" in r.stdout and not r.stderr, r.stdout + r.stderr
    for kind in ("duty", "voltage", "wheel_speed"):  # a bridge takes the duty the firmware's HAL writes
        path.write_text(json.dumps({"drive": kind}))
        assert load_inputs(argparse.Namespace(params=str(path), world="paper_room"))[0].drive_kind == kind
        with pytest.raises(CliError, match=f"drive '{kind}': this command runs current drives only"):
            load_inputs(argparse.Namespace(params=str(path), world="paper_room"), drives=("current",))
    r = run_twinbot("gui", "--params", str(path), "--frames", "1")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "drive 'wheel_speed'" in r.stderr and "Traceback" not in r.stderr


def test_the_hal_duty_is_the_rp2040_hals(monkeypatch):
    """hardware_io.hal_duty, what a bridge robot's twin is given, is the duty firmware/hal_rp2040.py `_drive`
    writes (its PWM register over 65535, the sign on the direction pin), full scale and clipping included."""
    import sys
    import types

    from firmware.config import CURRENT_FULL_SCALE_MA
    from host_sim.controller.hardware_io import firmware_command, hal_duty

    machine = types.ModuleType("machine")
    for name in ("ADC", "PWM", "WDT", "Pin"):
        setattr(machine, name, object)
    machine.mem32 = None
    monkeypatch.setitem(sys.modules, "machine", machine)
    monkeypatch.setitem(sys.modules, "micropython", types.ModuleType("micropython"))
    monkeypatch.delitem(sys.modules, "firmware.hal_rp2040", raising=False)
    from firmware.hal_rp2040 import Rp2040Hal

    class Out:
        def value(self, v):
            self.v = v

        def duty_u16(self, v):
            self.v = v

    hal = types.SimpleNamespace(motor_dir=[Out()], motor_pwm=[Out()])
    for ma in (0, 1, -1, 7, 250, -333, 999, CURRENT_FULL_SCALE_MA, -CURRENT_FULL_SCALE_MA, 1500, -32000):
        Rp2040Hal._drive(hal, 0, ma)
        sign = -1 if hal.motor_dir[0].v else 1
        assert hal_duty(ma) == sign * hal.motor_pwm[0].v / 65535, ma
    assert hal_duty(CURRENT_FULL_SCALE_MA // 2) == pytest.approx(0.5, abs=2e-5) and hal_duty(-5000) == -1.0
    assert firmware_command(RobotParams(drive="voltage", battery_voltage=6.0))(-5000) == -6.0
    assert firmware_command(DEFAULT)(-250) == -0.25  # a current drive: the reference in A, as ever
    set_point = RobotParams(drive="wheel_speed", battery_voltage=6.0, torque_constant=0.004, gear_ratio=30.0)
    assert firmware_command(set_point)(-5000) == pytest.approx(-50.0)  # full duty: V / (k_e N), the top speed
    assert firmware_command(set_point)(CURRENT_FULL_SCALE_MA // 4) == hal_duty(CURRENT_FULL_SCALE_MA // 4) * 6.0 / 0.12


@pytest.mark.slow
def test_diagnose_names_a_motors_resistance_on_a_bench_and_nothing_of_the_floor(tmp_path):
    """A duty robot on a bench whose left motor has 6 ohm more than its datasheet: the diagnosis, on the
    encoders alone, holds the body, fits motor_resistance at the left wheel and says nothing of the motion."""
    from host_sim.diagnosis import diagnose
    from host_sim.recordings.recording import RecordingWriter, load_recording

    base = RobotParams(drive="duty")
    truth = base.replace(armature_resistance_delta_l=6.0)
    period, n = 0.04, 1500
    levels = np.repeat(np.random.default_rng(1).uniform(-1, 1, (n // 25 + 1, 2)), 25, axis=0)[:n]
    res = BatchSim(None, truth, bench=True, cycle_s=period).run_inputs(levels, sensors=False)
    path = tmp_path / "bench.csv"
    block = {"kind": "duty", "unit": "fraction", "source_unit": "fraction", "full_scale": None}
    with RecordingWriter(path, source="robot", sample_period=period, robot=base.to_json(),
                         extra={"drive": block, "bench": True}) as w:
        for j in range(n):
            w.row(j * period, tuple(levels[j]), tuple(res.enc[j, 0]), [0] * 8, [0] * 8, float(res.vbat[j, 0]))
    found = diagnose(load_recording(path), base, None).to_json()
    assert found["verdict"] == "explained"
    (effect,) = found["effects"]
    assert effect["name"] == "motor_resistance" and effect["wheel"] == "left"
    assert effect["params"]["resistance"]["value"] == pytest.approx(6.0, rel=0.02)
    assert not {c["channel"] for c in found["located"]} & {"forward", "lateral", "heading_rate", "travel", "turn"}
