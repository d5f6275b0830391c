"""The reference plant's own drives: its H-bridge, its wheel-speed loop, their effects and their cases.

The bridge is solved cycle by cycle (tools/reference_plant/hbridge.py); these tests hold it to the closed
forms of a PWM cycle in periodic steady state (docs/motors.md "Drives") and the plant's robot to them at a
steady speed.  docs/proving-ground.md, "Drives".
"""
from __future__ import annotations

import json
import math

import pytest

from host_sim.recordings.recording import load_recording
from tools.reference_plant import effects, hbridge
from tools.reference_plant.cases import kinds, make_case
from tools.reference_plant.plant import Plant
from tools.reference_plant.robot_model import PlantSpec, datasheet_spec

V, R, L, F = 7.4, 10.0, 2e-4, 20000.0
SHEET = datasheet_spec().replace(tracker_noise_xy=0.0, tracker_noise_phi=0.0)


def periodic(duty: float, emf: float, brake: bool) -> float:
    """The bridge's mean current once its cycles repeat (many ms at a held back-EMF)."""
    i = 0.0
    for _ in range(50):
        i, mean, _battery = hbridge.step(i, duty, emf, V, R, L, F, brake, 0.001)
    return mean


def closed_form_coast(d: float, e: float) -> float:
    """Fast decay at duty d > 0, |e| < V: discontinuous conduction where the current dies within the cycle,
    else continuous ((2d - 1) V - e) / R."""
    k = L * F / R  # tau / T
    rise = (V - e) * (1.0 - math.exp(-d / k))  # R i at the end of the on-phase, from 0
    x = k * math.log(1.0 + rise / (V + e))  # the share of the cycle the off-phase conducts
    if x < 1.0 - d:
        return (d * V - x * V - (d + x) * e) / R
    return ((2.0 * d - 1.0) * V - e) / R


@pytest.mark.parametrize("duty", [0.05, 0.2, 0.5, 0.9])
@pytest.mark.parametrize("emf", [-2.0, 0.0, 1.5, 4.0])
def test_the_bridge_agrees_with_the_closed_form_in_periodic_steady_state(duty, emf):
    assert periodic(duty, emf, brake=True) == pytest.approx((duty * V - emf) / R, abs=1e-6)
    assert periodic(duty, emf, brake=False) == pytest.approx(closed_form_coast(duty, emf), abs=1e-6)
    assert periodic(-duty, -emf, brake=False) == pytest.approx(-closed_form_coast(duty, emf), abs=1e-6)  # mirror


def test_a_generating_motor_feeds_the_battery_through_the_diodes():
    i, mean, battery = 0.0, 0.0, 0.0
    for _ in range(20):
        i, mean, battery = hbridge.step(i, 0.3, 9.0, V, R, L, F, False, 0.001)
    assert mean == pytest.approx((V - 9.0) / R, abs=1e-6) and battery == pytest.approx(mean, abs=1e-6)


def test_the_battery_gives_its_drivers_current_at_its_terminals():
    """V = V_bat - R_int (i_q + both bridges' battery current at the terminal voltage V): the bridges' power
    taken at the terminals, not at the open-circuit voltage (3 % less current at this sag)."""
    spec = SHEET.replace(drive="duty", battery_resistance=2.0, inductance=(2e-4, 2e-4))
    plant = Plant(spec, None, (0.0, 0.0, 0.0), 0)
    plant.command((0.3, -0.5), 0)
    plant.advance(1.0)
    v, drawn = plant.v_term, 0.0
    for k, duty in enumerate((0.3, -0.5)):
        emf = plant.torque_constant(k) * spec.gear_ratio * float(plant.data.qvel[plant._drive_v[k]])
        drawn += hbridge.step(plant._coil[k], duty, emf, v, spec.armature_resistance[k], spec.inductance[k],
                              spec.pwm_frequency, False, plant.dt)[2]
    assert v == pytest.approx(spec.battery_voltage - 2.0 * (spec.quiescent_current + drawn), abs=1e-5)


def steady(spec: PlantSpec, cmd: float, seconds: float = 2.0) -> Plant:
    plant = Plant(spec, None, (0.0, 0.0, 0.0), 0)
    plant.command((cmd, cmd), 0)
    plant.advance(seconds)
    return plant


def test_at_a_steady_speed_the_robots_current_is_the_closed_forms():
    """On the floor at a steady low duty: brake's current is (d V - e) / R at the wheel's back-EMF, coast's
    the discontinuous form, and coasting runs faster (the terminals see e, not -V, once the current dies)."""
    d, ke = 0.15, SHEET.torque_constant[0] * SHEET.gear_ratio
    runs = {decay: steady(SHEET.replace(drive="duty", pwm_decay=decay), d) for decay in ("brake", "coast")}
    for decay, plant in runs.items():
        e = ke * plant.wheel_speeds()[0]
        expected = (d * V - e) / R if decay == "brake" else closed_form_coast(d, e)
        assert plant.current[0] == pytest.approx(expected, rel=0.02), decay
    assert runs["coast"].wheel_speeds()[0] > 1.3 * runs["brake"].wheel_speeds()[0]


def test_the_voltage_drive_is_a_duty_across_the_battery():
    volts = steady(SHEET.replace(drive="voltage"), 0.25 * V)
    duty = steady(SHEET.replace(drive="duty"), 0.25)
    assert volts.wheel_speeds()[0] == pytest.approx(duty.wheel_speeds()[0], rel=1e-3)


def test_the_wheel_speed_loop_holds_its_set_point():
    for decay in ("coast", "brake"):
        plant = steady(SHEET.replace(drive="wheel_speed", pwm_decay=decay), 6.0, 3.0)
        assert plant.wheel_speeds() == pytest.approx((6.0, 6.0), rel=0.03), decay
    slow = steady(effects.apply(SHEET.replace(drive="wheel_speed"), "speed_loop_ki", 0.3), 6.0, 0.5)
    quick = steady(effects.apply(SHEET.replace(drive="wheel_speed"), "speed_loop_ki", 3.0), 6.0, 0.5)
    assert slow.wheel_speeds()[0] < quick.wheel_speeds()[0] - 0.5  # the integral takes longer to build


def test_the_drive_effects_are_physical():
    duty = SHEET.replace(drive="duty", pwm_decay="brake")
    base = steady(duty, 0.3).wheel_speeds()
    resisted = effects.apply(duty, "motor_resistance", 15.0, "left")
    start = steady(resisted, 0.3, 0.001).current  # at rest the winding alone sets the current: d V / R
    assert start[0] == pytest.approx(10.0 / 15.0 * start[1], rel=0.03)
    moving = steady(resisted, 0.3).wheel_speeds()
    assert moving[0] < base[0] - 0.2 and moving[1] == pytest.approx(base[1], rel=0.01)
    held = steady(effects.apply(duty, "driver_deadband", 0.06), 0.05).wheel_speeds()
    assert held == (0.0, 0.0) or max(map(abs, held)) < 1e-3  # below the deadband the bridge gives nothing
    narrowed = steady(effects.apply(duty, "driver_deadband", 0.06), 0.3).wheel_speeds()
    assert narrowed[0] < base[0]
    kp = steady(effects.apply(SHEET.replace(drive="wheel_speed"), "speed_loop_kp", 0.3), 6.0, 0.15).wheel_speeds()
    soft = steady(SHEET.replace(drive="wheel_speed"), 6.0, 0.15).wheel_speeds()
    assert kp[0] > soft[0]  # a stiffer loop answers a step sooner


def test_each_drive_draws_only_the_effects_it_has():
    current = kinds("tuning")
    assert not {"motor_resistance", "driver_deadband", "speed_loop_kp", "speed_loop_ki"} & set(current)
    assert "current_limit" in current and "current_limit" not in kinds("tuning", "duty")
    assert {"motor_resistance", "driver_deadband"} <= set(kinds("tuning", "duty"))
    assert "speed_loop_kp" not in kinds("tuning", "voltage") and "speed_loop_ki" in kinds("tuning", "wheel_speed")


@pytest.mark.parametrize("drive", ["duty", "wheel_speed"])
def test_a_case_of_another_drive_records_its_commands_in_that_drives_unit(tmp_path, drive):
    rec_path, key_path = make_case(7, tmp_path, duration=1.0, drive=drive)
    rec = load_recording(rec_path)
    meta = json.loads(rec_path.with_name(rec_path.name + ".json").read_text())
    assert rec.drive == drive and meta["robot"]["drive"] == drive
    assert meta["drive"]["unit"] == {"duty": "fraction", "wheel_speed": "rad/s"}[drive]
    assert json.loads(key_path.read_text())["plant"]["drive"] == drive
    assert abs(rec.cmd).max() > 0
    current = load_recording(make_case(7, tmp_path / "current", duration=1.0)[0])
    assert current.drive == "current" and "drive" not in json.loads(
        (tmp_path / "current" / (rec_path.name + ".json")).read_text())
