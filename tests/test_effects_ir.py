"""The IR effects of the library (host_sim/physics/effects.py, docs/effects.md "IR sensor effects") as physics in the twin.

Each effect on a case computed by hand (a wall straight ahead of S1, the
emitters at 60 %, no noise), then the single-robot path (read_sensors,
SimRobot) against the batch path (read_sensors on (N, 3) poses, BatchSim), then a
parameter file that sets them all.  With every effect absent the readings
are those of tests/test_ir_sensor.py, unchanged.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from host_sim.physics import effects as E
from host_sim.sensors import ir_sensor as ir
from host_sim.robot.batch import IR_FIELDS, BatchSim
from host_sim.physics.params import DEFAULT as P
from host_sim.physics.params import load_params
from host_sim.robot.sim_robot import SimRobot
from host_sim.physics.world import Lamp, builtin_world
from tests.test_batch import assert_adc_match, simrobot_run
from tests.test_ir_sensor import R, ambient_reference, room, wall_ahead

AT = (1.0, 1.0, 0.0)  # S1 looks along +x at the wall of wall_ahead(gap)
GAP = 0.06  # m from S1 to the wall: ~480 counts reflected, far from the ADC's ceiling


def reading(world, p, pose=AT, power=60, t=0.0):
    off, on = ir.read_sensors(world, pose, power, t, p)
    return off, on, on - off


def at_sensor(name, k, value):
    return E.apply(P, name, k, [value])


# --------------------------------------------------------------------------- each effect by hand
def test_gain_scales_one_pairs_reflected_light_before_the_adc():
    w = wall_ahead(GAP)
    _, _, nominal = reading(w, P)
    off, on, refl = reading(w, at_sensor("ir_gain", 0, 1.3))
    assert refl[0] == round(1.3 * float(ir.response(GAP, 0.0, 60))) != nominal[0]
    assert np.array_equal(refl[1:], nominal[1:]) and (off == P.ir_ambient).all()
    # Before the ADC: a bright pair saturates at the ceiling, as the total light does.
    _, on, _ = reading(wall_ahead(0.03), at_sensor("ir_gain", 0, 3.0))
    assert on[0] == P.adc_max


@pytest.mark.parametrize("delta", [0.3, -0.2])
def test_misalignment_turns_the_axis_about_the_mount(delta):
    """The turned axis leaves S1's mount (1 + R, 1) at angle delta: it meets the wall gap / cos(delta)
    away, at incidence delta."""
    w = wall_ahead(GAP)
    _, _, refl = reading(w, at_sensor("ir_misalignment", 0, delta))
    assert refl[0] == round(float(ir.response(GAP / math.cos(delta), delta, 60)))
    dist, angle, hit = ir.reflection(w, np.array(AT), at_sensor("ir_misalignment", 0, delta))
    assert dist[0] == pytest.approx(GAP / math.cos(delta), abs=1e-12) and abs(angle[0]) == pytest.approx(abs(delta))
    # Counter-clockwise: a wall above the nominal axis only (y > 1.01) is seen by S1 turned by +0.3, not -0.3.
    x = 1.0 + R + GAP
    upper = room([{"segment": [x, 1.01, x, 1.5]}])
    assert reading(upper, P)[2][0] == 0
    assert reading(upper, at_sensor("ir_misalignment", 0, 0.3))[2][0] > 0
    assert reading(upper, at_sensor("ir_misalignment", 0, -0.3))[2][0] == 0


def test_misalignment_turns_the_receiver_towards_or_away_from_a_lamp():
    lamp = {"x": 1.5, "y": 1.3, "level": 20.0}  # ahead and to the left of S1
    w = room([], lamps=[lamp], ambient=100)
    for delta in (0.0, 0.4, -0.4):
        p = at_sensor("ir_misalignment", 0, delta)
        off, _, _ = reading(w, p)
        assert np.array_equal(off, np.rint(ambient_reference(w, AT, p=p)))
    towards, away = (reading(w, at_sensor("ir_misalignment", 0, d))[0][0] for d in (0.4, -0.4))
    assert towards > reading(w, P)[0][0] > away


def test_offset_is_added_to_the_emitter_on_reading_only():
    w = wall_ahead(GAP)
    off0, on0, _ = reading(w, P)
    off, on, _ = reading(w, at_sensor("ir_offset", 2, 25.0))
    assert on[2] == on0[2] + 25 and np.array_equal(off, off0)  # S3 sees no wall: on - off = 25
    assert np.array_equal(np.delete(on, 2), np.delete(on0, 2))
    _, on, _ = reading(w, at_sensor("ir_offset", 2, -400.0))
    assert on[2] == 0  # the ADC's floor


def test_ambient_leakage_puts_a_fraction_of_the_ambient_into_on_minus_off():
    w = wall_ahead(GAP, ambient=900)
    off, _, refl = reading(w, at_sensor("ambient_leakage", 0, 0.1))
    assert (off == 900).all()
    assert refl[0] == round(900 + float(ir.response(GAP, 0.0, 60)) + 0.1 * 900) - 900
    assert np.array_equal(refl[1:], reading(w, P)[2][1:])
    # With a lamp, the sensor facing it leaks more: leakage x its own ambient.
    lit = room([], lamps=[{"x": 1.5, "y": 1.0, "level": 10.0}], ambient=100)
    p = E.apply(E.apply(P, "ambient_leakage", 0, [0.2]), "ambient_leakage", 4, [0.2])
    off, _, refl = reading(lit, p)
    ambient = float(ambient_reference(lit, AT)[0])  # no wall: nothing reflected
    assert off[0] == round(ambient) > off[4] == 100
    assert refl[0] == round(1.2 * ambient) - round(ambient) and refl[4] == 20


def test_latency_reads_the_pose_of_that_long_ago():
    """A robot driving at the wall: with ir_latency = 2 control periods, each reading is the one the
    latency-free robot took two periods earlier (the first ones: where it started)."""
    w = builtin_world("paper_room")
    cmd = np.full((30, 2), 0.15)
    start = (0.35, 0.35, math.pi)  # facing the left wall
    nominal = simrobot_run(w, P, start, cmd)
    late = simrobot_run(w, P.replace(ir_latency=0.08), start, cmd)
    np.testing.assert_allclose(late["pose"], nominal["pose"], atol=0)  # the robot moves alike
    assert_adc_match(late["on"][2:], nominal["on"][:-2])
    assert_adc_match(late["on"][:2], nominal["on"][[0, 0]])
    assert not np.array_equal(late["on"], nominal["on"])
    # Half a period: halfway between the poses of the last two readings.
    half = simrobot_run(w, P.replace(ir_latency=0.02), start, cmd)
    mid = 0.5 * (nominal["pose"][4] + nominal["pose"][5])
    assert_adc_match(half["on"][5], ir.read_sensors(w, mid, 60, 0.18)[1])


def test_pose_history_interpolates_and_forgets():
    h = ir.PoseHistory(keep=0.05)
    for k in range(5):
        h.add(0.04 * k, (0.01 * k, 0.0, math.pi - 0.1 + 0.05 * k))  # the heading crosses +-pi... as one turn
    assert h.at(0.14) == pytest.approx([0.035, 0.0, math.pi - 0.1 + 0.175])
    assert len(h.t) == 3 and h.at(0.0) == pytest.approx(h.poses[0])  # older than kept: the oldest kept
    wrapped = ir.pose_at([0.0, 1.0], [[0, 0, math.pi - 0.1], [0, 0, -math.pi + 0.1]], 0.5)
    assert abs(wrapped[2]) == pytest.approx(math.pi)  # the short way round, not through 0


# --------------------------------------------------------------------------- scalar == batch, per effect
EFFECTS = {
    "ir_gain": E.apply(P, "ir_gain", 1, [1.7]),
    "ir_misalignment": E.apply(E.apply(P, "ir_misalignment", 0, [0.25]), "ir_misalignment", 5, [-0.4]),
    "ir_offset": E.apply(P, "ir_offset", 3, [37.5]),
    "ambient_leakage": E.apply(E.apply(P, "ambient_leakage", 0, [0.3]), "ambient_leakage", 6, [-0.1]),
}


@pytest.mark.parametrize("name", sorted(EFFECTS))
def test_scalar_equals_batch(name):
    p = EFFECTS[name]
    lamps = (Lamp(x=1.0, y=1.3, level=30.0, flicker_hz=100.0), Lamp(x=0.2, y=0.2, level=20.0))
    w = builtin_world("paper_room").with_changes(lamps=lamps)
    rng = np.random.default_rng(11)
    poses = np.column_stack([rng.uniform(0.1, 1.9, 64), rng.uniform(0.1, 1.4, 64), rng.uniform(-4, 4, 64)])
    power, t = rng.uniform(10, 100, 64), rng.uniform(0, 5, 64)
    off_b, on_b = ir.read_sensors(w, poses, power, t, p)
    single = [ir.read_sensors(w, poses[i], float(power[i]), float(t[i]), p) for i in range(64)]
    assert np.array_equal(np.array([s[0] for s in single]), off_b)
    assert np.array_equal(np.array([s[1] for s in single]), on_b)
    assert not np.array_equal(on_b, ir.read_sensors(w, poses, power, t, P)[1])  # the effect acts
    noisy = ir.read_sensors(w, poses[0], 60.0, 1.0, p, np.random.default_rng(3))
    batch = ir.read_sensors(w, poses[:1], 60.0, 1.0, p, np.random.default_rng(3))
    assert np.array_equal(noisy[1], batch[1][0]) and np.array_equal(noisy[0], batch[0][0])
    beam = p.replace(ir_beam_rays=5)  # and with the beam: 1 count at a rounding tie of its sum
    single = np.array([ir.read_sensors(w, poses[i], float(power[i]), float(t[i]), beam)[1] for i in range(64)])
    assert np.abs(single - ir.read_sensors(w, poses, power, t, beam)[1]).max() <= 1


def test_latency_simrobot_equals_batchsim_and_groups_apart():
    """BatchSim keeps a pose history as SimRobot does; robots differing only in latency or leakage are read apart."""
    assert "ambient_leakage" in IR_FIELDS and "ir_latency" in IR_FIELDS
    w = builtin_world("paper_room")
    rng = np.random.default_rng(5)
    cmd = np.repeat(np.round(rng.uniform(-0.1, 0.3, (6, 2)), 3), 10, axis=0)
    params = [P, P.replace(ir_latency=0.05), P.replace(ir_latency=0.11), EFFECTS["ambient_leakage"]]
    start = (0.4, 0.4, math.pi * 0.8)
    res = BatchSim(w, params, np.tile(start, (len(params), 1))).run_inputs(cmd)
    for i, p in enumerate(params):
        ref = simrobot_run(w, p, start, cmd)
        assert_adc_match(res.ir_on[:, i], ref["on"])
        assert_adc_match(res.ir_amb[:, i], ref["amb"])
    assert not np.array_equal(res.ir_on[:, 0], res.ir_on[:, 1])
    assert not np.array_equal(res.ir_on[:, 0], res.ir_on[:, 3])


def test_a_track_is_read_with_its_latency():
    """read_sensors(track=True) (replay, diagnosis) reads a recorded track as SimRobot reads its own history."""
    w = builtin_world("paper_room")
    p = P.replace(ir_latency=0.06)
    cmd = np.full((25, 2), 0.12)
    ref = simrobot_run(w, p, (0.35, 0.35, math.pi), cmd)
    t = 0.04 * np.arange(25)
    off, on = ir.read_sensors(w, ref["pose"], 60.0, t, p, track=True)
    assert_adc_match(on, ref["on"])
    assert_adc_match(off, ref["amb"])


# --------------------------------------------------------------------------- parameter file, absent values
def test_a_parameter_file_sets_the_ir_effects(tmp_path):
    data = {"ir_gain_scale": [1, 1.2, 1, 1, 1, 1, 1, 1], "ir_misalignment": [0.1, 0, 0, 0, 0, 0, 0, 0],
            "ir_offset": [0, 0, 12, 0, 0, 0, 0, 0], "ambient_leakage": [0, 0, 0, 0.05, 0, 0, 0, 0],
            "ir_latency": 0.03}
    path = tmp_path / "robot.json"
    path.write_text(json.dumps(data))
    p = load_params(path)
    assert E.values(p, "ir_gain", 1) == [1.2] and E.values(p, "ir_misalignment", 0) == [0.1]
    assert E.values(p, "ir_offset", 2) == [12.0] and E.values(p, "ambient_leakage", 3) == [0.05]
    assert E.values(p, "ir_latency", "both") == [0.03]
    robot = SimRobot(builtin_world("paper_room"), p, (0.35, 0.35, math.pi), noise=False)
    nominal = SimRobot(builtin_world("paper_room"), P, (0.35, 0.35, math.pi), noise=False)
    s, s0 = robot.sense(), nominal.sense()
    assert s.adc_on[2] - s0.adc_on[2] == 12  # read by the simulator


def test_absent_effects_are_the_defaults_and_refused_when_impossible():
    for name in ("ir_gain", "ir_misalignment", "ir_offset", "ambient_leakage", "ir_latency"):
        site = "both" if name == "ir_latency" else 0
        assert E.values(P, name, site) == E.absent_values(P, name)
    with pytest.raises(ValueError, match="ir_misalignment"):
        ir.read_sensors(wall_ahead(GAP), AT, 60, 0.0, at_sensor("ir_misalignment", 0, 2.0))
    with pytest.raises(ValueError, match="ir_gain_scale"):
        ir.read_sensors(wall_ahead(GAP), AT, 60, 0.0, at_sensor("ir_gain", 0, -1.0))
