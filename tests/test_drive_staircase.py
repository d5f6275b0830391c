"""Proof: a duty staircase recorded on a stand from a plant that is not the twin's code, replayed by the twin's
H-bridge drive with the plant's datasheet values, turns the wheels within 10 % of the plant's steady speed at
every duty of 40 % or more (docs/motors.md "Drives", docs/recordings.md "The drive block").

The plant, written here: the switched circuit integrated in small steps through every PWM cycle (coast decay,
the current returned through the diodes and cut off at zero, an inductance), a wheel with plain Coulomb and
viscous friction (no Stribeck dip), a 29.86:1 gear and a 12-count encoder (358.32 counts a wheel turn).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from host_sim.physics.world import World
from host_sim.recordings.recording import RecordingError, RecordingWriter, load_recording
from host_sim.recordings.replay import replay, replay_batch

# The plant's datasheet: a 6 V class gear motor on a 2S battery
V_BAT, RES, IND, K_E, GEAR = 7.9, 6.5, 3.5e-4, 0.0042, 29.86
PWM_HZ, INERTIA, T_COULOMB, C_VISCOUS = 10000.0, 9.0e-6, 3.0e-4, 4.0e-6  # wheel side
COUNTS = 12 * GEAR
SUBSTEPS = 16  # per PWM cycle
DUTIES = (0.2, 0.4, 0.6, 0.8, 1.0)
HOLD_S, PERIOD_S = 2.0, 0.02


def plant_staircase() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, duty, wheel angle) every PERIOD_S of the staircase, from the switched circuit."""
    h = 1.0 / PWM_HZ / SUBSTEPS
    decay = math.exp(-h * RES / IND)
    n_ke = K_E * GEAR
    i = w = theta = 0.0
    rows_per_hold = round(HOLD_S / PERIOD_S)
    cycles_per_row = round(PERIOD_S * PWM_HZ)
    t, duty_out, angle = [], [], []
    for duty in DUTIES:
        on_steps = round(duty * SUBSTEPS)
        for _row in range(rows_per_hold):
            t.append(len(t) * PERIOD_S)
            duty_out.append(duty)
            angle.append(theta)
            for _cycle in range(cycles_per_row):
                for k in range(SUBSTEPS):
                    e = n_ke * w
                    if k < on_steps:
                        u = V_BAT
                    elif i > 0.0:
                        u = -V_BAT  # coasting: the diodes return the current to the supply
                    else:
                        u = e  # no current: the terminals show the back-EMF
                    target = (u - e) / RES
                    new = target + (i - target) * decay
                    if k >= on_steps and i > 0.0 > new:
                        new = 0.0
                    torque = n_ke * 0.5 * (i + new) - C_VISCOUS * w
                    i = new
                    if w == 0.0 and abs(torque) <= T_COULOMB:
                        continue
                    w_new = w + h * (torque - math.copysign(T_COULOMB, w if w else torque)) / INERTIA
                    w_new = 0.0 if w_new * w < 0.0 else w_new
                    theta += 0.5 * h * (w + w_new)
                    w = w_new
    return np.array(t), np.array(duty_out), np.array(angle)


ROBOT = {"drive": "duty", "pwm_decay": "coast", "battery_voltage": V_BAT, "armature_resistance": RES,
         "motor_inductance": IND, "torque_constant": K_E, "gear_ratio": GEAR, "gear_efficiency": 1.0,
         "pwm_frequency": PWM_HZ, "wheel_inertia": INERTIA, "coulomb_friction": T_COULOMB,
         "viscous_friction": C_VISCOUS, "ticks_per_rev": COUNTS}


@pytest.fixture(scope="module")
def bench_recording(tmp_path_factory):
    t, duty, angle = plant_staircase()
    path = tmp_path_factory.mktemp("stand") / "staircase.csv"
    drive = {"kind": "duty", "unit": "fraction", "source_unit": "counts", "full_scale": 255}
    with RecordingWriter(path, source="robot", sample_period=PERIOD_S, robot=ROBOT,
                         extra={"drive": drive, "bench": True}) as rec:
        for tk, dk, ak in zip(t, duty, angle):
            count = math.floor(ak / (2 * math.pi) * COUNTS)
            rec.row(float(tk), (float(dk), float(dk)), (count, count), [0] * 8, [0] * 8, V_BAT)
    return path


def steady_speeds(t: np.ndarray, enc: np.ndarray) -> list[float]:
    """rad/s of the left wheel over the last half second of each hold."""
    out = []
    per_hold = round(HOLD_S / PERIOD_S)
    for k in range(len(DUTIES)):
        a, b = (k + 1) * per_hold - round(0.5 / PERIOD_S), (k + 1) * per_hold - 1
        out.append(float((enc[b] - enc[a]) * 2 * math.pi / COUNTS / (t[b] - t[a])))
    return out


def test_a_duty_staircase_on_a_stand_replays_within_ten_percent(bench_recording):
    from host_sim.physics.params import params_from_dict

    rec = load_recording(bench_recording)
    assert rec.drive == "duty" and rec.bench and rec.pose is None
    params = params_from_dict(rec.meta["robot"])
    recorded = steady_speeds(rec.t, rec.enc[:, 0])
    batch = replay_batch(rec, params, sensors=False)
    one = replay(rec, params, World(name="stand", size=(1.0, 1.0), walls=[]))
    for twin in (steady_speeds(batch.t, batch.enc[:, 0, 0]), steady_speeds(one.t, one.enc[:, 0])):
        for duty, want, got in zip(DUTIES, recorded, twin):
            if duty >= 0.4:
                assert got == pytest.approx(want, rel=0.10), (duty, want, got)
    # the pose stays: the body is held
    assert np.all(batch.pose == batch.pose[0])
    # the linear (brake) model misses the light-load speeds by far more
    linear = replay_batch(rec, params.replace(pwm_decay=1.0), sensors=False)
    assert abs(steady_speeds(linear.t, linear.enc[:, 0, 0])[1] / recorded[1] - 1) > 0.25


def test_a_sidecar_whose_robot_and_drive_block_disagree_is_refused(bench_recording, tmp_path):
    side = json.loads(bench_recording.with_name("staircase.csv.json").read_text())
    (tmp_path / "r.csv").write_text(bench_recording.read_text())
    for change, words in (({"robot": {**ROBOT, "drive": "voltage"}}, "robot's parameters say drive 'voltage'"),
                          ({"drive": {"kind": "duty", "unit": "%"}}, "unit must be 'fraction'"),
                          ({"drive": {"kind": "pwm"}}, "one of current, voltage"),
                          ({"bench": "yes"}, "'bench' must be true or false")):
        (tmp_path / "r.csv.json").write_text(json.dumps({**side, **change}))
        with pytest.raises(RecordingError, match=words):
            load_recording(tmp_path / "r.csv")
