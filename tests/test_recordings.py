"""One meaning for recordings: the writer's two entry points, the firmware's view, version 1 files."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from host_sim.physics.params import DEFAULT
from host_sim.recordings.recording import (COLUMNS, COLUMNS_V1, RecordingError, RecordingWriter, load_recording,
                                           sidecar_path)
from host_sim.recordings.replay import replay_inputs
from host_sim.controller.sil import SilController
from host_sim.loops.simulation import Simulation
from host_sim.physics.world import builtin_world

ROOM = builtin_world("paper_room")


def telemetry(tick: int, **extra: object) -> dict[str, object]:
    f: dict[str, object] = {"tick_ms": tick, "mode": 1, "flags": 0, "enc_l": 10, "enc_r": -3,
                            "ir_on": (5,) * 8, "ir_amb": (2,) * 8, "i_ref_l_ma": 120, "i_ref_r_ma": -40,
                            "vbat_mv": 7400}
    f.update(extra)
    return f


def test_telemetry_rows_unwrap_the_robot_clock_and_skip_repeats(tmp_path):
    path = tmp_path / "r.csv"
    with RecordingWriter(path, source="robot", sample_period=0.04) as w:
        assert w.telemetry(telemetry((1 << 30) - 20))
        assert not w.telemetry(telemetry((1 << 30) - 20))  # the same cycle twice
        assert w.telemetry(telemetry(20))  # the 30-bit clock wrapped: 40 ms later
    rec = load_recording(path)
    assert np.allclose(rec.t, [0.0, 0.04])
    assert np.allclose(rec.cmd[0], [0.12, -0.04]) and rec.enc[1].tolist() == [10, -3]
    assert rec.emitter is None and rec.firmware is None and rec.pose is None  # an older firmware reports neither


def test_a_clock_reset_keeps_recording_with_time_carrying_on_and_says_so_in_the_sidecar(tmp_path):
    path = tmp_path / "r.csv"
    with RecordingWriter(path, source="robot", sample_period=0.04) as w:
        for tick in (5000, 5040, 5080):
            assert w.telemetry(telemetry(tick))
        assert w.telemetry(telemetry(12, enc_l=0, enc_r=0))  # the board restarted: its clock and counters too
        assert not w.telemetry(telemetry(12))  # a repeated tick is still dropped
        for tick in (52, 92):  # long before the new clock passes the old one
            assert w.telemetry(telemetry(tick))
        assert json.loads(sidecar_path(path).read_text())["clock_resets"] == [3]  # said before the close
    rec = load_recording(path)
    assert np.allclose(rec.t, [0.0, 0.04, 0.08, 0.12, 0.16, 0.2])  # one firmware period across the reset
    assert rec.meta["clock_resets"] == [3] and rec.enc[3].tolist() == [0, 0]


def test_the_firmwares_view_is_recorded_in_si_units(tmp_path):
    path = tmp_path / "r.csv"
    quarter_turn_back = (3 << 30) // 4  # the firmware wraps its heading to [0, 2^30): -90 degrees
    with RecordingWriter(path, source="robot", sample_period=0.04) as w:
        w.telemetry(telemetry(0, emitter_pct=60, sp_l=150, sp_r=-150, odo_x=1_500_000, odo_y=-20_000,
                              odo_heading=quarter_turn_back), pose=(0.1, 0.2, 0.3))
    rec = load_recording(path)
    assert rec.emitter is not None and rec.emitter.tolist() == [60.0]
    assert rec.firmware is not None
    mode, sp_l, sp_r, x, y, phi = rec.firmware[0]
    assert (mode, sp_l, sp_r, x, y) == (1, 0.15, -0.15, 1.5, -0.02)
    assert phi == pytest.approx(-math.pi / 2)
    assert rec.pose is not None and rec.pose[0].tolist() == [0.1, 0.2, 0.3]


def test_a_firmware_view_present_in_some_rows_only_is_refused(tmp_path):
    path = tmp_path / "r.csv"
    with RecordingWriter(path, source="robot", sample_period=0.04) as w:
        w.telemetry(telemetry(0, emitter_pct=60, sp_l=1, sp_r=1, odo_x=0, odo_y=0, odo_heading=0))
        w.telemetry(telemetry(40, emitter_pct=60))
    with pytest.raises(RecordingError, match=r"r.csv:3: the firmware's view \(mode, sp_l.*missing here"):
        load_recording(path)


def test_a_version_1_recording_still_loads_and_replays_with_the_sidecars_emitter_power(tmp_path):
    path = tmp_path / "old.csv"
    with RecordingWriter(path, source="simulator", sample_period=0.04, extra={"mode": "fixed"}) as w:
        pass
    sidecar = path.with_name("old.csv.json")
    sidecar.write_text(sidecar.read_text().replace('"version": 2', '"version": 1').replace('"rows": 0', '"rows": 2'))
    row = ",".join(["0.0", "0.1", "0.1", "0", "0"] + ["300"] * 8 + ["100"] * 8 + ["7.4", "0.5", "0.5", "0.0"])
    path.write_text(",".join(COLUMNS_V1) + "\n" + row + "\n" + row.replace("0.0,", "0.04,", 1) + "\n")
    rec = load_recording(path)
    assert rec.emitter is None and rec.firmware is None and rec.pose is not None
    inputs = replay_inputs(rec)
    assert inputs.emitter.tolist() == [0.0, 60.0]  # a simulator run's emitters come on with its first actuation
    assert inputs.at_rest and np.allclose(inputs.period, 0.04)


def test_a_simulated_run_records_what_the_firmware_reported_and_what_the_emitters_did(tmp_path):
    path = tmp_path / "sil.csv"
    with RecordingWriter(path, source="simulator", sample_period=0.04, extra={"mode": "fixed"}) as w:
        run = Simulation(ROOM, DEFAULT, SilController(1), seed=2, recorder=w).run_fixed(2.0)
    rec = load_recording(path)
    assert open(path).readline().strip().split(",") == COLUMNS
    assert len(rec) == len(run.t) and np.array_equal(rec.cmd, run.cmd) and np.array_equal(rec.pose, run.pose)
    assert rec.emitter is not None and rec.emitter[0] == 0 and (rec.emitter[1:] == 60).all()
    assert replay_inputs(rec).emitter.tolist() == rec.emitter.tolist()
    assert rec.firmware is not None and (rec.firmware[:, 0] == 1).all()  # AUTONOMOUS: the firmware's own view
    assert np.abs(rec.firmware[:, 1:3]).max() > 0.05  # the set-points its fuzzy controller gave the wheels
