"""The firmware uses the geometry of the robot it runs on (docs/firmware.md, Geometry):
configured from the parameters in SIL and PIL, reported in HELLO, written by `twinbot flash --params`.
"""
from __future__ import annotations

import json

import numpy as np

from host_sim.controller.hardware_io import firmware_geometry, setup_frames
from host_sim.physics.params import DEFAULT
from host_sim.recordings.recording import RecordingWriter, load_recording
from host_sim.controller.sil import SilController
from host_sim.loops.simulation import Simulation
from host_sim.physics.world import builtin_world
from protocol import messages as M
from protocol.framing import FrameDecoder
from tests.helpers import run_twinbot

BIG_WHEELS = DEFAULT.replace(wheel_radius=0.026, half_axle=0.055)
ARENA = builtin_world("arena")


def test_setup_sends_the_robots_geometry_first():
    frames = FrameDecoder().decode_all(b"".join(setup_frames(1, params=BIG_WHEELS)))
    sets = {M.param_by_id(M.unpack_payload(t, p)["param"])[1]: M.unpack_payload(t, p)["value"]
            for t, _s, p in frames if t == M.PARAM_SET}
    assert sets["wheel_diameter_um"] == 52000 and sets["wheel_base_um"] == 110000 and sets["ticks_per_rev"] == 1200
    assert firmware_geometry(DEFAULT.replace(wheel_radius_delta_l=0.001, ticks_per_rev_delta_r=10)) == (43000, 96000,
                                                                                                       1205)


def odometry_error(rec) -> float:
    """Largest distance between the firmware's odometry and the truth over a recorded run."""
    assert rec.firmware is not None and rec.pose is not None
    phi0 = rec.pose[0, 2]
    rot = np.array([[np.cos(phi0), -np.sin(phi0)], [np.sin(phi0), np.cos(phi0)]])
    truth_from_odometry = rec.pose[0, :2] + rec.firmware[:, 3:5] @ rot.T  # the firmware starts at (0, 0, 0)
    return float(np.max(np.hypot(*(truth_from_odometry - rec.pose[:, :2]).T)))


def run_big_wheels(tmp_path, firmware_params) -> float:
    path = tmp_path / f"run_{firmware_params is not None}.csv"
    with RecordingWriter(path, source="simulator", sample_period=0.04) as w:
        Simulation(ARENA, BIG_WHEELS, SilController(1, params=firmware_params), seed=1, recorder=w).run_fixed(15.0)
    return odometry_error(load_recording(path))


def test_the_firmware_told_its_geometry_reckons_its_way_and_untold_it_does_not(tmp_path):
    told = run_big_wheels(tmp_path, BIG_WHEELS)
    untold = run_big_wheels(tmp_path, None)  # a board flashed without --params: the default 21 mm wheels
    assert told < 0.01  # dead reckoning over 15 s of exploration, the wheels never slipping
    assert untold > 5 * told and untold > 0.1


def test_sim_params_configures_the_firmware_too(tmp_path):
    params = tmp_path / "big_wheels.json"
    params.write_text(json.dumps({"wheel_radius": 0.026, "half_axle": 0.055}))
    rec_path = tmp_path / "cli.csv"
    r = run_twinbot("sim", "--world", "arena", "--duration", "15", "--seed", "1", "--record", str(rec_path),
                    "--params", str(params), timeout=120)
    assert r.returncode == 0, r.stderr
    assert odometry_error(load_recording(rec_path)) < 0.03
