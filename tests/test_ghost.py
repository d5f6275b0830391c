"""The late-signal twin (host_sim/loops/late_signal_twin.py) against the simulator behind a late, jittery link."""
from __future__ import annotations

import numpy as np

from host_sim.loops.late_signal_twin import Ghost, odometry_pose
from host_sim.loops.late_signal_trial import run_late


def test_ghost_beats_the_raw_late_pose_at_200_ms() -> None:
    run = run_late(0.200, 0.050, seed=3, duration=30.0)
    ghost, raw = np.mean(run.ghost_err), np.mean(run.raw_err)
    assert len(run.ghost_err) > 600
    assert raw > 0.005  # the robot moved: a late pose is metres-per-second x 0.2 s off
    assert ghost < 0.5 * raw, (ghost, raw)


def test_latency_estimate_within_20_ms_of_the_injected_mean() -> None:
    run = run_late(0.200, 0.050, seed=4, duration=20.0)
    assert abs(np.mean(run.latency_est) - 0.200) < 0.020
    assert abs(np.mean(run.latency_est) - np.mean(run.latency_true)) < 0.010


def test_latency_counts_from_the_fastest_frame() -> None:
    g = Ghost(0.096, 0.042, 1200, floor_s=0.010)
    frame = {"tick_ms": 1000, "enc_l": 0, "enc_r": 0, "odo_x": 0, "odo_y": 0, "odo_heading": 0, "sp_l": 0, "sp_r": 0}
    g.on_telemetry(frame, 5.030)
    g.on_telemetry(dict(frame, tick_ms=1040), 5.050)  # fastest: offset 4.010
    g.on_telemetry(dict(frame, tick_ms=1080), 5.190)
    assert abs(g.latencies[-1] - (0.100 + 0.010)) < 1e-9
    assert abs(g.robot_time(5.190) - (5.190 - 4.000)) < 1e-9


def test_prediction_follows_the_commands_sent_since_the_frame() -> None:
    g = Ghost(0.096, 0.042, 1200, tau_s=0.02)
    frame = {"tick_ms": 0, "enc_l": 0, "enc_r": 0, "odo_x": 0, "odo_y": 0, "odo_heading": 0, "sp_l": 0, "sp_r": 0}
    g.on_telemetry(frame, 0.0)
    g.on_command(0.0, 200, 200)
    x, y, phi = g.predict(1.0)  # type: ignore[misc]
    assert 0.18 < x < 0.2 and abs(y) < 1e-9 and abs(phi) < 1e-9
    g.on_command(1.0, -100, 100)  # spin in place: no further travel, a turn of 2 v t / base
    x2, _y2, phi2 = g.predict(1.5)  # type: ignore[misc]
    assert abs(x2 - x) < 0.005 and 0.9 < phi2 < 1.1


def test_odometry_pose_units() -> None:
    x, y, phi = odometry_pose({"odo_x": 1_500_000, "odo_y": -250_000, "odo_heading": 3 << 28})
    assert (x, y) == (1.5, -0.25) and abs(phi - (-0.5 * np.pi)) < 1e-12


def test_without_the_floor_the_latency_counts_from_the_fastest_frame() -> None:
    run = run_late(0.200, 0.050, seed=4, duration=10.0, floor_s=0.0)
    assert abs(np.mean(run.latency_est) - 0.050) < 0.020  # the jitter above the 150 ms floor
