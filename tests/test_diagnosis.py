"""twinbot diagnose on recordings whose truth is known: the twin's own, with effects injected into it.

The MuJoCo plant (tools/proving_ground) is the independent proof; these are
the easy cases: a recording made by the twin with one parameter changed is
diagnosed with the nominal twin, which must name the change, measure it and
fit the held-out windows again.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from host_sim import effects as E
from host_sim.diagnosis import DiagnosisError, diagnose
from host_sim.params import DEFAULT, load_params
from host_sim.recording import RecordingWriter, load_recording
from host_sim.sil import SilController
from host_sim.simulation import Simulation
from host_sim.world import builtin_world
from tests.helpers import run_twinbot

ROOM = builtin_world("paper_room")


def record(tmp_path, params=DEFAULT, duration=30.0, name="run.csv", rules=1, seed=4):
    path = tmp_path / name
    with RecordingWriter(path, source="simulator", sample_period=0.04, robot=DEFAULT.to_json(),
                         world=ROOM.to_dict(), extra={"mode": "fixed"}) as w:
        Simulation(ROOM, params, SilController(rules), seed=seed, recorder=w).run_fixed(duration)
    return load_recording(path)


@pytest.fixture(scope="module")
def nominal_run(tmp_path_factory):
    return record(tmp_path_factory.mktemp("nominal"))


def test_the_twins_own_recording_is_a_match(nominal_run):
    d = diagnose(nominal_run, DEFAULT, ROOM)
    assert d.verdict == "match" and not d.located and not d.effects
    assert d.fit_before["wheel_l"] > 90 and d.fit_before["heading_rate"] > 95


@pytest.mark.parametrize("effect,site,true_value", [
    ("track_width", "both", 0.052),  # half_axle
    ("com_offset", "both", 0.030),
    ("ir_gain", 0, 1.3),  # S1 30 % brighter
    ("ir_offset", 2, 30.0),  # counts on S3's emitter-on reading
    ("ir_misalignment", 1, 0.2),  # S2 turned 11 degrees counter-clockwise
    ("ambient_leakage", 0, 0.2),  # S1's on-reading sees 20 % more of the ambient
    ("ir_latency", "both", 0.08),  # the ring reads the pose of two periods ago
    # the drive effects, physics in the twin (host_sim/drive_effects.py, docs/effects.md)
    ("dry_friction", "left", 3e-3),  # coulomb_friction_delta_l
    ("viscous_friction", "right", 4e-4),
    ("wheel_radius", "left", 1.5e-3),
    ("torque_constant", "right", -6e-4),
    ("encoder_scale", "left", 60.0),  # ticks_per_rev_delta_l
    ("backlash", "right", 0.15),
    ("actuator_delay", "both", 0.06),
    ("battery_resistance", "both", 3.0),
    ("caster_drag", "both", 0.1),
    ("turning_resistance", "both", 0.004),
])
def test_an_effect_injected_into_the_twin_is_named_measured_and_fitted(tmp_path, effect, site, true_value):
    rec = record(tmp_path, E.apply(DEFAULT, effect, site, [true_value]))
    d = diagnose(rec, DEFAULT, ROOM)
    assert d.verdict == "explained", d.summary()
    assert [e["name"] for e in d.effects] == [effect], d.summary()
    if isinstance(site, int):
        assert d.effects[0]["sensor"] == site
    elif site in ("left", "right"):
        assert d.effects[0]["wheel"] == site
    (param,) = d.effects[0]["params"].values()
    assert param["value"] == pytest.approx(true_value, rel=0.15)
    lo, hi = param["ci95"]
    assert lo <= param["value"] <= hi
    located = {item["channel"] for item in d.located}
    assert located and all(d.fit_after[c] > d.fit_before[c] for c in located)


def test_json_and_parameter_file_from_the_command(tmp_path):
    rec = record(tmp_path, DEFAULT.replace(half_axle=0.052), name="wide.csv")
    out, fitted = tmp_path / "verdict.json", tmp_path / "fitted.json"
    r = run_twinbot("diagnose", str(rec.path), "--json", str(out), "--write-params", str(fitted), "--quiet",
                    timeout=120)
    assert r.returncode == 0, r.stderr
    assert "explained" in r.stdout and "track_width" in r.stdout
    doc = json.loads(out.read_text())
    assert set(doc) >= {"recording", "verdict", "located", "effects", "fit", "unexplained"}
    assert doc["verdict"] == "explained" and set(doc["fit"]) == {"before", "after"}
    assert {"channel", "regime", "spans", "fit_before"} <= set(doc["located"][0])
    assert load_params(fitted).half_axle == pytest.approx(0.052, rel=0.02)


def test_too_short_or_too_still_is_said_plainly(tmp_path):
    short = record(tmp_path, duration=3.0, name="short.csv")
    with pytest.raises(DiagnosisError, match="too short"):
        diagnose(short, DEFAULT, ROOM)
    still = record(tmp_path, duration=10.0, name="still.csv")
    still.enc[:] = still.enc[:1]  # the wheels never turned
    with pytest.raises(DiagnosisError, match="too little excitation"):
        diagnose(still, DEFAULT, ROOM)


def test_without_a_tracker_the_encoders_are_judged_and_the_limits_said(nominal_run):
    blind = nominal_run
    saved = blind.pose
    try:
        blind.pose = None
        d = diagnose(blind, DEFAULT, ROOM)
    finally:
        blind.pose = saved
    assert d.verdict == "match"
    assert "wheel_l" in d.fit_before and "heading_rate" not in d.fit_before and "ir_0" not in d.fit_before
    assert any("no tracker" in n for n in d.notes)


def test_a_bad_recording_is_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("not,a,recording\n")
    r = run_twinbot("diagnose", str(bad))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert np.isfinite(1.0)


def test_too_little_of_a_motion_away_from_the_walls_is_said(nominal_run):
    from host_sim.diagnosis.compare import compare
    from host_sim.diagnosis.report import excitation_notes

    first = compare(nominal_run, DEFAULT, ROOM, locate=False)
    assert not any("turned for" in n for n in excitation_notes(nominal_run, first, DEFAULT, ROOM))
    straight = load_recording(nominal_run.path)
    straight.enc[:, 1] = straight.enc[:, 0]  # the encoders now say the robot never turned
    (note,) = excitation_notes(straight, first, DEFAULT, ROOM)
    assert "turned for 0.0 s" in note and "track width" in note and "--excite" in note
