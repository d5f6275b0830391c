"""Batch mode (host_sim/robot/batch.py): N robots at once agree with N single-robot runs (docs/dynamics.md)."""
from __future__ import annotations

# Tolerances.  BatchSim runs the same physics in the same order as SimRobot, but
# dynamics.step_batch groups the floating-point operations of the closed form differently from
# dynamics.step, so the two agree to rounding error, not bit for bit (about 1e-14 m over 16 s,
# contacts included).  Poses are compared to 1e-9 m.  Quantised outputs are then equal unless
# the exact value lies within that rounding error of a quantisation boundary, so:
# - encoder ticks are equal wherever the single robot's wheel angle is more than 1e-6 tick from
#   a tick boundary (a 1e-9 m error is ~2e-5 tick at most for a 21 mm wheel at 1200 ticks/rev),
#   and within 1 tick everywhere;
# - ADC counts are within 1 count everywhere and equal in all but 0.1 % of the readings (a
#   reading is off only if its exact value is within ~1e-10 counts of a rounding boundary).

import numpy as np
import pytest

from host_sim.robot.batch import BatchSim
from host_sim.recordings.replay import replay_batch
from host_sim.controller.hardware_io import Actuate
from host_sim.controller.sil import SilController
from host_sim.physics.dynamics import ParamBatch
from host_sim.robot.sim_robot import SimRobot
from host_sim.physics.params import DEFAULT
from host_sim.recordings.recording import RecordingWriter, load_recording
from host_sim.recordings.replay import replay
from host_sim.loops.simulation import Simulation
from host_sim.physics.world import World, builtin_world

ROOM = builtin_world("paper_room")
EMPTY = World(name="empty", size=(10.0, 10.0), walls=[])
TICK_EDGE = 1e-6  # ticks: closer than this to a boundary, a one-tick difference is rounding


def simrobot_run(world, p, pose, cmd, emitter0=60, seed=None, substeps=8, period=0.04):
    """The single-robot reference: what Simulation/replay do each control period."""
    robot = SimRobot(world, p, tuple(pose), seed=seed, noise=seed is not None)
    robot.emitter_pct = emitter0
    out = {k: [] for k in ("pose", "enc", "theta", "on", "amb")}
    for row in cmd:
        s = robot.sense()
        out["pose"].append(robot.pose)
        out["enc"].append((s.enc_l, s.enc_r))
        out["theta"].append(robot.q[3:5])
        out["on"].append(s.adc_on)
        out["amb"].append(s.adc_off)
        robot.actuate(Actuate(round(row[0] * 1000), round(row[1] * 1000), 60))
        for _ in range(substeps):
            robot.advance(period / substeps)
    res = {k: np.array(v) for k, v in out.items()}
    res["collisions"] = robot.collisions
    return res


def assert_ticks_match(batch_enc, ref_enc, ref_theta, p=DEFAULT):
    diff = np.abs(batch_enc - ref_enc)
    assert diff.max() <= 1
    frac = np.asarray(ref_theta) / (2 * np.pi) * p.ticks_per_rev
    on_edge = np.abs(frac - np.round(frac)) < TICK_EDGE
    assert (diff[~on_edge] == 0).all()


def assert_adc_match(batch, ref):
    diff = np.abs(np.asarray(batch, dtype=np.int64) - np.asarray(ref, dtype=np.int64))
    assert diff.max() <= 1
    assert (diff != 0).mean() <= 1e-3


def commands(rng, rows, n=None, hold=20):
    """Piecewise-constant current references in mA steps, some of them into the walls."""
    shape = (rows // hold, 2) if n is None else (rows // hold, n, 2)
    cmd = np.repeat(rng.uniform(-0.25, 0.45, size=shape), hold, axis=0)
    return np.round(cmd, 3)


def test_identical_parameter_sets_equal_single_robot_runs_in_a_world():
    rng = np.random.default_rng(1)
    poses = np.array([[0.35, 0.35, 0.5], [1.5, 0.5, 2.0], [0.3, 1.2, -1.0], [1.7, 1.2, 3.0]])
    cmd = commands(rng, 400, n=len(poses))
    sim = BatchSim(ROOM, [DEFAULT] * len(poses), poses)
    res = sim.run_inputs(cmd, sensors=True, seed=None)
    assert res.enc.shape == (400, 4, 2) and res.pose.shape == (400, 4, 3) and res.ir_on.shape == (400, 4, 8)
    for i, pose in enumerate(poses):
        ref = simrobot_run(ROOM, DEFAULT, pose, cmd[:, i])
        np.testing.assert_allclose(res.pose[:, i], ref["pose"], rtol=0, atol=1e-9)
        assert_ticks_match(res.enc[:, i], ref["enc"], ref["theta"])
        assert_adc_match(res.ir_on[:, i], ref["on"])
        assert_adc_match(res.ir_amb[:, i], ref["amb"])
        assert res.collisions[i] == ref["collisions"]
    assert res.collisions.sum() > 0  # the contact rule was exercised


def test_one_robot_with_a_seed_has_simrobots_sensor_noise():
    rng = np.random.default_rng(2)
    cmd = commands(rng, 120)
    res = BatchSim(ROOM, DEFAULT, [ROOM.start]).run_inputs(cmd, seed=7)
    ref = simrobot_run(ROOM, DEFAULT, ROOM.start, cmd, seed=7)
    np.testing.assert_allclose(res.pose[:, 0], ref["pose"], rtol=0, atol=1e-9)
    assert_adc_match(res.ir_on[:, 0], ref["on"])
    assert_adc_match(res.ir_amb[:, 0], ref["amb"])
    assert np.ptp(res.ir_amb[:, 0]) > 0  # there was noise to match


@pytest.mark.parametrize("grip", [1.0, 0.05])
def test_one_robot_steps_in_floats_as_in_a_batch(grip):
    """BatchSim.substep is every robot's step: a BatchSim of one takes it in Python floats, SimRobot (its
    view) the same bit for bit; the same robot in a batch of two takes the vectorised step, equal to rounding."""
    rng = np.random.default_rng(7)
    p = DEFAULT.replace(wheel_friction=grip)
    poses = np.array([[0.35, 0.35, 0.5], [1.5, 0.5, 2.0]])
    cmd = commands(rng, 400, n=2)
    alone = BatchSim(ROOM, p, poses[:1])
    assert alone._floats and not BatchSim(ROOM, p, poses)._floats
    res = alone.run_inputs(cmd[:, 0], sensors=False)
    ref = simrobot_run(ROOM, p, poses[0], cmd[:, 0])
    assert np.array_equal(res.theta[:, 0], ref["theta"]) and np.array_equal(res.enc[:, 0], ref["enc"])
    assert res.collisions[0] == ref["collisions"] > 0  # the contact step was exercised
    both = BatchSim(ROOM, p, poses).run_inputs(cmd, sensors=False)
    np.testing.assert_allclose(both.pose[:, 0], res.pose[:, 0], rtol=0, atol=1e-9)
    assert_ticks_match(both.enc[:, 0], res.enc[:, 0], res.theta[:, 0])
    assert both.collisions[0] == res.collisions[0]


def test_a_heavier_robot_accelerates_less():
    masses = [0.30, 0.46, 0.70, 1.00]
    params = [DEFAULT.replace(body_mass=m) for m in masses]
    cmd = np.full((10, 2), 0.2)  # 0.4 s of the same current on both wheels
    res = BatchSim(None, params, np.zeros((4, 3))).run_inputs(cmd, sensors=False)
    travelled = res.pose[-1, :, 0]
    assert (np.diff(travelled) < 0).all() and travelled[-1] > 0
    np.testing.assert_allclose(res.pose[:, :, 1:], 0.0, atol=1e-12)  # straight ahead, no turning
    # Each one is the single robot with its own parameters (the per-robot path).
    for i, p in enumerate(params):
        ref = simrobot_run(EMPTY, p, (0.0, 0.0, 0.0), cmd)
        np.testing.assert_allclose(res.pose[:, i], ref["pose"], rtol=0, atol=1e-9)
        assert_ticks_match(res.enc[:, i], ref["enc"], ref["theta"])


def test_parameter_sets_in_a_world_each_match_their_single_robot():
    rng = np.random.default_rng(3)
    names = ["body_mass", "wheel_radius", "viscous_friction", "ir_gain"]
    values = np.array(DEFAULT.to_vector(names)) * rng.uniform(0.8, 1.2, (5, len(names)))
    batch = ParamBatch.from_vectors(values, names)
    cmd = commands(rng, 300)
    res = BatchSim(ROOM, batch, np.tile(ROOM.start, (5, 1))).run_inputs(cmd)
    ends = res.pose[-1, :, :2]
    assert np.hypot(*(ends - ends[0]).T)[1:].min() > 1e-3  # N different trajectories
    for i in range(5):
        p = batch.robot(i)
        ref = simrobot_run(ROOM, p, ROOM.start, cmd)
        np.testing.assert_allclose(res.pose[:, i], ref["pose"], rtol=0, atol=1e-9)
        assert_ticks_match(res.enc[:, i], ref["enc"], ref["theta"], p)
        assert_adc_match(res.ir_on[:, i], ref["on"])  # each robot read with its own ir_gain
        assert res.collisions[i] == ref["collisions"]


def test_a_brighter_sensor_reads_more_of_the_same_wall():
    gains = [2.0, 2.9, 4.0]
    params = [DEFAULT.replace(ir_gain=g) for g in gains]
    pose = [0.35, 0.35, np.pi]  # facing the left wall, 0.35 m ahead of C
    res = BatchSim(ROOM, params, np.tile(pose, (3, 1))).run_inputs(np.zeros((1, 2)))
    reflected = res.ir_on[0] - res.ir_amb[0]
    assert (np.diff(reflected[:, 0]) > 0).all()  # S1, the front sensor


def test_the_state_carries_over_between_calls():
    rng = np.random.default_rng(4)
    cmd = commands(rng, 200, n=3)
    poses = np.array([[0.35, 0.35, 0.5], [1.5, 0.5, 2.0], [0.3, 1.2, -1.0]])
    whole = BatchSim(ROOM, DEFAULT, poses).run_inputs(cmd, sensors=False)
    sim = BatchSim(ROOM, DEFAULT, poses)
    first = sim.run_inputs(cmd[:77], sensors=False)
    rest = sim.run_inputs(cmd[77:], sensors=False)
    np.testing.assert_array_equal(np.concatenate([first.pose, rest.pose]), whole.pose)
    np.testing.assert_array_equal(np.concatenate([first.t, rest.t]), whole.t)


def _simulator_recording(path, seed, noise, duration=6.0):
    with RecordingWriter(path, source="simulator", sample_period=0.04, robot=DEFAULT.to_json(),
                         world=ROOM.to_dict(), extra={"mode": "fixed", "emitter_pct": 60}) as rec:
        Simulation(ROOM, DEFAULT, SilController(1), seed=seed, noise=noise, recorder=rec).run_fixed(duration)
    return load_recording(path)


def test_replay_batch_reproduces_a_simulator_recording(tmp_path):
    rec = _simulator_recording(tmp_path / "quiet.csv", seed=None, noise=False)
    assert np.hypot(*(rec.pose[-1, :2] - rec.pose[0, :2])) > 0.1  # the robot went somewhere
    res = replay_batch(rec, [DEFAULT] * 3)  # the world comes from the sidecar
    assert res.pose.shape == (len(rec), 3, 3)
    for i in range(3):
        np.testing.assert_allclose(res.pose[:, i], rec.pose, rtol=0, atol=1e-9)
        assert (np.abs(res.enc[:, i] - rec.enc) <= 1).all()
        assert (res.enc[:, i] == rec.enc).mean() > 0.999
        assert_adc_match(res.ir_on[:, i], rec.ir_on)
        assert_adc_match(res.ir_amb[:, i], rec.ir_amb)
    np.testing.assert_allclose(res.t, rec.t, rtol=0, atol=1e-9)


def test_replay_batch_with_noise_and_from_a_middle_row(tmp_path):
    rec = _simulator_recording(tmp_path / "noisy.csv", seed=3, noise=True)
    one = replay_batch(rec, DEFAULT, seed=3)  # N = 1 with the recording's seed: its noise too
    np.testing.assert_allclose(one.pose[:, 0], rec.pose, rtol=0, atol=1e-9)
    assert_adc_match(one.ir_on[:, 0], rec.ir_on)
    assert_adc_match(one.ir_amb[:, 0], rec.ir_amb)
    # From row 60 (wheel speeds estimated from the encoders), as replay does.
    batch = ParamBatch.from_params([DEFAULT, DEFAULT.replace(body_mass=0.6)])
    mid = replay_batch(rec, batch, start=60, stop=85, sensors=False)
    ref = replay(rec, DEFAULT, ROOM, start=60, stop=85)
    assert mid.start == 60 and mid.ir_on is None
    np.testing.assert_allclose(mid.pose[:, 0], ref.pose, rtol=0, atol=1e-9)
    assert np.abs(mid.pose[-1, 1, :2] - mid.pose[-1, 0, :2]).max() > 1e-4  # the heavier one differs


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="cmd must have shape"):
        BatchSim(ROOM, DEFAULT, np.tile(ROOM.start, (3, 1))).run_inputs(np.zeros((5, 2, 2)))
    with pytest.raises(ValueError, match="2 parameter sets for 3 robots"):
        BatchSim(ROOM, [DEFAULT, DEFAULT], np.tile(ROOM.start, (3, 1)))
    with pytest.raises(ValueError, match="poses must have shape"):
        BatchSim(ROOM, DEFAULT, np.zeros((3, 2)))


def test_replay_batch_follows_a_robots_own_timing(tmp_path):
    """A robot's recording: rows at the times it recorded them, not at the nominal period."""
    sim = _simulator_recording(tmp_path / "sim.csv", seed=None, noise=False, duration=3.0)
    jitter = np.random.default_rng(5).uniform(-0.004, 0.004, len(sim))
    jitter[0] = 0.0
    path = tmp_path / "robot.csv"
    with RecordingWriter(path, source="robot", sample_period=0.04, world=ROOM.to_dict()) as out:
        for k in range(len(sim)):
            out.row(sim.t[k] + jitter[k], sim.cmd[k], sim.enc[k], sim.ir_on[k], sim.ir_amb[k], sim.vbat[k],
                    sim.pose[k])
    rec = load_recording(path)
    res = replay_batch(rec, [DEFAULT, DEFAULT], start=10, sensors=False)
    ref = replay(rec, DEFAULT, ROOM, start=10)
    np.testing.assert_allclose(res.t, ref.t, rtol=0, atol=1e-12)
    for i in range(2):
        np.testing.assert_allclose(res.pose[:, i], ref.pose, rtol=0, atol=1e-9)
        assert (np.abs(res.enc[:, i] - ref.enc) <= 1).all()


def test_a_robot_recording_that_starts_from_rest_starts_the_twin_near_rest(tmp_path):
    """The wheel speed at a recording's first row is the slope there (a three-row one-sided difference), not
    the first period's mean: a robot accelerating from rest must not start its twin already moving."""
    from host_sim.recordings.replay import wheel_speeds_at

    sim = _simulator_recording(tmp_path / "sim.csv", seed=None, noise=False, duration=1.0)
    path = tmp_path / "robot.csv"
    with RecordingWriter(path, source="robot", sample_period=0.04, world=ROOM.to_dict()) as out:
        for k in range(len(sim)):
            out.row(sim.t[k], sim.cmd[k], sim.enc[k], sim.ir_on[k], sim.ir_amb[k], sim.vbat[k], sim.pose[k])
    rec = load_recording(path)
    tick = 2 * np.pi / DEFAULT.ticks_per_rev
    first_period = (rec.enc[1] - rec.enc[0]) * tick / (rec.t[1] - rec.t[0])  # rad/s, its mean over the period
    assert (np.abs(first_period) > 0.5).all()  # the robot sets off at once
    start = np.array(wheel_speeds_at(rec, 0, DEFAULT))
    assert (np.abs(start) < 0.3 * np.abs(first_period)).all(), (start, first_period)  # it was at rest at row 0
    # Inside, central differences; at the last row, the mirror of the first.
    inside = np.array(wheel_speeds_at(rec, 5, DEFAULT))
    np.testing.assert_allclose(inside, (rec.enc[6] - rec.enc[4]) * tick / (rec.t[6] - rec.t[4]))
    last = len(rec) - 1
    steady = (rec.enc[last] - rec.enc[last - 1]) * tick / (rec.t[last] - rec.t[last - 1])
    np.testing.assert_allclose(wheel_speeds_at(rec, last, DEFAULT), steady, rtol=0.15)


@pytest.mark.parametrize("effect", [{}, {"backlash_l": 0.05, "backlash_r": 0.03}, {"actuator_delay": 0.03},
                                    {"ir_latency": 0.02}, {"caster_drag": 0.002, "battery_resistance": 1.0}])
def test_each_robot_lives_its_own_durations(effect):
    """period (T, N): each robot steps its own row durations (a recorded robot's late rows) and reads its
    own clock, exactly as it would alone; equal durations as (T, N) are the shared (T,) bit for bit."""
    rng = np.random.default_rng(1)
    rows, n = 200, 3
    cmd = commands(rng, rows, hold=10)
    cmd[100:140] = 0.6  # into a wall: the contact step too
    period = 0.04 + rng.choice([0.0, 0.0, 0.003, 0.02, 0.08], size=(rows, n))
    p = DEFAULT.replace(**effect)
    starts = np.tile(ROOM.start, (n, 1)) + np.array([0.0, 0.0, 0.7]) * np.arange(n)[:, None]
    sensors = "ir_latency" in effect  # the IR ring reads along each robot's own clock
    res = BatchSim(ROOM, p, starts).run_inputs(cmd, period=period, sensors=sensors)
    assert res.t.shape == (rows, n)
    for i in range(n):
        alone = BatchSim(ROOM, p, starts[i:i + 1]).run_inputs(cmd, period=period[:, i], sensors=sensors)
        np.testing.assert_allclose(res.t[:, i], alone.t, rtol=0, atol=1e-12)
        np.testing.assert_allclose(res.pose[:, i], alone.pose[:, 0], rtol=0, atol=1e-9)
        if sensors:
            assert_adc_match(res.ir_on[:, i], alone.ir_on[:, 0])
        assert res.collisions[i] == alone.collisions[0]
    shared = BatchSim(ROOM, p, starts).run_inputs(cmd, period=period[:, 0], sensors=sensors)
    each = BatchSim(ROOM, p, starts).run_inputs(cmd, period=np.repeat(period[:, :1], n, axis=1), sensors=sensors)
    assert np.array_equal(shared.pose, each.pose) and np.array_equal(shared.theta, each.theta)
    assert not sensors or np.array_equal(shared.ir_on, each.ir_on)
    with pytest.raises(ValueError, match="period must have shape"):
        BatchSim(ROOM, p, starts).run_inputs(cmd, period=period[:, :2])
